"""Narrowband loads and the forces on walls: a granule held against a wall by a constant load
(Hertz's static overlap), and the momentum balance of a driven medium against its walls and a
rigid solid."""

import math

import numpy as np
import pytest

from granel import scenario as S
from granel.run import run_scenario


def _one_granule(tmp_path, overlap_factor=1.0, force=10.0):
    """A steel granule (R = 5 mm) pressed by `force` against a wall at x = R - delta0, delta0 the
    static Hertz overlap (F / A)^(2/3) with A = 4/3 E/(1 - nu^2) sqrt(R) (eq. 2, rigid wall)."""
    R, E, nu = 0.005, 200e9, 0.3
    d0 = (force / (4 / 3 * E / (1 - nu**2) * math.sqrt(R))) ** (2 / 3) * overlap_factor
    (tmp_path / "one.csv").write_text("label,x,y,radius\nA,0.0,0.0,0.005\n")
    (tmp_path / "one.toml").write_text(f"""name = "one"
[simulation]
duration = "10us"
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "G"
side = "none"
granules_file = "one.csv"
radius = 0.005
[[walls]]
p0 = [{R - d0!r}, -0.01]
p1 = [{R - d0!r}, 0.01]
normal = [-1.0, 0.0]
name = "right"
[[excitations]]
granule = "G:A"
kind = "constant"
value = {force!r}
direction = [1.0, 0.0]
""")
    return S.load(str(tmp_path / "one.toml"))


def test_wall_force_of_a_granule_at_hertz_equilibrium(tmp_path):
    """At the static Hertz overlap the granule stays put and the wall takes the load: 10 N to
    round-off, no tangential force, at every output."""
    ds = run_scenario(_one_granule(tmp_path))
    assert list(ds["wall"].values) == ["right"]
    np.testing.assert_allclose(ds["wall_force_normal"].values[:, 0], 10.0, rtol=1e-12)
    assert np.abs(ds["wall_force_tangential"].values).max() == 0.0
    assert np.abs(ds["v_x"].values).max() < 1e-12


def test_momentum_balance_against_walls_and_the_solid():
    """The SSGM of the paper's walled geometry driven harmonically against a rigid solid: the
    granules' total momentum changes by the time integral of the load minus the forces the three
    walls and the solid's contacts take (Simpson on outputs every 0.05 us, 20 us), in x and y."""
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', 'excitations.0.kind="harmonic"',
                          "excitations.0.amplitude=200.0", "excitations.0.frequency=50e3", "excitations.0.ramp_cycles=0.5",
                          'simulation.duration="20us"', 'simulation.output_every="0.05us"'])
    ds = run_scenario(sc)
    ssgm = ds["medium"].values == "SSGM"
    from granel.scenario.build import build_problem  # noqa: F401  (the system: masses, load, normals)

    problem = S.build_problem(sc)
    system = problem.system
    m = system.mass
    t = ds["time"].values
    P = np.stack([(m * ds["v_x"].values).sum(axis=1), (m * ds["v_y"].values).sum(axis=1)], axis=1)
    e = system.excitations[0]
    load = np.array([e.history(tt) for tt in t])[:, None] * (np.asarray(e.direction) / np.hypot(*e.direction))
    nrm = np.array([np.asarray(w.normal, float) / np.hypot(*w.normal) for w in system.walls])
    tan = np.array([(np.asarray(w.p1, float) - w.p0) / np.hypot(*(np.asarray(w.p1, float) - w.p0)) for w in system.walls])
    walls = -ds["wall_force_normal"].values[:, :, None] * nrm + ds["wall_force_tangential"].values[:, :, None] * tan
    cn = np.array([c.normal for c in system.solid_contacts], float)
    ct = np.stack([-cn[:, 1], cn[:, 0]], axis=1)
    solid = ds["contact_force_normal"].values[:, :, None] * cn + ds["contact_force_tangential"].values[:, :, None] * ct
    net = load - walls.sum(axis=1) - solid.sum(axis=1)
    from scipy.integrate import simpson

    assert ssgm.sum() == 14 and np.abs(P[:, 0]).max() > 1e-4  # the drive moved the medium
    impulse = np.array([[simpson(net[: k + 1, d], x=t[: k + 1]) for d in range(2)] for k in range(0, len(t), 40)])
    np.testing.assert_allclose(P[::40] - P[0], impulse, rtol=0, atol=2e-4 * np.abs(P[:, 0]).max())


def chain_scenario(tmp_path, n=10, preload=10.0, extra=""):
    """A monatomic chain of steel beads (R = 5 mm) along x, touching, against a wall at its far
    end; a constant load `preload` pushes the first bead toward it (the solid is a rigid block far
    away); friction and damping off unless `extra` sets them."""
    R = 0.005
    rows = ["label,x,y,radius"] + [f"{k + 1},{2 * R * k!r},0.0,{R}" for k in range(n)]
    (tmp_path / "chain.csv").write_text("\n".join(rows) + "\n")
    xw = 2 * R * (n - 1) + R
    (tmp_path / "chain.toml").write_text(f"""name = "chain"
[simulation]
duration = "20us"
equilibrate = true
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "C"
side = "none"
granules_file = "chain.csv"
radius = {R}
[[walls]]
p0 = [{xw!r}, -0.01]
p1 = [{xw!r}, 0.01]
normal = [-1.0, 0.0]
name = "far"
[[excitations]]
granule = "C:1"
kind = "constant"
value = {preload!r}
direction = [1.0, 0.0]
{extra}
""")
    return tmp_path / "chain.toml"


def test_equilibrium_of_a_precompressed_chain(tmp_path):
    """`simulation.equilibrate`: every contact of a chain pressed by F0 = 10 N against a wall carries
    F0, at Hertz's overlaps (F0 / A)^(2/3) with A = 4/3 E* sqrt(R*) (pairs: E* = E / 2(1 - nu^2),
    R* = R / 2; wall: E / (1 - nu^2), R), and the run starts and stays at rest."""
    sc = S.load(str(chain_scenario(tmp_path)))
    problem = S.build_problem(sc)
    rep = problem.equilibrium
    E, nu, R, F0 = 200e9, 0.3, 0.005, 10.0
    A_pair = 4 / 3 * E / (2 * (1 - nu**2)) * math.sqrt(R / 2)
    A_wall = 4 / 3 * E / (1 - nu**2) * math.sqrt(R)
    assert rep["equilibrium_loaded_pairs"] == 9 and rep["equilibrium_loaded_walls"] == 1
    assert rep["equilibrium_max_pair_force_N"] == pytest.approx(F0, rel=1e-9)
    assert rep["equilibrium_max_wall_force_N"] == pytest.approx(F0, rel=1e-9)
    x = problem.state.pos[:, 0]
    gaps = 2 * R - np.diff(x)  # the pairs' overlaps
    np.testing.assert_allclose(gaps, (F0 / A_pair) ** (2 / 3), rtol=1e-8)
    assert R - (2 * R * 9 + R - x[-1]) == pytest.approx((F0 / A_wall) ** (2 / 3), rel=1e-8)
    ds = run_scenario(sc)
    np.testing.assert_allclose(ds["wall_force_normal"].values[:, 0], F0, rtol=1e-9)
    assert np.abs(ds["v_x"].values).max() < 1e-9


@pytest.mark.parametrize("solid", ["rigid", "beam", "plate"])
def test_preloaded_medium_starts_at_rest_on_any_solid(solid):
    """The paper's SSGM pressed by 100 N on C against a rigid, beam or plate solid: the static
    equilibrium (granules, walls, and the solid's static compliance at its contacts) is a state of
    the dynamics: over 20 us no granule moves faster than 1e-8 m/s (a 100 N step load would send C
    to about 0.5 m/s), and the balance (13) holds to 1e-12 of the solid's strain energy scale."""
    sc = S.load("paper", [f'solid.kind="{solid}"', 'excitations.0.granule="SSGM:C"', 'excitations.0.kind="constant"',
                          "excitations.0.value=100.0", "simulation.equilibrate=true", 'simulation.duration="20us"'])
    ds = run_scenario(sc)
    assert np.hypot(ds["v_x"].values, ds["v_y"].values).max() < 1e-8
    assert ds.attrs["equilibrium_residual_N"] < 1e-8
    if solid != "rigid":
        assert ds["energy_solid"].values[0] > 1e-5  # the solid starts deformed
    assert np.abs(ds["balance_error"].values).max() < 1e-12


def test_a_load_nothing_holds_has_no_equilibrium(tmp_path):
    """A bead pushed away from the chain, toward nothing: a clear error naming it (exit 2 at load)."""
    path = chain_scenario(tmp_path)
    text = path.read_text().replace("direction = [1.0, 0.0]", "direction = [-1.0, 0.0]")
    path.write_text(text)
    with pytest.raises(S.ScenarioError, match=r"simulation.equilibrate.*C:1"):
        S.build_problem(S.load(str(path)))
