"""Figs. 1-2 schematics: drawn from the model objects, checked against the paper's geometry.

Expected numbers come from MODEL.md section 1 (radii, wall positions, contact heights) and
Sec. II B of the paper (rigid layer = R/10), not from the drawing code.
"""

import math

import matplotlib.pyplot as plt
import numpy as np
import pytest

from granel import scenario as S
from granel.viz import drawing as D
from granel.viz import model_geometry as G
from granel.viz import schematics as X
from granel.scenario import build_solid

R_L, R_S = 10.0, 5.0  # granule radii [mm]
SQ3 = math.sqrt(3.0)


@pytest.fixture(scope="module")
def paper():
    sc = S.load("paper")
    system, _, _ = S.build_granular(sc, sc.base)
    return sc, system


@pytest.fixture(scope="module")
def plate(paper):
    sc, system = paper
    return build_solid(G.with_solid_kind(sc, "plate"), system)


@pytest.fixture(scope="module")
def beam(paper):
    sc, system = paper
    return build_solid(G.with_solid_kind(sc, "beam"), system)


@pytest.fixture(scope="module")
def fig1(paper):
    fig = X.figure1(paper[0])
    yield fig
    plt.close(fig)


@pytest.fixture(scope="module")
def fig2(paper):
    fig = X.figure2(paper[0])
    yield fig
    plt.close(fig)


@pytest.fixture(scope="module")
def files(paper, tmp_path_factory):
    out = tmp_path_factory.mktemp("schematics")
    return X.fig1_geometry(paper[0], out / "fig1"), X.fig2_meshes(paper[0], out / "fig2")


def _arrow(ann):
    """(tail, head) of an arrow drawn with ax.annotate [mm]."""
    return np.asarray(ann.xyann, float), np.asarray(ann.xy, float)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.hypot(*v)


# ------------------------------------------------------------------ files


def test_files_written(files):
    for paths in files:
        png, pdf = paths
        assert png.suffix == ".png" and pdf.suffix == ".pdf"
        assert png.stat().st_size > 20_000
        assert pdf.read_bytes()[:4] == b"%PDF"


# ------------------------------------------------------------------ Fig. 1


def test_fig1_draws_all_six_walls_where_the_paper_has_them(fig1, paper):
    _, system = paper
    walls = D.tagged(fig1, "a", "wall")
    hatches = D.tagged(fig1, "a", "wall-hatch")
    labels = D.tagged(fig1, "a", "wall-label")
    assert len(walls) == len(system.walls) == 6
    assert set(walls) == set(hatches) == set(labels) == {w.name for w in system.walls}
    assert all(labels[name].get_text() == name for name in labels)
    x_lsgm = -(2 + 2 * SQ3) * R_L  # outer wall of the LSGM, MODEL.md sec. 1
    x_ssgm = 10.0 + (2 + 2 * SQ3) * R_S
    expected = {
        "LSGM:bottom": [(x_lsgm, 0.0), (0.0, 0.0)],
        "LSGM:top": [(x_lsgm, 100.0), (0.0, 100.0)],
        "LSGM:outer": [(x_lsgm, 0.0), (x_lsgm, 100.0)],
        "SSGM:bottom": [(10.0, 25.0), (x_ssgm, 25.0)],
        "SSGM:top": [(10.0, 75.0), (x_ssgm, 75.0)],
        "SSGM:outer": [(x_ssgm, 25.0), (x_ssgm, 75.0)],
    }
    for name, seg in expected.items():
        np.testing.assert_allclose(walls[name].get_xydata(), seg, atol=1e-9)


def test_fig1_labels_every_granule_at_its_centre(fig1, paper):
    _, system = paper
    labels = D.tagged(fig1, "a", "granule-label")
    assert {t.get_text() for t in labels.values()} == {str(k) for k in range(1, 15)} | set("ABCDEFGHIJKLMN")
    assert labels["LSGM:3"].get_position() == pytest.approx((-(1 + 2 * SQ3) * R_L, 50.0))
    assert labels["SSGM:C"].get_position() == pytest.approx((10.0 + (1 + 2 * SQ3) * R_S, 50.0))
    for g, lab in enumerate(system.labels):
        assert labels[lab].get_position() == pytest.approx(tuple(system.pos0[g] * 1e3))


def test_fig1_solid_contacts_clamps_and_free_edges(fig1):
    contacts = D.tagged(fig1, "a", "solid-contact")
    xy = {name: tuple(line.get_xydata()[0]) for name, line in contacts.items()}
    left = sorted(y for x, y in xy.values() if abs(x) < 1e-9)
    right = sorted(y for x, y in xy.values() if abs(x - 10.0) < 1e-9)
    np.testing.assert_allclose(left, [10, 30, 50, 70, 90])
    np.testing.assert_allclose(right, [30, 40, 50, 60, 70])
    clamps = D.tagged(fig1, "a", "clamp")
    np.testing.assert_allclose(clamps["bottom"].get_xydata(), [(0, 0), (10, 0)], atol=1e-9)
    np.testing.assert_allclose(clamps["top"].get_xydata(), [(0, 100), (10, 100)], atol=1e-9)
    assert set(D.tagged(fig1, "a", "free-edge")) == {"left", "right"}


def test_fig1_shock_arrows_at_both_paper_sites(fig1):
    shocks = D.tagged(fig1, "a", "shock")
    assert set(shocks) == {"LSGM:3", "SSGM:C"}
    centres = {"LSGM:3": (np.array([-(1 + 2 * SQ3) * R_L, 50.0]), R_L, (1.0, 0.0)),
               "SSGM:C": (np.array([10.0 + (1 + 2 * SQ3) * R_S, 50.0]), R_S, (-1.0, 0.0))}
    for name, (c, R, direction) in centres.items():
        tail, head = _arrow(shocks[name])
        np.testing.assert_allclose(_unit(head - tail), direction, atol=1e-12)
        # drawn inside the disc, so it never crosses the outer wall it touches
        assert np.hypot(*(tail - c)) < R and np.hypot(*(head - c)) < R
    assert {t.get_text() for t in D.tagged(fig1, "a", "shock-label").values()} == {"F(t)"}


def test_fig1_closeup_normal_and_tangent_vectors(fig1):
    normals = D.tagged(fig1, "b", "normal")
    tangents = D.tagged(fig1, "b", "tangent")
    assert set(normals) == set(tangents) == {"LSGM:12", "LSGM:12-LSGM:8"}
    # granule-solid: n_ik toward the solid (+x), t_ik = k x n_ik = +y
    tail, head = _arrow(normals["LSGM:12"])
    np.testing.assert_allclose(tail, (0.0, 50.0), atol=1e-9)
    np.testing.assert_allclose(_unit(head - tail), (1.0, 0.0), atol=1e-12)
    tail, head = _arrow(tangents["LSGM:12"])
    np.testing.assert_allclose(_unit(head - tail), (0.0, 1.0), atol=1e-12)
    # granule 12 (x = -R, y = 50) to granule 8 (x = -R - R sqrt3, y = 60): n = (-sqrt3/2, 1/2)
    tail, head = _arrow(normals["LSGM:12-LSGM:8"])
    np.testing.assert_allclose(tail, (-R_L - R_L * SQ3 / 2, 55.0), atol=1e-9)
    np.testing.assert_allclose(_unit(head - tail), (-SQ3 / 2, 0.5), atol=1e-12)
    tail, head = _arrow(tangents["LSGM:12-LSGM:8"])
    np.testing.assert_allclose(_unit(head - tail), (-0.5, -SQ3 / 2), atol=1e-12)
    # the inset's rigid layer: R/10 of granule 12 = 1 mm
    tail, head = _arrow(D.tagged(fig1, "b", "layer-span")["LSGM:12"])
    assert abs(abs(head[1] - tail[1]) - 1.0) < 1e-9


def test_fig1_beam_scenario_and_missing_solid(paper):
    sc_beam = S.load("paper", ['solid.kind="beam"'])
    fig = X.figure1(sc_beam)
    try:
        assert set(D.tagged(fig, "a", "solid")) == {"beam"}
        assert len(D.tagged(fig, "a", "wall")) == 6
        assert set(D.tagged(fig, "a", "shock")) == {"LSGM:3", "SSGM:C"}
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="no solid"):
        X.figure1(paper[0].model_copy(update={"solid": None}))
    with pytest.raises(ValueError, match="no solid"):
        X.fig2_meshes(paper[0].model_copy(update={"solid": None}), "/nonexistent/never")


def test_swapped_shock_mirrors_the_excited_granule(paper):
    sc, system = paper
    label, exc = G.swapped_shock(sc, system)
    assert label == "SSGM:C" and exc.direction == (-1.0, 0.0)
    sc_c = S.load("paper", ['excitations.0.granule="SSGM:C"'])
    label, exc = G.swapped_shock(sc_c, system)
    assert label == "LSGM:3" and exc.direction == (1.0, 0.0)


# ------------------------------------------------------------------ Fig. 2


def test_fig2_plate_panel_draws_every_element(fig2, paper, plate):
    sc, _ = paper
    mesh = D.tagged(fig2, "b", "elements")[""]
    # independent count: nx across (scenario) times ny along (Q8 edge: 2 ny + 1 nodes)
    on_edge = np.sum(np.abs(plate.nodes[:, 0]) < 1e-12)
    ny = (on_edge - 1) // 2
    assert len(mesh.get_paths()) == plate.nelements == sc.solid.mesh.nx * ny
    title = fig2.axes[1].get_title()
    assert f"{plate.nelements} Q8 elements" in title and f"{plate.ndof} DOFs" in title


@pytest.mark.parametrize("panel, name, edge, R", [("c", "LSGM:12", 0.0, 0.010), ("d", "SSGM:L", 0.010, 0.005)])
def test_fig2_rigid_layer_closeups(fig2, plate, panel, name, edge, R):
    expected = R / 10  # the paper's rigid layer length
    tail, head = _arrow(D.tagged(fig2, panel, "layer-span")[name])
    assert abs(abs(head[1] - tail[1]) / 1e3 - expected) < 1e-12
    assert f"{expected * 1e3:.2f} mm" in D.tagged(fig2, panel, "layer-label")[name].get_text()
    # highlighted nodes = the plate nodes on the edge within the layer (5: two Q8 elements)
    ours = np.flatnonzero((np.abs(plate.nodes[:, 0] - edge) < 1e-12)
                          & (np.abs(plate.nodes[:, 1] - 0.05) <= expected / 2 + 1e-12))
    assert len(ours) == 5
    drawn = D.tagged(fig2, panel, "layer-nodes")[name].get_xydata() / 1e3
    np.testing.assert_allclose(sorted(map(tuple, drawn)), sorted(map(tuple, plate.nodes[ours])), atol=1e-15)
    assert len(D.tagged(fig2, panel, "layer-elements")[name].get_paths()) == 2
    layer = G.rigid_layer(plate, name)
    assert abs(layer.length - expected) < 1e-12 and abs(layer.centre - 0.05) < 1e-12


def test_rigid_layers_are_a_tenth_of_each_radius(paper, plate):
    _, system = paper
    for c in system.solid_contacts:
        layer = G.rigid_layer(plate, c.name)
        assert len(layer.nodes) == 5
        assert abs(layer.length - system.radius[c.granule] / 10) < 1e-12


def test_fig2_beam_marks_contacts_at_nodes(fig2, beam):
    marks = D.tagged(fig2, "a", "beam-contact")
    assert len(marks) == len(beam.contacts) == 10
    node_y = beam.nodes[:, 1] * 1e3
    heights = []
    for name, line in marks.items():
        y = line.get_xydata()[0, 1]
        assert np.min(np.abs(node_y - y)) < 1e-9
        heights.append(y)
    np.testing.assert_allclose(sorted(heights), sorted([10, 30, 50, 70, 90, 30, 40, 50, 60, 70]), atol=1e-9)
    assert len(D.tagged(fig2, "a", "beam-nodes")[""].get_xydata()) == 41
    title = fig2.axes[0].get_title()
    assert "40 Hermite elements" in title and "78 DOFs" in title


def test_fig2_from_a_beam_scenario_still_draws_the_plate(plate):
    fig = X.figure2(S.load("paper", ['solid.kind="beam"']))
    try:
        assert len(D.tagged(fig, "b", "elements")[""].get_paths()) == plate.nelements
        assert set(D.tagged(fig, "c", "layer-span")) == {"LSGM:12"}
        assert set(D.tagged(fig, "d", "layer-span")) == {"SSGM:L"}
    finally:
        plt.close(fig)
