"""Scenario ergonomics: `--set key=-` removes a key or a list entry, and `granel show --resolved`
prints the scenario with every default, as TOML that reads back to the same scenario."""

import tomllib

import pytest
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app

runner = CliRunner()


def test_an_override_removes_a_list_entry_or_a_key():
    sc = S.load("paper", ["media.1=-"])
    assert [m.name for m in sc.media] == ["LSGM"]
    raw, _ = S.load_raw("paper")
    out = S.apply_overrides(raw, ["media.0=-", "media.0.radius=0.006", "excitations.0.tau=-"])
    assert [m["name"] for m in out["media"]] == ["SSGM"] and out["media"][0]["radius"] == 0.006
    assert "tau" not in out["excitations"][0]
    assert len(raw["media"]) == 2  # the original is untouched
    for bad in ("media.7=-", "contact.nothing=-", "media.x=-"):
        with pytest.raises(S.ScenarioError, match="nothing to remove"):
            S.apply_overrides(raw, [bad])


def test_show_resolved_prints_every_default_and_reads_back():
    res = runner.invoke(app, ["show", "paper", "--resolved", "--set", "media.1=-", "--set", "contact.mu=0.2"])
    assert res.exit_code == 0, res.output
    data = tomllib.loads(res.stdout)
    assert data["contact"]["mu"] == 0.2 and len(data["media"]) == 1
    for key in ("ledger_tol", "balance_limit", "overlap_limit", "equilibrate", "integrator"):
        assert key in data["simulation"]
    again = S.validate(data)
    assert S.to_toml(again) == res.stdout
    res = runner.invoke(app, ["show", "paper", "--resolved", "--set", "media.9=-"])
    assert res.exit_code == 2 and "nothing to remove" in " ".join(res.output.split())


def test_init_writes_a_valid_commented_template_and_never_replaces_a_file(tmp_path, monkeypatch):
    """`granel init demo`: demo.toml is the paper's scenario under another name (identical once
    resolved), with the schema's descriptions as comments; a second init refuses (exit 2) and
    leaves the file as it was."""
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["init", "demo"])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "demo.toml").read_text()
    assert "# Coulomb friction coefficient" in text and "# granules_file = ..." in text
    sc = S.load(str(tmp_path / "demo.toml"))
    paper = S.load("paper")
    assert sc.name == "demo"
    assert S.to_toml(sc.model_copy(update={"name": paper.name, "description": paper.description})) == S.to_toml(paper)
    (tmp_path / "demo.toml").write_text(text + "# mine\n")
    res = runner.invoke(app, ["init", "demo"])
    assert res.exit_code == 2 and "never replaces" in " ".join(res.output.split())
    assert (tmp_path / "demo.toml").read_text().endswith("# mine\n")
    assert runner.invoke(app, ["init", "../x"]).exit_code == 2


def test_a_scenario_without_a_solid(tmp_path):
    """`solid.kind = "none"`: two steel granules (R = 5 mm) in head-on collision, nothing else:
    no solid contact, no solid energy, momentum conserved to round-off, and the rebound speeds
    those of an elastic collision of equal masses (exchanged) within 1e-6 of the impact speed;
    a hexagonal medium can be placed without a solid beside it."""
    import numpy as np

    from granel.run import run_scenario

    (tmp_path / "two.csv").write_text("label,x,y,radius\nA,0.0,0.0,0.005\nB,0.0101,0.0,0.005\n")
    (tmp_path / "two.toml").write_text("""name = "two"
[simulation]
duration = "250us"
output_every = "1us"
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "none"
[[media]]
name = "G"
side = "none"
granules_file = "two.csv"
[[initial_velocities]]
granule = "G:A"
v = [1.0, 0.0]
""")
    ds = run_scenario(S.load(str(tmp_path / "two.toml")))
    assert ds.attrs["solid_kind"] == "rigid" and ds.sizes.get("contact", 0) == 0
    assert np.abs(ds["energy_solid"].values).max() == 0.0
    p = ds["v_x"].values.sum(axis=1)
    assert np.abs(p - 1.0).max() < 1e-12
    assert ds["v_x"].values[-1, 0] == pytest.approx(0.0, abs=1e-6) and ds["v_x"].values[-1, 1] == pytest.approx(1.0, abs=1e-6)
    hexa = S.load("paper", ['solid.kind="none"', "media.1=-"])
    from granel.scenario.build import build_granular

    system, _, _ = build_granular(hexa, hexa.base)
    assert system.n == 14 and not system.solid_contacts


def test_a_hexagonal_medium_anywhere():
    """`media.N.face_x` (with `center_y`) places a hexagonal medium away from any solid: the
    paper's SSGM (R = 5 mm, columns 5, 4, 5) grown rightward from x = 0.3, centred on y = -0.2,
    has column 0 at x = 0.305 and its channel walls 5 mm beyond its outer granules."""
    import numpy as np

    from granel.scenario.build import build_granular

    sc = S.load("paper", ['solid.kind="none"', "media.0=-", "media.0.face_x=0.3", "media.0.center_y=-0.2",
                          'excitations.0.granule="SSGM:C"'])
    system, _, _ = build_granular(sc, sc.base)
    x, y = system.pos0[:, 0], system.pos0[:, 1]
    assert x.min() == pytest.approx(0.305, abs=1e-12)
    assert x.max() == pytest.approx(0.305 + 2 * 0.005 * np.sqrt(3), abs=1e-12)
    col0 = np.isclose(x, 0.305)
    assert col0.sum() == 5 and np.mean(y[col0]) == pytest.approx(-0.2, abs=1e-12)
    walls = {w.name: w for w in system.walls}
    assert walls["SSGM:bottom"].p0[1] == pytest.approx(y.min() - 0.005)
    assert walls["SSGM:top"].p0[1] == pytest.approx(y.max() + 0.005)


GROWTH_MAP = {"right": (1, 0), "left": (-1, 0), "up": (0, 1), "down": (0, -1)}


def _box(grow: str, *more: str) -> S.Scenario:
    """The paper's SSGM (R = 5 mm, columns 5, 4, 5) away from any solid, grown from a face line
    through the origin, 0.1 mm from its first column, and closed by all four walls."""
    channel = '"left", "right"' if grow in ("up", "down") else '"bottom", "top"'
    return S.load("paper", ['solid.kind="none"', "media.0=-", 'media.0.side="none"', f'media.0.grow="{grow}"',
                            f'media.0.walls=[{channel}, "outer", "face"]', "media.0.gap=0.0001",
                            "media.0.outer_wall=-", 'excitations.0.granule="SSGM:C"',
                            "excitations.0.direction=[0.0, 1.0]", *more])


@pytest.mark.parametrize("grow", ["left", "up", "down"])
def test_a_hexagonal_medium_grows_in_any_direction(grow):
    """The same packing grown left, up or down is the rightward one mapped by the reflection that
    takes +x to the growth direction: granules (same labels, same order) and the four walls
    (names, segments, inward normals) to 1e-15 m."""
    import numpy as np

    from granel.scenario.build import build_granular

    def geometry(sc):
        system, _, _ = build_granular(sc, sc.base)
        walls = {w.name: (np.array([w.p0, w.p1]), np.array(w.normal)) for w in system.walls}
        return system, walls

    ref, ref_walls = geometry(_box("right"))
    got, got_walls = geometry(_box(grow))
    gx, gy = GROWTH_MAP[grow]
    # right -> this growth: (x, y) -> x e_grow + y e_along, e_along = +y for left, +x for up/down
    M = np.array([[gx, 0.0], [0.0, 1.0]]) if grow == "left" else np.array([[0.0, 1.0], [gy, 0.0]])
    assert got.labels == ref.labels
    np.testing.assert_allclose(got.pos0, ref.pos0 @ M.T, atol=1e-15)
    rename = {"bottom": "left", "top": "right"} if grow in ("up", "down") else {}
    assert len(got_walls) == 4
    for name, (seg, nrm) in ref_walls.items():
        side = name.split(":")[1]
        seg2, nrm2 = got_walls[f"SSGM:{rename.get(side, side)}"]
        np.testing.assert_allclose(sorted(map(tuple, seg2)), sorted(map(tuple, seg @ M.T)), atol=1e-15)
        np.testing.assert_allclose(nrm2, M @ nrm, atol=0)


@pytest.mark.parametrize("grow", ["right", "left", "up", "down"])
def test_a_granule_rattles_elastically_in_a_closed_box(grow):
    """One steel granule (R = 5 mm) between its face wall, 0.1 mm away, and its outer wall, which
    it touches, thrown at 1 m/s into the outer wall (no friction, no damping): it bounces off the
    outer wall, then the face wall, and moves at +1 m/s along the growth again, its speed kept
    to 1e-6 and the two walls (and no other) having pushed it, in every growth direction."""
    import numpy as np

    from granel.run import run_scenario

    gx, gy = GROWTH_MAP[grow]
    sc = _box(grow, "media.0.columns=[1]", 'media.0.labels=["g"]', "excitations=-", "contact.mu=0.0",
              "contact.alpha_n=0.0", 'simulation.duration="200us"', 'simulation.output_every="1us"',
              f'initial_velocities=[{{granule = "SSGM:g", v = [{float(gx)}, {float(gy)}]}}]')
    assert sc.media[0].columns == [1]
    ds = run_scenario(sc)
    vx, vy = ds["v_x"].values[:, 0], ds["v_y"].values[:, 0]
    along = vx * gx + vy * gy
    t = ds["time"].values
    assert along[0] == pytest.approx(1.0, abs=1e-12)
    mid = (t > 30e-6) & (t < 120e-6)  # between the bounces (t_c = 27 us; 0.1 mm at 1 m/s)
    np.testing.assert_allclose(along[mid], -1.0, atol=1e-6)
    assert along[-1] == pytest.approx(1.0, abs=1e-6)  # measured 4.4e-8 at the default tolerances
    np.testing.assert_allclose(vx * gy - vy * gx, 0.0, atol=1e-12)
    push = np.abs(ds["wall_force_normal"].values).max(axis=0)
    names = [str(n) for n in ds["wall"].values]
    assert {n for n, f in zip(names, push) if f > 0} == {"SSGM:outer", "SSGM:face"}


def test_one_version():
    """The package, its installed metadata and CITATION.cff give the same version."""
    from importlib.metadata import version
    from pathlib import Path

    import granel

    cff = (Path(__file__).resolve().parents[1] / "CITATION.cff").read_text()
    line = next(x for x in cff.splitlines() if x.startswith("version:"))
    assert line.split(":", 1)[1].strip() == granel.__version__ == version("granel")


@pytest.mark.parametrize("over, says", [
    (['media.1.grow="up"'], "grows to the right"),
    (['media.1.side="none"'], "needs a growth direction"),
    (['media.1.face_y=0.1'], "face_y: not used"),
    (['media.1.side="none"', 'media.1.grow="down"', "media.1.center_y=0.1"], "center_y: not used"),
    (['media.1.walls=["left"]', "media.1.channel_walls=-", "media.1.outer_wall=-"], "'left' is not a wall"),
    (['media.1.walls=["bottom", "face"]', "media.1.channel_walls=-", "media.1.outer_wall=-"], "solid's face"),
    (['media.1.walls=["bottom", "top"]'], "contradicts outer_wall = true"),
    (['media.1.walls=["north"]'], "media.1.walls.0"),
    (['media.1.walls=["top", "top"]', "media.1.channel_walls=-", "media.1.outer_wall=-"], "names a wall twice"),
])
def test_a_misplaced_medium_is_refused_naming_the_field(over, says):
    with pytest.raises(S.ScenarioError) as err:
        S.load("paper", over)
    assert says in str(err.value) and "media.1" in str(err.value)


def test_a_scenario_without_contact_says_the_paper_law_applies(tmp_path):
    """Leaving out [contact] runs the paper's friction and damping: `granel run` says so (on
    stderr, once) and the result records them; a scenario with [contact] gets no note."""
    (tmp_path / "two.csv").write_text("label,x,y,radius\nA,0.0,0.0,0.005\nB,0.0101,0.0,0.005\n")
    body = """name = "two"
[simulation]
duration = "20us"
[solid]
kind = "none"
[[media]]
name = "G"
side = "none"
granules_file = "two.csv"
"""
    (tmp_path / "two.toml").write_text(body)
    res = runner.invoke(app, ["run", str(tmp_path / "two.toml"), "-o", str(tmp_path / "a.nc")])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert text.count("no [contact] table") == 1 and "mu = 0.099" in text and "alpha_n = 0.006313" in text
    from granel.io.results import read_netcdf

    assert "mu = 0.099" in read_netcdf(tmp_path / "a.nc").attrs["scenario"]
    (tmp_path / "two.toml").write_text(body + "[contact]\nmu = 0.0\n")
    res = runner.invoke(app, ["run", str(tmp_path / "two.toml"), "-o", str(tmp_path / "b.nc")])
    assert res.exit_code == 0 and "[contact]" not in res.output


CHAIN = """name = "chain"
[simulation]
duration = "200us"
output_every = "1us"
[contact]
mu = 0.0
alpha_n = 0.0
[materials.steel]
E = 200e9
rho = 7850.0
nu = 0.3
[materials.aluminium]
E = 70e9
rho = 2700.0
nu = 0.33
[solid]
kind = "none"
[[media]]
name = "C"
side = "none"
grow = "right"
face_x = 0.01
radii = [0.003, 0.005, 0.004]
materials = ["steel", "aluminium", "steel"]
walls = ["face"]
"""


def test_a_chain_of_beads_of_their_own_radius_and_material(tmp_path):
    """`media.N.radii` (and `materials`): a straight chain of touching beads from a face line.
    Geometry: centres at 13, 21 and 30 mm from radii 3, 5, 4 mm grown right from x = 10 mm, label
    1 the outermost; masses from each bead's own density. Physics: the outer steel bead (4 mm)
    thrown at 1 m/s into the aluminium one (5 mm), the two alone, leaves as an elastic collision of
    unequal masses does: v1' = (m1 - m2) v / (m1 + m2), v2' = 2 m1 v / (m1 + m2) within 1e-6 of v
    (the contact, with the mixed-material E* of eq. (4), lasts about 20 us of the 60)."""
    import math

    import numpy as np

    from granel.run import run_scenario
    from granel.scenario.build import build_granular

    (tmp_path / "c.toml").write_text(CHAIN)
    sc = S.load(str(tmp_path / "c.toml"))
    system, _, _ = build_granular(sc, sc.base)
    assert system.labels == ["C:1", "C:2", "C:3"]
    np.testing.assert_allclose(system.pos0[:, 0], [0.030, 0.021, 0.013], atol=1e-15)
    np.testing.assert_allclose(system.radius, [0.004, 0.005, 0.003])
    m = [4 / 3 * math.pi * r**3 * rho for r, rho in ((0.004, 7850.0), (0.005, 2700.0), (0.003, 7850.0))]
    np.testing.assert_allclose(system.mass, m, rtol=1e-12)
    assert [w.name for w in system.walls] == ["C:face"]
    # two beads alone (no wall): the outer steel bead thrown into the aluminium one
    (tmp_path / "c.toml").write_text(CHAIN.replace('duration = "200us"', 'duration = "60us"') +
                                     '[[initial_velocities]]\ngranule = "C:1"\nv = [-1.0, 0.0]\n')
    ds = run_scenario(S.load(str(tmp_path / "c.toml"), ["media.0.radii=[0.005, 0.004]", 'media.0.materials=["aluminium", "steel"]',
                                                         "media.0.walls=[]"]))
    v = ds["v_x"].values[-1]
    m1, m2 = m[0], m[1]
    assert abs(v[0] - (-(m1 - m2) / (m1 + m2))) < 1e-6 and abs(v[1] - (-2 * m1 / (m1 + m2))) < 1e-6
    # a striker is a run's input: its kinetic energy, 1/2 m v^2, is the energy the metrics scale by
    from granel.analysis.reciprocity import run_metrics

    r = run_metrics(ds, "C:2")
    assert r["excited"] == "C:1" and r["input_work_J"] == pytest.approx(0.5 * m1, rel=1e-12)
    assert r["energy_far_final_frac"] == pytest.approx(1.0, abs=1e-6)  # one medium: all of it, kept


@pytest.mark.parametrize("over, says", [
    (['media.0.radius=0.005'], "a chain (radii) takes neither"),
    (['media.0.materials=["steel"]'], "materials: 1 given for 3 beads"),
    (['media.0.materials.1="lead"'], "media.0.materials.1: unknown material 'lead'"),
    (['media.0.walls=["top"]'], "not a wall of a chain"),
    (['media.0.radii=[0.003, -0.001]', "media.0.materials=-"], "media.0.radii.1"),
])
def test_a_bad_chain_is_refused_naming_the_field(tmp_path, over, says):
    (tmp_path / "c.toml").write_text(CHAIN)
    with pytest.raises(S.ScenarioError) as err:
        S.load(str(tmp_path / "c.toml"), over)
    assert says in " ".join(str(err.value).split())
