"""The tensioned string (`solid.string`) against references no one here wrote: the string's
harmonics n c / 2L (held ends) and (2n - 1) c / 4L (one end sliding), the clamped tensioned beam's
frequency equation, the foundation's shift w^2 = w0^2 + k_f / (rho A), the observed convergence
order of the Hermite elements, and a bead striking a long cord against the cord as a dashpot of
impedance 2 sqrt(T rho A) (until the waves return from its ends)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from granel import scenario as S
from granel.run import run_scenario
from granel.scenario.schema import ScenarioError
from granel.solid.base import Material, Slab
from granel.solid.dispersion import string_frequency
from granel.solid.kinds import kind_of
from granel.solid.string import build_string

from test_exact import ledger_bound

STEEL = Material(200e9, 7850.0, 0.3)
WIDTH, THICK, LENGTH = 1e-3, 1e-3, 0.1  # a 1 mm square steel cord, 10 cm long
RHO_A = STEEL.rho * WIDTH * THICK
EI = STEEL.E * THICK * WIDTH**3 / 12


def frequencies(model, count):
    """The lowest `count` natural frequencies [Hz] of a solid, by a dense generalised eigensolver."""
    w2 = scipy.linalg.eigh(model.K.toarray(), model.M.toarray(), eigvals_only=True, subset_by_index=[0, count - 1])
    return np.sqrt(w2) / (2 * math.pi)


def cord(n, held=(True, True), tension=100.0, foundation=0.0, bending=False):
    return build_string(Slab(0.0, 0.0, WIDTH, LENGTH, THICK), STEEL, [], n, held, tension, foundation, bending)


def observed_order(errors, ns) -> float:
    """The slope of log(error) against log(1 / n) between the last two meshes."""
    return math.log(errors[-2] / errors[-1]) / math.log(ns[-1] / ns[-2])


def test_a_held_string_rings_at_its_harmonics_with_the_elements_order():
    """f_n = n c / 2L, c = sqrt(T / rho A). Hermite cubics (degree p = 3) on a second-order problem:
    eigenvalue errors of order h^(2(p + 1 - 1)) = h^6 (Strang & Fix): the observed order on the
    fifth mode (4 to 16 elements per half wave) approaches 6 from below as the mesh is refined."""
    c = math.sqrt(100.0 / RHO_A)
    exact = np.arange(1, 6) * c / (2 * LENGTH)
    ns = [20, 40, 80]
    errors = [abs(frequencies(cord(n), 5)[4] / exact[4] - 1) for n in ns]
    first, second = observed_order(errors[:2], ns[:2]), observed_order(errors[1:], ns[1:])
    assert 5.5 <= first < second <= 6.2
    # at 40 elements every one of the five is within the fifth's error at 20 carried by h^5.5
    got = frequencies(cord(40), 5)
    np.testing.assert_allclose(got, exact, rtol=errors[0] * (20 / 40) ** 5.5)


def test_a_string_sliding_at_one_end_rings_at_odd_quarter_waves():
    """Held at the bottom, free to slide across at the top (no force across: w' = 0 there):
    f_n = (2n - 1) c / 4L."""
    c = math.sqrt(100.0 / RHO_A)
    exact = (2 * np.arange(1, 5) - 1) * c / (4 * LENGTH)
    fine, coarse = frequencies(cord(40, (True, False)), 4), frequencies(cord(20, (True, False)), 4)
    # the error at 40 elements is below the change from 20 (an order p >= 1 halves it at least)
    np.testing.assert_allclose(fine, exact, rtol=float(np.max(np.abs(coarse / fine - 1))))
    assert np.max(np.abs(fine / exact - 1)) < 1e-6


def clamped_tensioned_beam(T, count):
    """The lowest roots [Hz] of the clamped-clamped tensioned beam's frequency equation
    2 a b (1 - cosh aL cos bL) + (a^2 - b^2) sinh aL sin bL = 0, with a^2, -b^2 the roots
    (T -+ sqrt(T^2 + 4 EI rho A w^2)) / 2 EI of EI l^4 - T l^2 - rho A w^2 = 0 (w ~ exp(l y));
    divided by cosh aL to stay finite."""
    def equation(w):
        root = math.sqrt(T * T + 4 * EI * RHO_A * w * w)
        a, b = math.sqrt((T + root) / (2 * EI)), math.sqrt((root - T) / (2 * EI))
        aL, bL = a * LENGTH, b * LENGTH
        return 2 * a * b * (1 / math.cosh(aL) - math.cos(bL)) + (a * a - b * b) * math.tanh(aL) * math.sin(bL)

    grid = np.linspace(1.0, 2 * math.pi * 40_000, 40_001)
    values = np.array([equation(w) for w in grid])
    roots = [brentq(equation, grid[i], grid[i + 1], xtol=1e-12, rtol=1e-15)
             for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[:count]]
    return np.array(roots) / (2 * math.pi)


@pytest.mark.parametrize("T", [0.0, 10.0, 100.0])
def test_a_clamped_tensioned_beam_follows_its_frequency_equation(T):
    """With bending stiffness the held ends are clamped; T = 0 is the Euler-Bernoulli beam
    (cos bL cosh bL = 1), T L^2 / EI = 60 at 100 N (tension and bending both matter). Hermite cubics
    on the fourth-order problem: eigenvalue errors of order h^(2(p + 1 - 2)) = h^4, observed on the
    fifth mode between 40 and 80 elements; at 80 every mode within the fifth's error at 40 carried by
    h^3.5."""
    exact = clamped_tensioned_beam(T, 5)
    assert len(exact) == 5
    got = {n: frequencies(cord(n, tension=T, bending=True), 5) for n in (40, 80)}
    errors = [abs(got[n][4] / exact[4] - 1) for n in (40, 80)]
    assert 3.5 <= observed_order(errors, [40, 80]) <= 4.3
    np.testing.assert_allclose(got[80], exact, rtol=errors[0] * 0.5**3.5)


def test_a_foundation_lifts_every_mode_by_its_stiffness_over_the_mass():
    """w^2 = w0^2 + k_f / (rho A), mode by mode: the foundation's consistent matrix is k_f / (rho A)
    times the mass matrix, so the shift is exact to the eigensolver's round-off (1e-9 of w^2)."""
    kf = 4e6  # N/m^2: a cut-on of sqrt(kf / rho A) / 2 pi = 3.6 kHz, near the first harmonic
    bare, lifted = frequencies(cord(40), 8), frequencies(cord(40, foundation=kf), 8)
    np.testing.assert_allclose((2 * math.pi * lifted) ** 2, (2 * math.pi * bare) ** 2 + kf / RHO_A, rtol=1e-9)
    # and the branch of `solid.dispersion` says the same at the harmonics' wavenumbers n pi / L
    k = np.arange(1, 9) * math.pi / LENGTH
    np.testing.assert_allclose(string_frequency(k, 100.0, RHO_A, 0.0, kf), lifted, rtol=1e-6)


def test_the_string_kind_reports_its_branch_and_kinds():
    model = cord(20, foundation=1e6)
    kind = kind_of(model)
    f = kind.branches(model, np.array([0.0, 10.0]))["string"]
    assert f[0] == pytest.approx(math.sqrt(1e6 / RHO_A) / (2 * math.pi), rel=1e-12)  # the cut-on
    assert kind.mode_kinds(model, None, range(3)) == ["transverse"] * 3
    stress = kind.stress(model, np.zeros(model.T.shape[0]), STEEL.E, STEEL.nu)
    np.testing.assert_allclose(stress["tension_stress"], 100.0 / (WIDTH * THICK), rtol=1e-15)


# ------------------------------------------------------------------------ a bead on a long cord

BEAD = Material(0.5e9, 2200.0, 0.46)  # a PTFE bead: soft, so that the cord's elements are small against its contact
R, V0 = 1e-2, 0.01
MASS = BEAD.rho * 4 / 3 * math.pi * R**3
A_FACE = 4 / 3 * BEAD.E / (1 - BEAD.nu**2) * math.sqrt(R)  # eq. 3: a bead on the solid's face
TENSION, LONG = 1000.0, 1.0


def bead_on_cord(tmp_path, elements, duration):
    (tmp_path / "cord.toml").write_text(f"""name = "cord"
[simulation]
duration = "{duration}"
output_every = "2us"
[contact]
mu = 0.0
alpha_n = 0.0
[materials.steel]
E = {STEEL.E}
rho = {STEEL.rho}
nu = {STEEL.nu}
[materials.ptfe]
E = {BEAD.E}
rho = {BEAD.rho}
nu = {BEAD.nu}
[solid]
kind = "string"
width = {WIDTH}
thickness = {THICK}
length = {LONG}
beam_elements = {elements}
tension = {TENSION}
[[media]]
name = "B"
side = "left"
material = "ptfe"
radii = [{R}]
[[initial_velocities]]
granule = "B:1"
v = [{V0}, 0.0]
""")
    return S.load(str(tmp_path / "cord.toml"))


def dashpot_impact(t):
    """The contact force at times t of a Hertz bead (A d^(3/2)) pressing on a dashpot of
    impedance 2 sqrt(T rho A) (a point force on an infinite string sends a wave of speed c each
    way: w' = F / 2 sqrt(T rho A)), by scipy's DOP853; d' = v - w', m v' = -F."""
    Z = 2 * math.sqrt(TENSION * RHO_A)

    def rhs(_, s):
        f = A_FACE * max(s[0], 0.0) ** 1.5
        return [s[1] - f / Z, -f / MASS]

    sol = solve_ivp(rhs, (0.0, float(t[-1])), [0.0, V0], method="DOP853", rtol=1e-12, atol=1e-20, dense_output=True,
                    first_step=1e-12)
    return A_FACE * np.maximum(sol.sol(t)[0], 0.0) ** 1.5


def test_a_bead_on_a_long_cord_sees_a_dashpot_until_the_waves_return(tmp_path):
    """A soft bead struck on a 1 m cord at its middle: the waves return after L / c = 2.8 ms; until
    then the cord under the bead is a dashpot of impedance 2 sqrt(T rho A). The peak force and the
    force history within 2 % of the peak (the issue's figure); what separates them is the elements'
    mass under the bead (measured 0.47 % of the peak at 500 elements, 0.25 % at 1000), so the
    difference falls as the cord is refined."""
    assert LONG / math.sqrt(TENSION / RHO_A) > 2.5e-3
    errors = []
    for elements in (500, 1000):
        sc = bead_on_cord(tmp_path, elements, "2.5ms")
        ds = run_scenario(sc)
        t, f = ds["time"].values, ds["contact_force_normal"].values[:, 0]
        reference = dashpot_impact(t)
        assert abs(f.max() / reference.max() - 1) < 0.02
        errors.append(np.abs(f - reference).max() / reference.max())
        assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, sc)  # the ledger (13) closes
    assert errors[1] < errors[0] < 0.02
    # the bead parts from the cord only slowly: still pressing at the end, with a quarter of its peak
    assert 0.1 * reference.max() < reference[-1] < 0.5 * reference.max() and f[-1] > 0


@pytest.mark.parametrize("field, value, message", [
    ("tension", 0.0, "solid.tension: a string needs a tension > 0"),
    ("tension", -5.0, "solid.tension"),
    ("clamped", [False, False], "solid.clamped: a string held at neither end"),
])
def test_bad_string_input_is_named(field, value, message):
    with pytest.raises(ScenarioError, match=message.replace("(", r"\(")):
        S.load("paper", ['solid.kind="string"', f"solid.{field}={value!r}".replace("'", '"').lower()]
               + (['solid.tension=10.0'] if field != "tension" else []))


WAVEFIELD = Path(__file__).resolve().parents[1] / "scenarios" / "wavefield" / "string-impact.toml"


@pytest.mark.slow  # about 10 s: a 10 ms record of 600 DOFs and its frequency-wavenumber map
def test_struck_cord_ridges_lie_on_the_string_branch_with_its_cut_on(tmp_path):
    """`granel wavefield`'s ridges of a struck cord on a foundation (scenarios/wavefield/string-impact)
    against w^2 = (T k^2 + k_f) / rho A, written out here: over k_window .. k_resolved every ridge
    within 0.25 % in frequency (the dispersion error at which the elements' resolution is set,
    `analysis.wavefield.FE_ERROR`; measured 6e-5); the lowest ones lie well above the bare cord's
    c k, which the foundation's cut-on lifts."""
    from granel.analysis.result_model import result_modes, result_solid
    from granel.analysis.wavefield import FE_ERROR, analyse_wavefield
    from granel.run import load_result

    nc = tmp_path / "cord.nc"
    res = subprocess.run([sys.executable, "-m", "granel", "run", str(WAVEFIELD), "-o", str(nc)], capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    ds = load_result(nc)
    model = result_solid(ds)
    r = model.recipe
    T, kf, rho_a = 500.0, 7.7e6, 7850.0 * 1e-3 * 1e-3
    assert (r.tension, r.foundation, r.rho * r.width * r.thickness) == (T, kf, pytest.approx(rho_a, rel=1e-15))
    wf = analyse_wavefield(ds, model, result_modes(ds))
    assert np.isfinite(wf.kinetic_check)  # the cord's axis is the whole cord: its energy is checked
    ridges = wf.ridges
    keep = (ridges.k >= wf.k_window) & (ridges.k <= wf.k_resolved) & (ridges.f <= 0.9 * wf.fk.f[-1])
    k, f = ridges.k[keep], ridges.f[keep]
    branch = np.sqrt((T * k**2 + kf) / rho_a) / (2 * math.pi)
    assert len(k) >= 20
    assert np.abs(f / branch - 1).max() < FE_ERROR
    bare = math.sqrt(T / rho_a) * k / (2 * math.pi)
    assert f[np.argmin(k)] > 1.2 * bare[np.argmin(k)]


def test_a_granule_off_the_cords_nodes_is_named():
    """The paper's contact heights are multiples of L / 40; with 41 elements they fall between nodes."""
    sc = S.load("paper", ['solid.kind="string"', "solid.tension=10.0", "solid.beam_elements=41"])
    system, _, _ = S.build_granular(sc)
    with pytest.raises(ScenarioError, match="solid: string contact LSGM:10 at y = .*: not on a node.*50 is the first "
                       "count from 41 that does"):
        S.build_solid(sc, system)


def test_the_refusal_proposes_the_first_grid_that_holds_every_contact():
    """`fitting_elements`: the paper's contacts lie at 10, 30, 50, 70, 90 mm (LSGM) and 30 to 70 mm
    every 10 mm (SSGM) of a 100 mm solid, so a grid holds them all exactly when its count is a
    multiple of 10; a disc's count is even too; heights off every grid up to the limit get none,
    and the plate in bending's refusal says so."""
    from granel.solid.base import ELEMENTS_LIMIT, fitting_elements

    heights = [0.01, 0.03, 0.05, 0.07, 0.09, 0.03, 0.04, 0.05, 0.06, 0.07]
    assert [fitting_elements(0.0, 0.1, heights, n) for n in (2, 11, 24, 40, 395)] == [10, 20, 30, 40, 400]
    assert fitting_elements(0.0, 0.1, [0.05, 0.02], 5, even=True) == 10  # 5 holds both, but a disc needs even
    assert fitting_elements(0.0, 0.1, [0.05 + 1e-5], 2) is None and ELEMENTS_LIMIT == 400
    sc = S.load("chain-on-plate", ["media.0.center_y=0.0751", "media.0.radii=[0.0047]"])
    system, _, _ = S.build_granular(sc)
    with pytest.raises(ScenarioError, match="not on a node of z = 0.*no count up to 400 does: move the granules"):
        S.build_solid(sc, system)


DIMER = Path(__file__).resolve().parents[1] / "scenarios" / "string" / "dimer-cord.toml"


def test_every_method_gives_the_same_struck_cord_and_keeps_the_ledger():
    """The dimer chain striking the cord (scenarios/string/dimer-cord.toml) for 0.6 ms, through the
    exact modal integrator, the paper's algorithm and Newmark at 20 ns: the cord's energy history
    agrees within the exact integrator's rtol (1e-5 of the speeds the loads impart; measured 1.2e-6
    of the peak), and each closes the ledger (13) within its own bound (the exact integrator's
    ledger_tol; the fixed-step methods' measured 2e-9 of the input, under simulation.balance_limit)."""
    runs = {}
    for name, overrides in (("exact", []), ("paper", ['simulation.solver="paper"']),
                            ("newmark", ['simulation.integrator="newmark"'])):
        sc = S.load(str(DIMER), overrides + ['simulation.duration="0.6ms"', 'simulation.dt="20ns"'])
        ds = run_scenario(sc)
        runs[name] = ds["energy_solid"].values
        bound = ledger_bound(ds, sc) if name == "exact" else sc.simulation.balance_limit * ds["input_work"].values[-1]
        assert np.abs(ds["balance_error"].values).max() <= bound
    peak = runs["exact"].max()
    assert peak > 0.15 * ds["input_work"].values[-1]  # the pulse has crossed into the cord (21 % measured)
    for name in ("paper", "newmark"):
        assert np.abs(runs[name] - runs["exact"]).max() <= sc.simulation.rtol * peak
