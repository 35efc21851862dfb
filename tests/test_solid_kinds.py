"""Every kind of solid behind one protocol (`solid.base.SolidKind`, docs/solids.md "Kinds of solid"):
each registered kind against what the layers above ask of it, and no module outside `solid/`
testing a kind's name."""

from __future__ import annotations

import re
import typing
from pathlib import Path

import numpy as np
import pytest

from granel import scenario as S
from granel.scenario.schema import SolidSpec
from granel.solid.kinds import KINDS, is_elastic, kind_of

SRC = Path(__file__).resolve().parents[1] / "src" / "granel"
# the elastic kinds, built from the paper's scenario with its contacts
ELASTIC = [name for name, kind in KINDS.items() if kind.elastic]


@pytest.fixture(scope="module")
def models():
    sc = S.load("paper")
    system, _, _ = S.build_granular(sc)
    out = {}
    for name, kind in KINDS.items():
        extra = {"tension": "solid.tension=100.0", "surface_elements": "solid.surface_elements=40"}
        s = S.load("paper", [f'solid.kind="{name}"', *(v for f, v in extra.items() if f in kind.fields)])
        out[name] = S.build_solid(s, system), s.solid
    return out


def test_the_schema_offers_exactly_the_registered_kinds():
    offered = set(typing.get_args(SolidSpec.model_fields["kind"].annotation))
    assert offered == set(KINDS) | {"none"}


def test_an_unknown_kind_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match="unknown solid kind 'cord'.*plate.*beam.*rigid"):
        kind_of("cord")
    assert not is_elastic("cord") and not is_elastic("rigid") and is_elastic("plate")


@pytest.mark.parametrize("name", list(KINDS))
def test_a_kind_builds_what_it_says(models, name):
    """The built model carries the kind's name, and the estimate before the build (`size`, which
    the memory check reads) is a lower bound on its DOFs before clamping and on its elements."""
    model, section = models[name]
    kind = kind_of(model)
    assert kind is KINDS[name] and model.kind == name
    dofs, elements = kind.size(section)
    if kind.elastic:
        assert 0 < dofs <= model.T.shape[0] and 0 < elements <= model.nelements
    else:
        assert model.ndof == 0 and (dofs, elements) == (0, 0)


@pytest.mark.parametrize("name", ELASTIC)
def test_energy_cells_integrate_back_to_the_solid_energy(models, name):
    """The energy density w of eq. (14) on a kind's cells, times each cell's volume (its area times
    the out-of-plane thickness), sums to the solid's kinetic plus strain energy (eq. 11): an
    identity (each cell holds its mean), so the tolerance is the round-off of a few thousand terms."""
    model, _ = models[name]
    rng = np.random.default_rng(4)
    q, v = rng.normal(size=model.ndof) * 1e-7, rng.normal(size=model.ndof) * 1e-2
    cells = kind_of(model).energy_cells(model, q, v)
    assert cells.polygons.shape[0] == cells.values.shape[0] and cells.polygons.shape[2] == 2
    x, y = cells.polygons[..., 0], cells.polygons[..., 1]
    area = 0.5 * np.abs((x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y).sum(axis=1))  # shoelace
    total = float((cells.values * area).sum()) * model.recipe.thickness
    assert total == pytest.approx(sum(model.energy(q, v)), rel=1e-10)


@pytest.mark.parametrize("name", list(KINDS))
def test_the_shape_lies_in_the_box_and_the_box_holds_the_contacts(models, name):
    model, _ = models[name]
    kind = kind_of(model)
    x0, y0, x1, y1 = kind.box(model)
    assert x1 > x0 and y1 > y0
    scale = 1e-9 * max(x1 - x0, y1 - y0)
    for c in model.contacts:
        assert x0 - scale <= c.position[0] <= x1 + scale and y0 - scale <= c.position[1] <= y1 + scale
    if not kind.elastic:
        with pytest.raises(ValueError, match="rigid"):
            kind.shape(model)
        return
    shape = kind.shape(model)
    pts = shape.polygons.reshape(-1, 2) if shape.polygons is not None else shape.line
    assert pts[:, 0].min() >= x0 - scale and pts[:, 0].max() <= x1 + scale
    assert pts[:, 1].min() >= y0 - scale and pts[:, 1].max() <= y1 + scale
    # a deformed shape moves by exactly scale * u
    u = np.zeros((len(model.nodes), 2))
    u[:, 0] = 1.0
    moved = kind.shape(model, u, 2e-3)
    got = moved.polygons if moved.polygons is not None else moved.line
    ref = shape.polygons if shape.polygons is not None else shape.line
    np.testing.assert_allclose(got[..., 0] - ref[..., 0], 2e-3, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ELASTIC)
def test_export_cells_are_the_elements_and_the_stress_is_per_cell(models, name):
    model, _ = models[name]
    kind = kind_of(model)
    cells = kind.export_cells(model)
    assert sum(len(c) for _, c in cells) == model.nelements
    x = model.T @ np.zeros(model.ndof)
    stress = kind.stress(model, x, model.recipe.E, model.recipe.nu)
    assert stress and all(s.shape == (model.nelements,) and np.isfinite(s).all() for s in stress.values())
    # at rest only a prestress remains (the string's tension T / A)
    assert all(not s.any() for name, s in stress.items() if name != "tension_stress")


@pytest.mark.parametrize("name", ELASTIC)
def test_wave_lines_interpolate_with_a_partition_of_unity(models, name):
    """Each sample is a weighted sum of nodal deflections whose weights sum to 1 (the interpolation
    reproduces a uniform motion), and samples at a node read that node's deflection alone."""
    model, _ = models[name]
    lines = kind_of(model).wave_lines(model)
    ys = model.nodes[1:-1:4, 1]  # interior nodes of the drawn line (every kind samples its nodes there)
    S_ = lines.sampler(ys).toarray().reshape(len(lines.x), len(lines.components), len(ys), -1)
    np.testing.assert_allclose(S_[:, 0].sum(axis=-1), 1.0, rtol=0, atol=1e-12)
    assert lines.mass.shape == lines.x.shape and (lines.mass > 0).all() and lines.count >= 2


# what a branch on a kind's name looks like: `kind == "beam"`, `.kind in ("plate", ...)`
BRANCH = re.compile(r"""kind\s*(==|!=|in|not in)\s*\(?\s*["'](%s)["']""" % "|".join(KINDS))


def test_no_module_outside_the_solids_tests_a_kind_by_name():
    offenders = []
    for path in SRC.rglob("*.py"):
        if path.parent.name == "solid":
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if BRANCH.search(line):
                offenders.append(f"{path.relative_to(SRC)}:{n}: {line.strip()}")
    assert not offenders, "branches on a solid's kind outside solid/:\n" + "\n".join(offenders)
