"""The contact law's derivatives, the interface map and its friction eigenvalue (A9), the local
friction root, and the shared coupled core against independent references."""

import math

import numpy as np
import pytest
from numba import njit
from scipy.optimize import brentq

from granel import scenario as S
from granel.coupling import core
from granel.coupling.driver import drive
from granel.granular.contact import contact_law, contact_law_derivatives, friction_eigenvalue, hertz_potential, tanh
from granel.run import make_solver, run_scenario

A, G, MU, KS = 4 / 3 * 219.8e9 * math.sqrt(0.005), 6.313e-3 * math.sqrt(0.004 * 1.6e10), 0.099, 100.0
EPS = np.finfo(float).eps


@njit
def _law(A, G, d, dd, vt, mu, k_s):
    return contact_law(A, G, d, dd, vt, mu, k_s)


@njit
def _derivs(A, G, d, dd, vt, mu, k_s):
    return contact_law_derivatives(A, G, d, dd, vt, mu, k_s)


@njit
def _pot(A, d):
    return hertz_potential(A, d)


@njit
def _lam(mu, k_s, normal, vt, h, ct):
    return friction_eigenvalue(mu, k_s, normal, vt, h, ct)


@njit
def _tanh(x):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = tanh(x[i])
    return out


def test_friction_tanh_within_two_ulp():
    """The friction law's tanh (eq. 5) against numpy's over the whole range, subnormal arguments
    to saturation, within 2 ulp; exactly +-1 beyond 19.1."""
    x = np.concatenate([np.linspace(-40, 40, 400001), np.logspace(-310, 1.6, 200000), -np.logspace(-310, 1.6, 200000), [0.0]])
    got, ref = _tanh(x), np.tanh(x)
    assert np.all(np.abs(got - ref) <= 2 * np.spacing(np.abs(ref)))
    assert np.all(got[np.abs(x) > 19.1] == np.sign(x[np.abs(x) > 19.1]))


@pytest.mark.parametrize("delta, ddelta, vt", [(1e-6, 0.3, 0.004), (3e-7, -0.2, -0.02), (2e-6, 0.0, 1e-4), (5e-8, 1.5, 0.5)])
def test_contact_law_derivatives_match_finite_differences(delta, ddelta, vt):
    """Eqs. (2), (3), (5): the analytic partial derivatives against central differences (relative
    steps 1e-6), and the potential 2/5 A delta^(5/2) whose derivative is the elastic force. A
    central difference is off by its rounding, eps (|f(x + e)| + |f(x - e)|) / 2e, and by its
    truncation, e^2 f^(3) / 6, which the same difference at 2e shows (it grows 4-fold there:
    a third of the change). Measured: at most 1.2e-10 of the largest derivative, the rounding."""
    def differences(scale):
        fd, rounding = [], []
        for k, x in enumerate((delta, ddelta, vt)):
            e = scale * 1e-6 * max(abs(x), {0: 1e-7, 1: 1e-3, 2: 1e-4}[k])
            lo = [delta, ddelta, vt]
            hi = [delta, ddelta, vt]
            lo[k] -= e
            hi[k] += e
            fp, fm = np.array(_law(A, G, *hi, MU, KS)[:2]), np.array(_law(A, G, *lo, MU, KS)[:2])
            fd.append((fp - fm) / (2 * e))
            rounding.append(EPS * (np.abs(fp) + np.abs(fm)) / (2 * e))
        order = ([0, 0], [1, 0], [0, 1], [1, 1], [2, 0], [2, 1])  # rows: d/d(delta), d/d(ddelta), d/d(vt); columns: fn, ft
        return (np.array([np.array(fd)[i, j] for i, j in order]), np.array([np.array(rounding)[i, j] for i, j in order]))

    d = np.array(_derivs(A, G, delta, ddelta, vt, MU, KS))
    want = np.array([d[0], d[1], d[2], d[3], 0.0, d[4]])
    got, rounding = differences(1.0)
    wide, _ = differences(2.0)
    assert np.all(np.abs(got - want) <= 2 * rounding + np.abs(wide - got) / 3 + 4 * EPS * np.abs(want))
    e = 1e-6 * delta
    up, down = _pot(A, delta + e), _pot(A, delta - e)
    truncation = e**2 / 6 * 0.75 * A / math.sqrt(delta)  # P^(3) = 3/4 A delta^(-1/2)
    assert (up - down) / (2 * e) == pytest.approx(A * delta**1.5, abs=2 * EPS * (up + down) / (2 * e) + truncation)
    # the law itself, against the paper's formulas typed out here: the same few operations, a few ulps
    fn = A * delta**1.5 + G * delta**0.25 * ddelta
    assert _law(A, G, delta, ddelta, vt, MU, KS)[:2] == pytest.approx((fn, -MU * abs(fn) * math.tanh(KS * vt)), rel=8 * EPS)


@pytest.fixture(scope="module")
def mid_run():
    """The paper's algorithm on the strong SSGM-side plate case, stopped at 0.06 ms (the wave is
    on the plate; six contacts are loaded)."""
    sc = S.load("paper", ['excitations.0.granule="SSGM:C"', 'simulation.solver="paper"', 'simulation.duration="0.06ms"'])
    problem = S.build_problem(sc)
    solver = make_solver(problem)
    drive(solver, problem.schedule)
    return solver


def _one_map(solver, F, level, derivatives=False):
    """G(F) of the step that would follow the solver's state, and the work arrays."""
    st, solid, cache = solver.st, solver.solid, solver.cache
    core.ensure_level(cache, solid, solver.cfg.dt0, level)
    h = solver.cfg.dt0 / 2**level
    nc = st.F.shape[0]
    pred = core.Prediction(st.u.copy(), st.v.copy(), st.a.copy(), np.empty(2 * nc))
    core.modal_predictor(st, solid, cache.D[level], h, np.empty(len(solid.w2)), pred.a_pred)
    w = core.iter_work(st.y, nc)
    assert core.interface_map(st.y, st.clock[0]["t"], h, solver.stepper.model, pred, cache.C[level], F, 0.0, w, derivatives)
    return w.iface.F.copy(), w, h


def test_interface_forces_jacobian_matches_finite_differences(mid_run):
    """dG/du and dG/dw at the contacts (from `contact_law_derivatives`) against central differences
    of `kernels.interface_forces` in the points' displacement and velocity."""
    from granel.granular import kernels
    from granel.granular.bundles import interface_buffers

    solver = mid_run
    _, w, _ = _one_map(solver, solver.st.F.copy(), int(solver.st.clock[0]["level"]), derivatives=True)
    y, u, v = w.ytr, w.u1.copy(), w.v1.copy()
    active = np.flatnonzero(w.iface.normal > 0)
    assert len(active) >= 4
    for c in active:
        for b in range(2):
            for which, base, scale in (("Du", u, 1e-12), ("Dw", v, 1e-7)):
                out = [interface_buffers(len(u)) for _ in range(2)]
                for s, o in zip((1, -1), out):
                    p = base.copy()
                    p[c, b] += s * scale
                    kernels.interface_forces(y, solver.stepper.model, p if which == "Du" else u, p if which == "Dw" else v, o, False)
                fd = (out[0].F[c] - out[1].F[c]) / (2 * scale)
                an = getattr(w.iface, which)[c, :, b]
                assert np.abs(fd - an).max() <= 2e-5 * np.abs(getattr(w.iface, which)[c]).max(), (c, which, b)


def test_friction_eigenvalue_a9_matches_the_fixed_point_map(mid_run):
    """(A6)-(A9): the derivative of the tangential force after one pass of the map with respect to
    the tangential force before it, measured by finite differences of the whole map (granules
    included), against the paper's local, linearised estimate |lambda| = 1/2 mu k_s |N| h c_t /
    cosh^2(k_s v_t). The paper neglects the granule's own response (Assumption 3): its tangential
    compliance at the contact, 1/m + R^2/I = 3.5/m, against the solid's c_t, so the two differ
    by at most 3.5 / (m c_t) (measured 1.3e-5 to 1.2e-4, at most 0.26 of that), and the map's
    derivative is -|lambda|: the friction iteration oscillates about its fixed point."""
    solver = mid_run
    st = solver.st
    level = int(st.clock[0]["level"])
    F0 = st.F.copy()
    G0, w, h = _one_map(solver, F0, level)
    normal, vrel = w.iface.normal.copy(), w.iface.vrel.copy()
    checked = 0
    for c, (tx, ty) in enumerate(solver.solid.frame.tangent):
        lam = _lam(MU, KS, normal[c], vrel[c], h, solver.cache.ct[level, c])
        if lam < 0.01:
            continue
        eps = 1e-4 * max(abs(F0[c] @ (tx, ty)), 1e-3)
        outs = []
        for s in (1, -1):
            F = F0.copy()
            F[c] += s * eps * np.array([tx, ty])
            outs.append(_one_map(solver, F, level)[0][c] @ (tx, ty))
        fd = (outs[0] - outs[1]) / (2 * eps)
        g = solver.system.solid_contacts[c].granule
        granule = 1 / solver.system.mass[g] + solver.system.radius[g] ** 2 / solver.system.inertia[g]
        # the difference's own error (a 1e-4 relative step: its square, and eps / 1e-4) is far below
        assert -fd == pytest.approx(lam, rel=granule / solver.cache.ct[level, c] + 1e-7), c
        checked += 1
    assert checked >= 4


def test_local_friction_root():
    """The root of g(s) = s - muN tanh(k_s (vt - beta (s - sj))) against scipy's brentq, from
    gentle to very stiff friction (mu k_s |N| beta from 0.1 to 1e4): within the root finder's own
    tolerance (it stops when a step is below 1e-14 muN, safeguarded Newton on a bracket, so the
    root is within that step), brentq's (1e-15 of muN and of the root), and the rounding of g
    at the root over its slope g' = 1 + muN k_s beta sech^2 (measured at most 0.85 of the sum)."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        muN, k_s = 10 ** rng.uniform(-2, 2), 10 ** rng.uniform(1, 5)
        beta = 10 ** rng.uniform(-1, 4) / (muN * k_s)
        vt, sj = rng.normal(0, 0.05), rng.uniform(-muN, muN)
        g = lambda s: s - muN * math.tanh(k_s * (vt - beta * (s - sj)))  # noqa: E731
        ref = brentq(g, -muN, muN, xtol=1e-15 * muN, rtol=1e-15)
        sech2 = 1 - math.tanh(k_s * (vt - beta * (ref - sj))) ** 2
        rounding = 4 * EPS * (muN + abs(ref) + muN * sech2 * k_s * (abs(vt) + beta * (abs(ref) + abs(sj))))
        tol = 1e-14 * muN + 1e-15 * (muN + abs(ref)) + rounding / (1 + muN * k_s * beta * sech2)
        assert core.local_friction_root(muN, k_s, vt, beta, sj) == pytest.approx(ref, abs=tol)


def test_b1_steps_keep_the_eigenvalues_at_half_on_a_common_step():
    """(B1): every accepted step of the paper method satisfies max_k |lambda_k| <= 1/2 at the one
    step size all contacts share, steps are dtau0 / 2^n, and each lands on its own grid."""
    sc = S.load("paper", ['excitations.0.granule="SSGM:C"', 'simulation.solver="paper"', 'simulation.duration="0.025ms"'])
    ds = run_scenario(sc)
    h = ds["step_dt"].values
    n = np.log2(4e-8 / h)
    assert np.array_equal(n, np.round(n)) and n.max() >= 3  # halved several times: dt0 / 2^n exactly
    # (B1)'s own test; stored in float32, which holds 0.5 and rounds to nearest: no margin needed
    assert ds["step_lambda"].values.max() <= 0.5
    # each step starts on a multiple of its own size; the clock sums the steps, half an ulp each
    t = ds["step_time"].values
    t0 = t - h
    assert np.all(np.abs(t0 / h - np.round(t0 / h)) <= len(h) * np.spacing(t.max()) / h)


def test_rigid_solid_is_the_no_mode_case_of_the_core():
    """With a rigid solid the coupled core reduces to RK4 on the granules: the same trajectory as
    the plain granular stepper, to round-off."""
    from granel.granular.system import Stepper

    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', 'simulation.duration="0.05ms"',
                          'simulation.integrator="newmark"'])
    ds = run_scenario(sc)
    steps = 1250
    system, state, _ = S.build_granular(sc)
    Stepper(system, substep=True).advance(state, 4e-8, steps)
    # two codes of the same RK4 round each step apart by up to an ulp of the speeds and positions;
    # the contacts amplify a position defect, by a gain measured on a deliberate 1e-13 m one
    # (measured 2.1e-13 of the largest speed, against 2.4e-9: the worst case, every position an ulp
    # apart at every step)
    _, moved, _ = S.build_granular(sc)
    moved.pos[:] += 1e-13 * np.random.default_rng(0).uniform(-1, 1, moved.pos.shape)
    Stepper(system, substep=True).advance(moved, 4e-8, steps)
    vmax = np.abs(state.vel).max()
    gain = np.abs(moved.vel - state.vel).max() / vmax / 1e-13
    tol = steps * (EPS + gain * np.spacing(np.abs(state.pos).max()))
    assert np.abs(ds["v_x"].values[-1] - state.vel[:, 0]).max() <= tol * vmax
    assert ds["step_iterations"].values.max() == 1  # the forces never feed back


def test_paper_and_fast_methods_agree_at_stiff_friction():
    """k_s = 1e4 on the plate (weak shock on the SSGM, through its first contacts with the plate):
    the paper's fixed point needs (B1) steps of 8e-11 s, the fast method keeps 40 ns with Newton and
    the exact local friction root; they agree to 1e-5 of the input (measured 7e-7 over 0.1 ms), and so
    does the exact integrator with its own steps. Three discretisations of the same equations:
    they differ by their truncation (Newmark's at 40 ns on the plate's modes, O(h^2)), which no
    BLAS kernel changes; 1e-5 is the accuracy the project asks of a run's energies at 0.1 ms."""
    base = ['excitations.0.granule="SSGM:C"', 'excitations.0.shock="weak"', "contact.k_s=1e4", 'simulation.duration="0.065ms"',
            "simulation.max_halvings=20"]
    a = run_scenario(S.load("paper", base + ['simulation.solver="paper"']))
    b = run_scenario(S.load("paper", base + ['simulation.solver="fast"', 'simulation.integrator="newmark"']))
    c = run_scenario(S.load("paper", base + ['simulation.solver="fast"']))  # the exact integrator
    assert a.attrs["solver_min_step"] <= 4e-8 / 2**8 and b.attrs["solver_min_step"] == 4e-8
    w = a["input_work"].values.max()
    assert b["energy_solid"].values.max() > 1e-3 * w  # the plate was reached
    for k in ("energy_lsgm", "energy_ssgm", "energy_solid", "dissipated_friction"):
        assert np.abs(a[k].values - b[k].values).max() < 1e-5 * w, k
        assert np.abs(a[k].values - c[k].values).max() < 1e-5 * w, k
