"""Narrowband loads and the forces on walls: a granule held against a wall by a constant load
(Hertz's static overlap), and the momentum balance of a driven medium against its walls and a
rigid solid."""

import math

import numpy as np
import pytest

from granel import scenario as S
from granel.run import run_scenario

EPS = np.finfo(float).eps


def rest_speed(force_defect, stiffness, mass):
    """The largest speed a force defect sets a granule held by a contact of `stiffness` moving at:
    it oscillates about the true rest position, dF / sqrt(k m) at most."""
    return force_defect / math.sqrt(stiffness * mass)


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
    round-off, no tangential force, at every output. The overlap d0 (6e-7 m) is the difference of
    two positions near R = 5 mm, each good to an ulp of R: a force good to 3/2 of 2 ulp(R) / d0
    (4e-12; measured 6e-13), and a speed of what that defect sets going (`rest_speed`)."""
    ds = run_scenario(_one_granule(tmp_path))
    R, F = 0.005, 10.0
    A = 4 / 3 * 200e9 / (1 - 0.3**2) * math.sqrt(R)
    d0 = (F / A) ** (2 / 3)
    rel = 1.5 * 2 * np.spacing(R) / d0 + 4 * EPS
    assert list(ds["wall"].values) == ["right"]
    np.testing.assert_allclose(ds["wall_force_normal"].values[:, 0], F, rtol=rel)
    assert np.abs(ds["wall_force_tangential"].values).max() == 0.0
    mass = 4 / 3 * math.pi * R**3 * 7850.0
    assert np.abs(ds["v_x"].values).max() < rest_speed(rel * F, 1.5 * F / d0, mass)


def test_momentum_balance_against_walls_and_the_solid():
    """The SSGM of the paper's walled geometry driven harmonically against a rigid solid: the
    granules' total momentum changes by the time integral of the load minus the forces the three
    walls and the solid's contacts take (Simpson on outputs every 0.05 us, 20 us), in x and y:
    within Simpson's own error, which its difference from the trapezoid rule bounds (the cruder
    rule's error is the larger; measured 9.5e-6 of the largest momentum against 2.1e-5), and the
    run's, rtol 1e-5 of the speeds."""
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
    from scipy.integrate import trapezoid

    impulse = np.array([[simpson(net[: k + 1, d], x=t[: k + 1]) for d in range(2)] for k in range(0, len(t), 40)])
    cruder = np.array([[trapezoid(net[: k + 1, d], x=t[: k + 1]) for d in range(2)] for k in range(0, len(t), 40)])
    quadrature = np.abs(impulse - cruder).max()
    np.testing.assert_allclose(P[::40] - P[0], impulse, rtol=0, atol=quadrature + sc.simulation.rtol * np.abs(P[:, 0]).max())


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
    R* = R / 2; wall: E / (1 - nu^2), R), and the run starts and stays at rest. The equilibrium
    stops when every granule's imbalance is within its round-off bound (at most the reported
    `equilibrium_tolerance_N`): a contact's force is the sum of the imbalances from the loaded end,
    good to n times that; an overlap (1e-6 m) is a difference of positions good to an ulp of x
    (0.1 m); a force holds it to the 3/2 power, an overlap the force to the 2/3."""
    sc = S.load(str(chain_scenario(tmp_path)))
    problem = S.build_problem(sc)
    rep = problem.equilibrium
    E, nu, R, F0, n = 200e9, 0.3, 0.005, 10.0, 10
    A_pair = 4 / 3 * E / (2 * (1 - nu**2)) * math.sqrt(R / 2)
    A_wall = 4 / 3 * E / (1 - nu**2) * math.sqrt(R)
    d_pair, d_wall = (F0 / A_pair) ** (2 / 3), (F0 / A_wall) ** (2 / 3)
    resolution = np.spacing(2 * R * n) / d_pair
    bound = rep["equilibrium_tolerance_N"] / F0
    assert 0 < bound < 1e-9 and rep["equilibrium_residual_N"] <= rep["equilibrium_tolerance_N"]
    force_tol = n * bound + 1.5 * resolution
    overlap_tol = 2 / 3 * n * bound + resolution
    assert rep["equilibrium_loaded_pairs"] == 9 and rep["equilibrium_loaded_walls"] == 1
    assert rep["equilibrium_max_pair_force_N"] == pytest.approx(F0, rel=force_tol)
    assert rep["equilibrium_max_wall_force_N"] == pytest.approx(F0, rel=force_tol)
    x = problem.state.pos[:, 0]
    gaps = 2 * R - np.diff(x)  # the pairs' overlaps
    np.testing.assert_allclose(gaps, d_pair, rtol=overlap_tol)
    assert R - (2 * R * 9 + R - x[-1]) == pytest.approx(d_wall, rel=overlap_tol)
    ds = run_scenario(sc)
    # at rest: the force defect can swing to twice itself, and sets the beads moving (`rest_speed`)
    np.testing.assert_allclose(ds["wall_force_normal"].values[:, 0], F0, rtol=2 * force_tol)
    mass = 4 / 3 * math.pi * R**3 * 7850.0
    assert np.abs(ds["v_x"].values).max() < rest_speed(force_tol * F0, 1.5 * F0 / d_pair, mass)
    # the equilibrium contact by contact in the result: nine pairs and the wall, each at F0
    names = list(ds["equilibrium_contact"].values)
    assert names[0] == "C:1-C:2" and names[-1] == "C:10|far" and len(names) == 10
    np.testing.assert_allclose(ds["equilibrium_force"].values, F0, rtol=force_tol)
    np.testing.assert_allclose(ds["equilibrium_overlap"].values[:9], d_pair, rtol=overlap_tol)
    assert ds["equilibrium_overlap"].values[9] == pytest.approx(d_wall, rel=overlap_tol)


@pytest.mark.parametrize("solid", ["rigid", "beam", "plate"])
def test_preloaded_medium_starts_at_rest_on_any_solid(solid):
    """The paper's SSGM pressed by 100 N on C against a rigid, beam or plate solid: the static
    equilibrium (granules, walls, and the solid's static compliance at its contacts) is a state of
    the dynamics (a 100 N step load would send C to about 0.5 m/s). The equilibrium holds each
    granule within its round-off bound (`equilibrium_tolerance_N`, about 5e-11 of the load; the
    medium has a granule B that the load leaves touching at zero force) and uses the factorised compliance B K^-1 B'; the run starts the
    solid from its modes, whose static compliance is that to eps (w_max / w_1)^2 (test_exact): a
    displacement defect at the contacts of that share of C F, which a contact of stiffness k
    turns into a force, and the two defects set the granules moving (`rest_speed`). Measured, on
    the rigid, beam and plate solids: 1.1e-12, 1.0e-10 and 7.7e-10 m/s (Prescott's kernels:
    2.6e-11 and 2.0e-9 on beam and plate), at most 0.1 of the bound. The balance (13) is the
    rounding of the energies it differences, an ulp of the load's work F x and of the solid's
    energy a step (measured 2e-15 J)."""
    sc = S.load("paper", [f'solid.kind="{solid}"', 'excitations.0.granule="SSGM:C"', 'excitations.0.kind="constant"',
                          "excitations.0.value=100.0", "simulation.equilibrate=true", 'simulation.duration="20us"'])
    problem = S.build_problem(sc)
    ds = run_scenario(sc)
    F = 100.0
    system = problem.system
    tolerance = ds.attrs["equilibrium_tolerance_N"]
    assert ds.attrs["equilibrium_residual_N"] <= tolerance < 1e-9 * F  # round-off of 100 N on 1e-2 m coordinates
    from granel.granular.system import Stepper

    model = Stepper(system).model
    A = np.concatenate([model.pairs.A, model.walls.A, model.points.A]).max()
    k = 1.5 * A ** (2 / 3) * F ** (1 / 3)  # the stiffest contact under the whole load
    defect = tolerance
    if solid != "rigid":
        from scipy.sparse.linalg import splu

        from granel.solid.mode_cache import all_modes

        assert ds["energy_solid"].values[0] > 1e-5  # the solid starts deformed
        omega = all_modes(problem.solid).omega
        B = problem.solid.contact_map()
        C = B @ splu(problem.solid.K.tocsc()).solve(B.T.toarray())
        defect += k * EPS * (omega[-1] / omega[0]) ** 2 * np.abs(C).max() * F
    assert np.hypot(ds["v_x"].values, ds["v_y"].values).max() < rest_speed(defect, k, system.mass.min())
    steps = int(ds.attrs["solver_steps"])
    scale = F * np.abs(problem.state.pos).max() + ds["energy_solid"].values.max()
    assert np.abs(ds["balance_error"].values).max() <= 2 * steps * EPS * scale


def test_a_load_nothing_holds_has_no_equilibrium(tmp_path):
    """A bead pushed away from the chain, toward nothing: a clear error naming it (exit 2 at load)."""
    path = chain_scenario(tmp_path)
    text = path.read_text().replace("direction = [1.0, 0.0]", "direction = [-1.0, 0.0]")
    path.write_text(text)
    with pytest.raises(S.ScenarioError, match=r"simulation.equilibrate.*C:1"):
        S.build_problem(S.load(str(path)))


# ---------------------------------------------------------------- analysis on known signals

def test_lock_in_and_harmonics_of_a_known_signal():
    """Amplitudes at f, 2f, 3f, f/2, f/3 of 0.2 + sin(2 pi f t) + 0.3 cos(4 pi f t + 1) +
    0.1 sin(pi f t), fitted over whole periods of f/3: the signal's own coefficients, but for the
    rounding of sums over its N samples, N eps of its mean absolute value, twice for an amplitude
    (2e-12; measured 2 eps)."""
    from granel.analysis.narrowband import harmonic_amplitudes, lock_in

    f = 1e4
    t = np.linspace(0, 30 / f, 6001)
    s = 0.2 + np.sin(2 * np.pi * f * t) + 0.3 * np.cos(4 * np.pi * f * t + 1) + 0.1 * np.sin(np.pi * f * t)
    amps = harmonic_amplitudes(t, s, f)
    tol = 2 * len(t) * EPS * np.abs(s).mean()
    assert amps["f"] == pytest.approx(1.0, abs=tol) and amps["2f"] == pytest.approx(0.3, abs=tol)
    assert amps["f/2"] == pytest.approx(0.1, abs=tol)
    assert amps["3f"] < tol and amps["f/3"] < tol
    A = lock_in(t, s, [2 * f])[0]  # complex: 0.3 e^(i)
    assert A.real == pytest.approx(0.3 * math.cos(1.0), abs=tol) and A.imag == pytest.approx(0.3 * math.sin(1.0), abs=tol)


def test_steady_window_and_response_period():
    """A drive at f with a transient decaying as e^(-t / 0.5 ms) is steady (1 %) once the
    transient is below about 1 % of the response; a response repeating every two drive periods
    locks to 2, a plain one to 1, one with an incommensurate part to none (0)."""
    from granel.analysis.narrowband import response_period, steady_window

    f = 2e4
    T = 1 / f
    t = np.linspace(0, 5e-3, 20001)
    s = np.sin(2 * np.pi * f * t) + 2 * np.exp(-t / 5e-4) * np.sin(2 * np.pi * 1.37 * f * t)
    lo, hi = steady_window(t, s, T, rtol=1e-2)
    # the period-to-period change of the transient, about 2 e^(-t/tau) (1 - e^(-T/tau)) (+ its
    # beat with the drive), is 1 % of the response near t = 2.3e-3 s
    assert 1.5e-3 < lo < 3.0e-3 and hi == t[-1]
    assert response_period(t, np.sin(2 * np.pi * f * t), T) == 1
    assert response_period(t, np.sin(2 * np.pi * f * t) + 0.4 * np.sin(np.pi * f * t), T) == 2
    assert response_period(t, np.sin(2 * np.pi * f * t) + 0.4 * np.sin(2 * np.pi * f * (np.sqrt(2) - 1) * t), T) == 0


# ---------------------------------------------------------------- physics

STEEL = (200e9, 7850.0, 0.3)


def hertz_chain_cutoff(F0, R=0.005, E=200e9, rho=7850.0, nu=0.3):
    """The linear cut-off of a monatomic chain precompressed by F0: f_c = (1/pi) sqrt(K/m),
    K = 3/2 A^(2/3) F0^(1/3), A = 4/3 E* sqrt(R/2), E* = E / 2(1 - nu^2) (two equal spheres)."""
    A = 4 / 3 * E / (2 * (1 - nu**2)) * math.sqrt(R / 2)
    K = 1.5 * A ** (2 / 3) * F0 ** (1 / 3)
    m = 4 / 3 * math.pi * R**3 * rho
    return math.sqrt(K / m) / math.pi


def driven_chain(tmp_path, n=20, preload=10.0, drive=0.1, frequency=1e4, duration="3ms", alpha_n=0.05):
    """`chain_scenario` with a harmonic drive on the first bead (5 ramp cycles) on top of the
    preload, equilibrated, with Tsuji damping alpha_n (to reach a steady state in a few ms)."""
    extra = f"""[[excitations]]
granule = "C:1"
kind = "harmonic"
amplitude = {drive!r}
frequency = {frequency!r}
ramp_cycles = 5
direction = [1.0, 0.0]
"""
    path = chain_scenario(tmp_path, n, preload, extra)
    text = path.read_text().replace('duration = "20us"', f'duration = "{duration}"\noutput_every = "2us"')
    path.write_text(text.replace("alpha_n = 0.0", f"alpha_n = {alpha_n!r}"))
    return S.load(str(path))


def test_cutoff_of_a_precompressed_chain(tmp_path):
    """A chain of 20 steel beads (R = 5 mm) precompressed by 10 N, driven by 0.1 N at its first
    bead: the force it transmits to the far wall, at the drive frequency in the last 1.5 ms of 3,
    falls by more than 20 dB between 0.97 and 1.03 of the cut-off (f_c = 17.3 kHz here, from
    Hertz's law) and passes below it (above -10 dB at 0.8 f_c). Measured: -4.6, -29.1 and
    -70.0 dB at 0.8, 0.97 and 1.03 f_c."""
    from granel.analysis.narrowband import harmonic_amplitudes, transmissibility

    fc = hertz_chain_cutoff(10.0)
    assert fc == pytest.approx(17.3e3, rel=3e-3)
    db = {}
    for r in (0.8, 0.97, 1.03):
        ds = run_scenario(driven_chain(tmp_path, frequency=r * fc))
        t, F = ds["time"].values, ds["wall_force_normal"].values[:, 0]
        amp = harmonic_amplitudes(t, F, r * fc, orders=(1,), subharmonics=(), window=(1.5e-3, 3e-3))["f"]
        db[r] = 20 * math.log10(transmissibility(amp, 0.1))
    assert db[0.8] > -10.0
    assert db[0.97] - db[1.03] > 20.0
