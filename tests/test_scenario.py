"""Scenario validation: every invalid input fails at load time naming the field and value."""

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st, HealthCheck

from granel import scenario as S


@pytest.fixture(scope="module")
def paper_raw():
    raw, _ = S.load_raw("paper")
    return raw


def test_paper_scenario_geometry(paper_raw):
    sc = S.validate(copy.deepcopy(paper_raw))
    system, state, media = S.build_granular(sc)
    lab = system.labels
    p = {l: system.pos0[i] for i, l in enumerate(lab)}
    R, r = 0.01, 0.005
    # MODEL.md section 1
    for k, y in zip(range(10, 15), [0.01, 0.03, 0.05, 0.07, 0.09]):
        assert p[f"LSGM:{k}"] == pytest.approx([-R, y], abs=1e-15)
    for k, y in zip(range(6, 10), [0.02, 0.04, 0.06, 0.08]):
        assert p[f"LSGM:{k}"] == pytest.approx([-R - R * math.sqrt(3), y], abs=1e-15)
    for k, y in zip(range(1, 6), [0.01, 0.03, 0.05, 0.07, 0.09]):
        assert p[f"LSGM:{k}"] == pytest.approx([-R - 2 * R * math.sqrt(3), y], abs=1e-15)
    for k, y in zip("JKLMN", [0.03, 0.04, 0.05, 0.06, 0.07]):
        assert p[f"SSGM:{k}"] == pytest.approx([0.01 + r, y], abs=1e-15)
    for k, y in zip("ABCDE", [0.03, 0.04, 0.05, 0.06, 0.07]):
        assert p[f"SSGM:{k}"] == pytest.approx([0.01 + r + 2 * r * math.sqrt(3), y], abs=1e-15)
    walls = {w.name: w for w in system.walls}
    assert walls["LSGM:bottom"].p0[1] == pytest.approx(0.0, abs=1e-15)
    assert walls["LSGM:top"].p0[1] == pytest.approx(0.1)
    assert walls["SSGM:bottom"].p0[1] == pytest.approx(0.025)
    assert walls["SSGM:top"].p0[1] == pytest.approx(0.075)
    # three rigid walls per medium (MODEL.md sec. 1): the outer ones touch granules 1..5 and A..E
    assert len(system.walls) == 6
    lo, so = walls["LSGM:outer"], walls["SSGM:outer"]
    assert lo.p0[0] == lo.p1[0] == pytest.approx(-2 * R - 2 * R * math.sqrt(3), abs=1e-15)
    assert so.p0[0] == so.p1[0] == pytest.approx(0.01 + 2 * r + 2 * r * math.sqrt(3), abs=1e-15)
    assert lo.normal == (1.0, 0.0) and so.normal == (-1.0, 0.0)  # pointing into the media
    assert sorted((lo.p0[1], lo.p1[1])) == pytest.approx([0.0, 0.1]) and sorted((so.p0[1], so.p1[1])) == pytest.approx([0.025, 0.075])
    free = S.build_granular(S.validate(S.apply_overrides(paper_raw, ["media.0.outer_wall=false", "media.1.outer_wall=false"])))[0]
    assert sorted(w.name for w in free.walls) == ["LSGM:bottom", "LSGM:top", "SSGM:bottom", "SSGM:top"]
    assert [c.name for c in system.solid_contacts] == [f"LSGM:{k}" for k in range(10, 15)] + [f"SSGM:{k}" for k in "JKLMN"]
    assert system.excitations[0].granule == lab.index("LSGM:3")
    assert system.excitations[0].direction == (1.0, 0.0)
    assert system.excitations[0].history.params[0] == 1591.6
    assert system.mass[0] == pytest.approx(4 / 3 * math.pi * R**3 * 7850)


@pytest.mark.parametrize(
    "override, field",
    [
        ("media.0.radius=-0.01", "media.0.radius"),
        ("materials.steel.E=0", "materials.steel.E"),
        ("materials.steel.nu=0.7", "materials.steel.nu"),
        ('excitations.0.granule="LSGM:99"', "excitations.0.granule"),
        ('excitations.0.granule="XSGM:1"', "excitations.0.granule"),
        ("contact.friction=0.2", "contact.friction"),
        ("bogus=1", "bogus"),
        ('simulation.dt="5us"', "simulation.dt"),
        ('simulation.dt="-1ns"', "simulation.dt"),
        ('simulation.duration="fast"', "simulation.duration"),
        ("media.0.gap=-0.001", "media.0.gap"),
        ('excitations.0.shock="huge"', "excitations.0.shock"),
        ('solid.kind="shell"', "solid.kind"),
        ('media.0.material="wood"', "media.0.material"),
        ("solid.width=0", "solid.width"),
        ("solid.x0=1e4", "solid.x0"),  # positions beyond 1 km lose the digits an overlap needs (schema)
        ("solid.y0=-2e3", "solid.y0"),
        ("media.0.center_y=1e5", "media.0.center_y"),
        ("media.1.face_x=5e3", "media.1.face_x"),
    ],
)
def test_invalid_fields_are_named(paper_raw, override, field):
    raw = S.apply_overrides(paper_raw, [override])
    with pytest.raises(S.ScenarioError) as err:
        S.validate(raw)
    assert field in str(err.value)


def test_overlapping_granules_rejected(paper_raw):
    raw = copy.deepcopy(paper_raw)
    raw["media"].append({"name": "X", "granules_file": None, "side": "left", "radius": 0.01, "columns": [1], "center_y": 0.05})
    raw["media"][-1].pop("granules_file")
    with pytest.raises(S.ScenarioError, match=r"overlap"):
        S.validate(raw)


def test_granules_from_file(tmp_path):
    (tmp_path / "g.csv").write_text("label,x,y,radius\na,0,0,0.005\nb,0.0101,0,0.005\n")
    (tmp_path / "s.toml").write_text(
        """
name = "two"
solid = {kind = "rigid", x0 = 1.0}
[simulation]
duration = "0.1ms"
dt = "20ns"
[[media]]
name = "M"
side = "none"
granules_file = "g.csv"
[[initial_velocities]]
granule = "M:a"
v = [1.0, 0.0]
"""
    )
    sc = S.load(tmp_path / "s.toml")
    system, state, _ = S.build_granular(sc, sc.base)
    assert system.labels == ["M:a", "M:b"]
    assert state.vel[0, 0] == 1.0
    # per-granule materials
    (tmp_path / "g.csv").write_text("label,x,y,radius,material\na,0,0,0.005,\nb,0.0101,0,0.005,soft\n")
    text = (tmp_path / "s.toml").read_text()
    (tmp_path / "s.toml").write_text(text + "[materials.soft]\nE = 2e9\nrho = 1200.0\nnu = 0.4\n[materials.steel]\nE = 200e9\nrho = 7850.0\nnu = 0.3\n")
    sc = S.load(tmp_path / "s.toml")
    system, _, _ = S.build_granular(sc, sc.base)
    assert list(system.E) == [200e9, 2e9] and system.mass[1] == pytest.approx(4 / 3 * math.pi * 0.005**3 * 1200)
    (tmp_path / "g.csv").write_text("label,x,y,radius,material\na,0,0,0.005,wood\nb,0.0101,0,0.005,\n")
    with pytest.raises(S.ScenarioError, match="wood"):
        S.load(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(text)
    (tmp_path / "g.csv").write_text("label,x,y,radius\na,0,0,0.005\nb,0.0099,0,0.005\n")
    with pytest.raises(S.ScenarioError, match="overlap"):
        S.load(tmp_path / "s.toml")
    (tmp_path / "g.csv").write_text("label,x,y\na,0,0\n")
    with pytest.raises(S.ScenarioError, match="granules_file"):
        S.load(tmp_path / "s.toml")


def test_time_units():
    from granel.io.units import parse_time

    assert parse_time("0.8ms") == pytest.approx(8e-4)
    assert parse_time("40ns") == pytest.approx(4e-8)
    assert parse_time("1us") == pytest.approx(1e-6)
    assert parse_time(4e-8) == 4e-8
    with pytest.raises(ValueError):
        parse_time("3 parsecs")


FIELDS = [
    ("media.0.radius", st.floats(max_value=0.0, allow_nan=False)),
    ("media.1.radius", st.floats(max_value=0.0, allow_nan=False)),
    ("materials.steel.E", st.floats(max_value=0.0, allow_nan=False)),
    ("materials.steel.rho", st.floats(max_value=0.0, allow_nan=False)),
    ("materials.steel.nu", st.one_of(st.floats(min_value=0.5, allow_nan=False, allow_infinity=False), st.floats(max_value=-1.0, allow_nan=False, allow_infinity=False))),
    ("contact.mu", st.floats(max_value=-1e-12, allow_nan=False)),
    ("contact.k_s", st.floats(max_value=0.0, allow_nan=False)),
    ("media.0.columns", st.lists(st.integers(max_value=0), min_size=1, max_size=4)),
    ("excitations.0.granule", st.text(min_size=1, max_size=8).filter(lambda s: s not in {"LSGM:3"} and "\x00" not in s)),
    ("simulation.dt", st.floats(min_value=2e-6, max_value=1.0)),
    ("simulation.duration", st.one_of(st.floats(max_value=0.0, allow_nan=False), st.text(alphabet="xyz!", min_size=1, max_size=5))),
    ("solid.thickness", st.floats(max_value=0.0, allow_nan=False)),
]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_invalid_fields_give_clear_errors(paper_raw, data):
    """Any invalid value in any of these fields: a ScenarioError that names the field, never
    a traceback from inside the builder."""
    path, strategy = data.draw(st.sampled_from(FIELDS))
    value = data.draw(strategy)
    raw = copy.deepcopy(paper_raw)
    node = raw
    parts = path.split(".")
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node.setdefault(p, {})
    node[parts[-1]] = value
    with pytest.raises(S.ScenarioError) as err:
        S.validate(raw)
    assert path in str(err.value)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12), section=st.sampled_from(["", "simulation", "contact", "solid", "media.0", "excitations.0"]))
def test_unknown_fields_rejected(paper_raw, key, section):
    raw = copy.deepcopy(paper_raw)
    node = raw
    for p in [s for s in section.split(".") if s]:
        node = node[int(p)] if isinstance(node, list) else node[p]
    if key in node or (not section and key in S.Scenario.model_fields) or (section and key in _fields_of(section)):
        return
    node[key] = 1
    with pytest.raises(S.ScenarioError) as err:
        S.validate(raw)
    assert key in str(err.value) and "unknown field" in str(err.value)


def _fields_of(section):
    model = {"simulation": S.SimulationSpec, "contact": S.ContactSpec, "solid": S.SolidSpec,
             "media.0": S.MediumSpec, "excitations.0": S.ExcitationSpec}[section]
    return model.model_fields


@pytest.mark.parametrize("n", [1, 2, 300, 2500])
def test_close_pairs_match_a_kd_tree(n):
    """The neighbour search (direct below DIRECT_PAIRS granules, a k-d tree above) finds exactly
    the pairs scipy's k-d tree finds, on random points with a cut-off of a few spacings."""
    from scipy.spatial import cKDTree

    from granel.granular.neighbours import close_pairs

    pos = np.random.default_rng(n).uniform(0, 1, size=(n, 2))
    cutoff = 3.0 / np.sqrt(n)
    got = {tuple(p) for p in close_pairs(pos, cutoff)}
    want = {tuple(p) for p in cKDTree(pos).query_pairs(cutoff)}
    assert got == want and all(i < j for i, j in got)
