"""Gravity (`gravity = [gx, gy]`) against closed forms and independent solutions: a vertical chain
carries k m g at its k-th contact, a frictionless packing in a box puts its whole weight on the
floor, a dropped bead follows the impact equation integrated independently (Tsuji's dashpot) with
the ledger (13) closed, a chain precompressed by its weight carries sound at Hertz's speed
c ~ depth^(1/6), a solid sags under its own weight as beam and bar theory say, and every coupled
method keeps the ledger with gravity's potential in it."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from granel import scenario as S
from granel.analysis.balance import balance_scale, relative_balance_error
from granel.guard.exits import USAGE
from granel.io.model import read_record
from granel.run import run_scenario, summarize
from granel.solid.base import Material, Slab
from granel.solid.beam import build_beam
from granel.solid.plate import LayerSpec, build_plate

from test_exact import ledger_bound

E, NU, RHO, R, G = 200e9, 0.3, 7850.0, 0.005, 9.81
MASS = RHO * 4 / 3 * math.pi * R**3
A_PAIR = 4 / 3 * E / (2 * (1 - NU**2)) * math.sqrt(R / 2)  # eq. 2 between two equal steel beads
A_WALL = 4 / 3 * E / (1 - NU**2) * math.sqrt(R)  # a steel bead on a rigid wall
FLOOR = """[[walls]]
p0 = [-0.01, 0.0]
p1 = [0.01, 0.0]
normal = [0.0, 1.0]
name = "floor"
"""


def column(tmp_path, n, simulation="", extra="", duration="10us"):
    """n steel beads (R = 5 mm) stacked on a floor at y = 0, touching, under gravity -y; label 1 at
    the bottom; frictionless and undamped unless `extra` says."""
    rows = ["label,x,y,radius"] + [f"{k + 1},0.0,{R + 2 * R * k!r},{R}" for k in range(n)]
    (tmp_path / "column.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "column.toml").write_text(f"""name = "column"
gravity = [0.0, {-G}]
[simulation]
duration = "{duration}"
equilibrate = true
{simulation}
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
granules_file = "column.csv"
radius = {R}
{FLOOR}{extra}""")
    return tmp_path / "column.toml"


@pytest.mark.parametrize("n", [10, 60, 1000])
def test_a_vertical_chain_carries_k_m_g_at_its_kth_contact(tmp_path, n):
    """At rest, the k-th contact from the top carries the weight of the k beads above it, k m g,
    at Hertz's overlap (k m g / A)^(2/3), and the floor the whole column's. Each granule is balanced
    within its round-off bound (`equilibrium_tolerance_N`), so the k-th contact's force is good to
    k times that, and an overlap, a difference of coordinates of the column's height, to an ulp of
    it (3/2 of that relative in the force). A few Newton iterations from the secant predictor:
    53 bits in at most 6 doublings."""
    problem = S.build_problem(S.load(str(column(tmp_path, n))))
    eq = problem.equilibrium
    assert eq["equilibrium_loaded_pairs"] == n - 1 and eq["equilibrium_loaded_walls"] == 1
    assert eq["equilibrium_residual_N"] <= eq["equilibrium_tolerance_N"]
    assert eq["equilibrium_iterations"] <= 1 + 6
    y = problem.state.pos[:, 1]
    k = np.arange(n - 1, 0, -1)  # beads above contact (j, j+1), from the bottom contact up
    overlaps = 2 * R - np.diff(y)
    expected = (k * MASS * G / A_PAIR) ** (2 / 3)
    resolution = np.spacing(2 * R * n) / expected
    force_tol = k * eq["equilibrium_tolerance_N"] / (k * MASS * G) + 1.5 * resolution
    np.testing.assert_allclose(A_PAIR * overlaps**1.5, k * MASS * G, rtol=force_tol.max())
    floor = n * MASS * G
    assert eq["equilibrium_max_wall_force_N"] == pytest.approx(floor, rel=n * eq["equilibrium_tolerance_N"] / floor)
    assert R - y[0] == pytest.approx((floor / A_WALL) ** (2 / 3), rel=2 / 3 * n * eq["equilibrium_tolerance_N"] / floor
                                     + np.spacing(R) / (floor / A_WALL) ** (2 / 3))


def box(tmp_path, rows):
    """A frictionless hexagonal packing of `rows` (from the floor up) in a box (floor and side walls
    that touch it) under gravity -y."""
    (tmp_path / "box.toml").write_text(f"""name = "box"
gravity = [0.0, {-G}]
[simulation]
duration = "10us"
equilibrate = true
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "H"
side = "none"
grow = "up"
columns = {rows}
radius = {R}
face_y = 0.0
center_x = 0.0
walls = ["left", "right", "face"]
""")
    return tmp_path / "box.toml"


@pytest.mark.parametrize("rows", [[20, 19] * 10, pytest.param([100, 99] * 50, marks=pytest.mark.slow)])
def test_a_frictionless_packing_puts_its_whole_weight_on_the_floor(tmp_path, rows):
    """Frictionless side walls push only sideways, so the floor carries the packing's weight: the
    sum of the floor's contact forces is sum m g, to the sum of the granules' round-off bounds
    (each granule's imbalance is at most its bound, and the vertical balance of the whole
    packing adds them). 390 and 9950 granules (the latter measured: 18 iterations, 4 s)."""
    problem = S.build_problem(S.load(str(box(tmp_path, rows))))
    eq = problem.equilibrium
    names, forces, _ = problem.equilibrium_contacts
    floor = sum(f for name, f in zip(names, forces) if name.endswith("|H:face"))
    weight = problem.system.mass.sum() * G
    assert problem.system.n == sum(rows)
    assert eq["equilibrium_residual_N"] <= eq["equilibrium_tolerance_N"]
    assert floor == pytest.approx(weight, rel=sum(rows) * eq["equilibrium_tolerance_N"] / weight)
    assert {name.split("|")[1] for name in names if "|" in name} == {"H:face", "H:left", "H:right"}


def drop(tmp_path, v0, alpha, gap):
    """One steel bead, its lowest point `gap` above a damped floor, thrown down at v0 under gravity;
    the exact integrator at steps of at most 10 ns (see the test)."""
    (tmp_path / "drop.toml").write_text(f"""name = "drop"
gravity = [0.0, {-G}]
[simulation]
duration = "150us"
output_every = "1us"
rtol = 1e-9
max_step = 1e-8
[contact]
mu = 0.0
alpha_n = {alpha}
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "B"
side = "none"
radii = [{R}]
grow = "up"
face_y = {gap!r}
{FLOOR}[[initial_velocities]]
granule = "B:1"
v = [0.0, {-v0!r}]
""")
    return tmp_path / "drop.toml"


def tsuji_drop(v0, alpha, y0, t):
    """The bead's velocity at times t, independently: free fall in closed form to the touch, then
    m y'' = A d^(3/2) - alpha sqrt(m A) d^(1/4) y' - m g (d = R - y, eqs. 2-3 with m* = m) by scipy's
    DOP853 from the touch to the parting, then free flight; and the restitution v_out / v_in."""
    damping = alpha * math.sqrt(MASS * A_WALL)
    s_in = (-v0 + math.sqrt(v0 * v0 + 2 * G * (y0 - R))) / G
    v_in = -v0 - G * s_in

    def rhs(_, s):
        d = max(R - s[0], 0.0)
        return [s[1], (A_WALL * d**1.5 - damping * d**0.25 * s[1]) / MASS - G]

    def parting(_, s):
        return s[0] - R

    parting.terminal, parting.direction = True, 1
    sol = solve_ivp(rhs, (s_in, s_in + 1e-3), [R, v_in], method="DOP853", rtol=1e-13, atol=1e-18, events=parting,
                    dense_output=True, first_step=1e-12)
    s_out, v_out = sol.t_events[0][0], sol.y_events[0][0][1]
    v = np.where(t < s_in, -v0 - G * t, v_out - G * (t - s_out))
    inside = (t >= s_in) & (t <= s_out)
    v[inside] = sol.sol(t[inside])[1]
    return v, -v_out / v_in


@pytest.mark.parametrize("v0", [0.1, 0.5])
def test_a_dropped_bead_bounces_as_the_tsuji_impact_equation_says(tmp_path, v0):
    """The bead's velocity history (fall, Tsuji-damped Hertz impact, rebound under gravity) against
    the impact equation integrated by scipy. Tsuji's dashpot d^(1/4) d' has an unbounded derivative
    at the touch, where a step is not of RK4's order: its error is at most the dashpot's whole
    impulse over one step h after the touch, alpha sqrt(m A) v^(5/4) h^(5/4) / (5/4) / m in velocity
    (h = max_step; measured below a quarter of it), plus the error-controlled steps' own rtol of
    the speed over every step. The ledger (13), with gravity's potential, closes within the
    integrator's own bound."""
    alpha, gap = 0.2, 1e-6
    ds = run_scenario(S.load(str(drop(tmp_path, v0, alpha, gap))))
    t, v = ds["time"].values, ds["v_y"].values[:, 0]
    assert ds["y"].values[0, 0] == pytest.approx(R + gap, abs=np.spacing(R) * 4)
    reference, restitution = tsuji_drop(v0, alpha, float(ds["y"].values[0, 0]), t)
    assert 0.7 < restitution < 0.8  # a real loss: the dashpot matters
    onset = alpha * math.sqrt(MASS * A_WALL) * v0**1.25 * 1e-8**1.25 / 1.25 / MASS
    steps = int(ds.attrs["solver_steps"])
    assert np.abs(v - reference).max() <= onset + steps * 1e-9 * v0
    assert v[-1] > 0  # it rebounded
    assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, S.load(str(tmp_path / "drop.toml")))
    # the gravitational potential recorded is -m g . (x - x as built)
    np.testing.assert_allclose(ds["energy_gravity"].values, MASS * G * (ds["y"].values[:, 0] - ds["y"].values[0, 0]),
                               rtol=0, atol=4 * np.spacing(MASS * G * R))
    assert balance_scale(ds)[1] == "initial stored energy"  # the throw's kinetic energy


@pytest.mark.slow
def test_sound_in_a_chain_under_its_weight_speeds_up_as_depth_to_one_sixth(tmp_path):
    """A column of 200 beads at rest under its weight; a weak, long half-sine on the top bead. The
    k-th contact from the top carries k m g, so the long-wave sound speed there is
    c = 2R sqrt(k_H / m), k_H = 3/2 A^(2/3) (k m g)^(1/3): c ~ depth^(1/6). The pulse's travel time
    between neighbouring beads (the centroid of v^2) gives the local speed. A discrete chain's group
    velocity is c cos(q a / 2) = c sqrt(1 - (w / w_c)^2), w_c = 2 sqrt(k_H / m): each local speed is
    within (w / w_c)^2 / 2 of Hertz's for the pulse's frequencies (below 2 / tau), and the fitted
    exponent within the spread of that bias over the depths (over ln of their ratio)."""
    n, tau, amplitude = 200, 5e-4, 1e-3  # 1 mN: a thousandth of the load at depth 20
    extra = f"""[[excitations]]
granule = "C:{n}"
kind = "half_sine"
fmax = {amplitude}
tau = {tau}
direction = [0.0, -1.0]
"""
    path = column(tmp_path, n, 'output_every = "2us"', extra, duration="4.5ms")
    ds = run_scenario(S.load(str(path)))
    t, v = ds["time"].values, ds["v_y"].values
    v = v - v[0]
    w = v**2
    centroid = (w * t[:, None]).sum(axis=0) / w.sum(axis=0)
    speed = 2 * R / np.diff(centroid[::-1])  # from the top down: between depth d - 1 and d
    depth = np.arange(1, n)
    k_h = 1.5 * A_PAIR ** (2 / 3) * (depth * MASS * G) ** (1 / 3)
    hertz = 2 * R * np.sqrt(k_h / MASS)
    bias = (2 * np.pi * 2 / tau / (2 * np.sqrt(k_h / MASS))) ** 2 / 2
    sel = (depth >= 20) & (depth <= 120)  # the pulse has formed, and no echo from the floor yet
    assert np.all(np.abs(speed[sel] / hertz[sel] - 1) <= bias[sel])
    slope = np.polyfit(np.log(depth[sel]), np.log(speed[sel]), 1)[0]
    assert slope == pytest.approx(1 / 6, abs=(bias[sel].max() - bias[sel].min()) / math.log(120 / 20) + bias[sel].max())
    assert relative_balance_error(ds) <= ledger_bound(ds, S.load(str(path))) / balance_scale(ds)[0]


W, L, H = 0.01, 0.1, 0.001


def test_a_clamped_beam_sags_as_euler_bernoulli_says():
    """Gravity across a clamped-clamped beam: w(y) = q y^2 (L - y)^2 / (24 EI), q = rho A g; Hermite
    elements with the consistent load are exact at the nodes, so the contact points (on nodes) sag
    to the closed form within the solve's round-off (its condition number, ~1e8, times eps). Along
    its axis the beam is held rigidly: no sag."""
    beam = build_beam(Slab(0, 0, W, L, H), Material(E, RHO, NU), [("a", "left", 0.05), ("b", "right", 0.025)], 40)
    sag = beam.sag((-G, 0.0))
    q, EI = RHO * W * H * G, E * H * W**3 / 12
    exact = np.array([-q * y**2 * (L - y) ** 2 / (24 * EI) for y in (0.05, 0.025)])
    np.testing.assert_allclose(sag[:, 0], exact, rtol=1e8 * np.finfo(float).eps)
    assert np.all(sag[:, 1] == 0)
    assert np.all(beam.sag((0.0, -G)) == 0)


def test_the_plate_sags_between_its_beam_and_bar_bounds():
    """The paper's strip (10 x 100 x 1 mm, both ends clamped). Across: a clamped-clamped Timoshenko
    beam (Cowper's shear coefficient) sags by q y^2 (L - y)^2 / (24 EI) + q y (L - y) / (2 kappa G A);
    the plane-stress strip is stiffer, its clamp holding the whole end (its first period is 0.5 %
    shorter than that beam's, test_solids: about 1 % in compliance), so within 2 % below. Along:
    a bar under its weight, u = rho g y (L - y) / (2 E), with its ends' lateral contraction free;
    the clamps hold it there, which stiffens the strip at most to plane strain, E / (1 - nu^2): the
    plate lies between the two."""
    layers = [LayerSpec("a", "left", 0.03, 0.0005), LayerSpec("b", "left", 0.05, 0.0005)]
    plate = build_plate(Slab(0, 0, W, L, H), Material(E, RHO, NU), layers)
    across = plate.sag((-G, 0.0))[:, 0]
    q, EI, kappa = RHO * W * H * G, E * H * W**3 / 12, 10 * (1 + NU) / (12 + 11 * NU)
    shear = E / (2 * (1 + NU)) * kappa * W * H
    timoshenko = np.array([-(q * y**2 * (L - y) ** 2 / (24 * EI) + q * y * (L - y) / (2 * shear)) for y in (0.03, 0.05)])
    assert np.all((across / timoshenko - 1 < 0) & (across / timoshenko - 1 > -0.02))
    along = plate.sag((0.0, -G))[:, 1]
    bar = np.array([-RHO * G * y * (L - y) / (2 * E) for y in (0.03, 0.05)])
    assert np.all((along / bar <= 1) & (along / bar >= 1 - NU**2))


def test_a_solid_nothing_holds_is_named(tmp_path):
    """A plate clamped nowhere cannot carry its weight: the scenario is refused (exit 2) naming
    gravity and solid.clamped, before any computation."""
    out = subprocess.run([sys.executable, "-m", "granel", "run", "paper", "--set", "gravity=[0.0,-9.81]",
                          "--set", "solid.clamped=[false,false]", "--output", str(tmp_path / "r.nc")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == USAGE
    assert "gravity" in out.stderr and "solid.clamped" in out.stderr and "free to move under its own weight" in out.stderr
    assert not (tmp_path / "r.nc").exists()


@pytest.mark.parametrize("value", ["[0.0,-1e9]", "[0.0]", "[nan,0.0]", '"down"'])
def test_bad_gravity_is_refused_naming_the_field(tmp_path, value):
    out = subprocess.run([sys.executable, "-m", "granel", "run", "paper", "--set", f"gravity={value}",
                          "--output", str(tmp_path / "r.nc")], capture_output=True, text=True, timeout=600)
    assert out.returncode == USAGE, out.stderr
    assert "gravity" in out.stderr
    assert not (tmp_path / "r.nc").exists()


@pytest.mark.parametrize("method", [[], ['simulation.solver="paper"'], ['simulation.integrator="newmark"']])
def test_every_coupled_method_keeps_the_ledger_with_gravity(method):
    """The paper's packings and plate under gravity along -y, at rest at their static equilibrium,
    then the strong shock: the ledger (13), with the granules' gravitational potential in it, closes
    within the exact integrator's bound (ledger_tol of the largest input work; the paper's scheme
    and Newmark, at the 40 ns step, meet it too, as they do without gravity, test_conservation).
    The record carries gravity, and the solid's contact points sit where its weight moved them."""
    sc = S.load("paper", ["gravity=[0.0, -9.81]", "simulation.equilibrate=true", 'simulation.duration="0.1ms"'] + method)
    ds = run_scenario(sc)
    assert read_record(ds).gravity == (0.0, -9.81)
    assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, sc)
    assert "energy_gravity" in ds
    m = ds["granule_mass"].values
    np.testing.assert_allclose(ds["energy_gravity"].values,
                               (m * 9.81 * (ds["y"].values - ds["granule_position0"].values[:, 1])).sum(axis=1),
                               rtol=0, atol=1e-15 * (m * 9.81 * np.abs(ds["y"].values)).sum(axis=1).max())
    built, _, _ = S.build_granular(sc)
    solid = S.build_solid(sc, built)
    sag = solid.sag((0.0, -9.81))
    np.testing.assert_array_equal(ds["contact_position"].values,
                                  np.array([c.point for c in built.solid_contacts]) + sag)
    assert np.abs(sag).max() > 0


def test_the_summary_names_its_energy_scale(tmp_path):
    """A column at rest under its weight: nothing is put in, so the balance error is measured
    against the energy stored in its contacts at the start (the Hertz potential 2/5 A d^(5/2) of
    each at k m g, summed), and the summary says so."""
    path = column(tmp_path, 10)
    out = subprocess.run([sys.executable, "-m", "granel", "run", str(path), "--json-summary", "--output",
                          str(tmp_path / "r.nc")], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    assert s["balance_scale"] == "initial stored energy"
    k = np.arange(1, 10)
    stored = (0.4 * A_PAIR * (k * MASS * G / A_PAIR) ** (5 / 3)).sum() + 0.4 * A_WALL * (10 * MASS * G / A_WALL) ** (5 / 3)
    # each contact's force is good to 10 round-off bounds (test above), its energy (~ F^(5/3)) to 5/3 of that
    tolerance = s["equilibrium"]["tolerance_N"]
    assert s["balance_scale_J"] == pytest.approx(stored, rel=5 / 3 * 10 * tolerance / (MASS * G) + 1e-15)
    assert s["input_work_J"] == 0.0


def test_a_medium_at_rest_under_its_weight_holds_the_energy_put_in(tmp_path):
    """A column at rest under gravity, pressed by a half-sine pulse on its top bead, frictionless
    and undamped: once the pulse is over, its energy about the equilibrium (`dynamic_energy`:
    E(t) - E(0) less gravity's work) is the pulse's work, as energy conservation says, to the
    solver's ledger tolerance; gravity's work itself is a large share of it (the column sinks)."""
    from granel.analysis.reciprocity import dynamic_energy, gravity_work

    extra = """[[excitations]]
granule = "C:20"
kind = "half_sine"
fmax = 5.0
tau = 2e-5
direction = [0.0, -1.0]
"""
    ds = run_scenario(S.load(str(column(tmp_path, 20, extra=extra, duration="100us"))))
    e, why = dynamic_energy(ds, "C")
    w = ds["input_work"].values
    assert why is None and w[-1] > 0
    after = ds["time"].values > 2e-5
    tol = float(ds.attrs["solver_ledger_tol"]) * load_energy(ds)
    np.testing.assert_allclose(e[after], w[after], rtol=0, atol=tol)
    assert np.abs(gravity_work(ds, "C")).max() > 100 * tol


def load_energy(ds) -> float:
    """The ledger's own energy scale of a run: its loads' energy (`granular.scales.load_scales`)."""
    from granel.analysis.result_model import result_system
    from granel.granular.scales import load_scales
    from granel.granular.system import initial_state

    system = result_system(ds)
    return load_scales(system, initial_state(system), float(ds["time"].values[-1]))[1]
