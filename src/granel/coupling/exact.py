"""The exact modal integrator of the shared core (the fast method's solid integrator): each retained
mode is propagated in closed form under an interface force that is a C1 cubic over the step, the
dropped high modes answer statically (residual flexibility), and the step size is error-controlled.

Over a step [t0, t0 + h] the contact points' displacement is
    u(tau) = P eta(tau) + R F(tau),     eta_i'' + w_i^2 eta_i = (P' F(tau))_i,
with P = B Phi over the retained modes (w_i <= w_cut) and R = B K^-1 B' - P W^-2 P' the static
compliance of the dropped modes at the contacts. The force over the step is the cubic through the
start value F0 and slope F0' (so the force history is C1), the force Fm at mid-step and the end
force F1: in Hermite form its end slope is F1' = F0' + 4 (F0 + F1 - 2 Fm) / h. The unknowns are
forces only, X = (F1, Fm): no slope comes from differentiating the stiff contact law.
`solid.propagation` gives each mode's displacement and velocity per unit Hermite datum
(F0, F0', F1, F1') at the step's end and at mid-step, so the contacts' end and mid-step motion is
affine in X. The granules are integrated by RK4 under the cubic Hermite motion through
(u0, w0, u1, w1); the map X -> G(X) returns the forces (eqs. 2, 5) at the end and at mid-step
(the granular state there by cubic Hermite interpolation). Newton on X = G(X) uses the contact
law's derivatives (the granules' sensitivity neglected, the paper's Assumption 3).

Local error of the whole coupled step: the embedded third-order solution of classical RK4 with the
end-of-step derivative (FSAL weights (1, 2, 2, 0, 1)/6, err = h/6 (k4 - k5) per RK4 sub-step) on
the granules' velocities and spin velocities against atol + rtol v_ref, and the step's defect of
the energy ledger (13) against its share h / T of ledger_tol e_ref. A PI controller picks the next
step on a geometric grid h_k = h_max 2^(-k/4) (so the per-step operators are cached), and a step
never crosses a load's kink.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..granular.bundles import InterfaceForces, Motion, interface_buffers, motion_buffers
from ..granular.contact import friction_map_slope
from ..granular.kernels import friction_rate, granule_energies, interface_forces, moved_beyond, rhs, rk4_step, rk4_substepped
from ..solid.propagation import hermite_taylor, hermite_values, weights_at
from . import core

GRID_PER_OCTAVE = 4


class ExactSolid(NamedTuple):
    """Retained modes (omega, P = B Phi: (2nc, nr)), the residual compliance R (2nc, 2nc) of the
    dropped ones, and the contacts' frame."""

    omega: np.ndarray
    P: np.ndarray
    R: np.ndarray
    frame: core.ContactFrame


class OpsCache(NamedTuple):
    """Per step size h (grid level k: h_max 2^(-k/4); the last slot for an off-grid step cut at a
    load's kink), computed on first use: the modal weights at the end (hom (nr, 3) = (S0, h S1,
    -w^2 h S1), wd, wv (nr, 4): displacement and velocity per unit modal Hermite datum) and at
    mid-step (homm), and the contact operators at the end (Cu, Cw) and at mid-step (Cum, Cwm),
    (4, 2nc, 2nc) each: the contacts' displacement and velocity per unit Hermite datum, the
    residual compliance included."""

    ready: np.ndarray  # (L+1,) bool
    hom: np.ndarray  # (L+1, nr, 3)
    wd: np.ndarray  # (L+1, nr, 4)
    wv: np.ndarray
    homm: np.ndarray  # (L+1, nr, 3)
    Cu: np.ndarray  # (L+1, 4, 2nc, 2nc)
    Cw: np.ndarray
    Cum: np.ndarray
    Cwm: np.ndarray


class ExactConfig(NamedTuple):
    h_max: float
    levels: int  # L: the smallest grid step is h_max 2^(-L/4)
    adaptive: bool  # False: every step is h_max (a fixed step), but for retries of a failed one
    rtol: float
    atol: float  # [m/s]
    v_ref: float  # velocity scale of the error norm [m/s]
    e_ref: float  # energy scale of the error norm [J]
    ledger_tol: float  # the energy ledger (13) may drift by ledger_tol e_ref over `duration`
    ledger_limit: float  # [J] a drift beyond this stops the run (the control has failed)
    duration: float
    newton: bool
    abstol: float
    reltol: float
    max_iterations: int
    max_disp: float


class ExactState(NamedTuple):
    """The state at the current time (y, modal eta/eta', the interface force F and slope Fd and
    their modal projections qF = P'F, qFd = P'Fd, the contacts' displacement u and velocity w,
    |N|, v_t, the granules' derivative dy) and, for dense output, the same at
    the previous step's start (suffix 0). clock = [t, t0, err_prev, friction rate of the last
    step, energy ledger (13), its initial value, the controller's continuous level]; meta = [grid
    level of the next step, rejected]."""

    y: np.ndarray
    dy: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    F: np.ndarray
    Fd: np.ndarray
    qF: np.ndarray
    qFd: np.ndarray
    u: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    vrel: np.ndarray
    y0: np.ndarray
    dy0: np.ndarray
    eta0: np.ndarray
    etad0: np.ndarray
    F0: np.ndarray
    Fd0: np.ndarray
    qF0: np.ndarray
    qFd0: np.ndarray
    step_motion: Motion  # the contacts' motion in the last step (for dense output)
    clock: np.ndarray
    meta: np.ndarray


class Work(NamedTuple):
    ytr: np.ndarray
    rk4: np.ndarray  # (5, len(y))
    k5: np.ndarray
    err: np.ndarray  # embedded error of the granular state
    ymid: np.ndarray  # the granular state at mid-step
    motion: Motion
    u1: np.ndarray  # (2nc,) the contacts at the end ...
    w1: np.ndarray
    um: np.ndarray  # ... and at mid-step
    wm: np.ndarray
    uf: np.ndarray  # their free parts (no force data)
    wf: np.ndarray
    umf: np.ndarray
    wmf: np.ndarray
    Fd1: np.ndarray  # (2nc,) the end slope the unknowns imply
    X: np.ndarray  # (4nc,) unknowns (F1, Fm) flat
    G: np.ndarray  # (4nc,)
    J: np.ndarray  # (4nc, 4nc)
    r: np.ndarray
    iface: InterfaceForces  # at the end
    iface_m: InterfaceForces  # at mid-step
    ww: np.ndarray  # (nr,) modal scratch
    rate: np.ndarray  # (1,): the friction rate of the step's RK4 sub-steps
    parts: np.ndarray  # (2,): the last step's scaled velocity error and energy-ledger defect
    qF1: np.ndarray  # (nr,): P' F1 and P' F1' of the trial step
    qFd1: np.ndarray
    inv_m: np.ndarray  # (nc,): 1/m and R^2/I of each contact's granule
    spin: np.ndarray


@njit(cache=True)
def work_for(y, nc, nr):
    m2 = 2 * nc
    z = np.zeros(m2)
    return Work(np.empty_like(y), np.empty((5, y.shape[0])), np.empty_like(y), np.zeros_like(y), np.empty_like(y),
                motion_buffers(nc), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(),
                np.zeros(2 * m2), np.zeros(2 * m2), np.zeros((2 * m2, 2 * m2)), np.zeros(2 * m2), interface_buffers(nc),
                interface_buffers(nc), np.zeros(nr), np.zeros(1), np.zeros(2), np.zeros(nr), np.zeros(nr), np.zeros(nc),
                np.zeros(nc))


# ---------------------------------------------------------------- per-step operators


@njit(cache=True)
def _contact_operator(P, weight, out):
    """out = P diag(weight) P'."""
    m2 = P.shape[0]
    for a in range(m2):
        for b in range(a, m2):
            acc = 0.0
            for i in range(P.shape[1]):
                acc += P[a, i] * weight[i] * P[b, i]
            out[a, b] = acc
            out[b, a] = acc


@njit(cache=True)
def _operators_at(solid, h, tau, hom, Cu, Cw):
    """Modal free-response weights at tau into a step h, and the contacts' displacement and
    velocity there per unit Hermite datum (4, 2nc, 2nc), the residual part R F(tau) included."""
    omega, P, R = solid.omega, solid.P, solid.R
    nr = omega.shape[0]
    m2 = P.shape[0]
    wd, wv, wa = np.empty((nr, 4)), np.empty((nr, 4)), np.empty((nr, 4))
    weights_at(omega, h, tau, hom, wd, wv, wa)
    col = np.empty(nr)
    for b in range(4):
        for i in range(nr):
            col[i] = wd[i, b]
        _contact_operator(P, col, Cu[b])
        for i in range(nr):
            col[i] = wv[i, b]
        _contact_operator(P, col, Cw[b])
    T, hb, dhb = np.empty((4, 4)), np.empty(4), np.empty(4)
    hermite_taylor(h, T)
    hermite_values(T, tau, hb, dhb)
    for b in range(4):
        for r in range(m2):
            for q in range(m2):
                Cu[b, r, q] += hb[b] * R[r, q]
                Cw[b, r, q] += dhb[b] * R[r, q]
    return wd, wv


@njit(cache=True)
def ensure_ops(cache, solid, slot, h):
    """Fill `cache` slot `slot` for step size h (once per grid level; always for the off-grid slot)."""
    if cache.ready[slot]:
        return
    wd, wv = _operators_at(solid, h, h, cache.hom[slot], cache.Cu[slot], cache.Cw[slot])
    cache.wd[slot, :, :] = wd
    cache.wv[slot, :, :] = wv
    _operators_at(solid, h, 0.5 * h, cache.homm[slot], cache.Cum[slot], cache.Cwm[slot])
    cache.ready[slot] = slot < cache.ready.shape[0] - 1  # the off-grid slot is recomputed each time


# ---------------------------------------------------------------- the interface map


@njit(cache=True)
def _motion_and_ends(st, cache, slot, h, w):
    """For the unknowns w.X = (F1, Fm): the end slope F1' = F0' + 4 (F0 + F1 - 2 Fm) / h, the
    contacts' displacement and velocity at the end and at mid-step, and the cubic Hermite motion
    through (u0, w0, u1, w1) for the RK4 of the granules."""
    m2 = st.u.shape[0]
    X = w.X
    for q in range(m2):
        w.Fd1[q] = st.Fd[q // 2, q % 2] + 4.0 * (st.F[q // 2, q % 2] + X[q] - 2.0 * X[m2 + q]) / h
    for r in range(m2):
        u1, w1, um, wm = w.uf[r], w.wf[r], w.umf[r], w.wmf[r]
        for q in range(m2):
            data0 = st.F[q // 2, q % 2]
            data1 = st.Fd[q // 2, q % 2]
            u1 += cache.Cu[slot, 0, r, q] * data0 + cache.Cu[slot, 1, r, q] * data1 + cache.Cu[slot, 2, r, q] * X[q] \
                + cache.Cu[slot, 3, r, q] * w.Fd1[q]
            w1 += cache.Cw[slot, 0, r, q] * data0 + cache.Cw[slot, 1, r, q] * data1 + cache.Cw[slot, 2, r, q] * X[q] \
                + cache.Cw[slot, 3, r, q] * w.Fd1[q]
            um += cache.Cum[slot, 0, r, q] * data0 + cache.Cum[slot, 1, r, q] * data1 + cache.Cum[slot, 2, r, q] * X[q] \
                + cache.Cum[slot, 3, r, q] * w.Fd1[q]
            wm += cache.Cwm[slot, 0, r, q] * data0 + cache.Cwm[slot, 1, r, q] * data1 + cache.Cwm[slot, 2, r, q] * X[q] \
                + cache.Cwm[slot, 3, r, q] * w.Fd1[q]
        w.u1[r], w.w1[r], w.um[r], w.wm[r] = u1, w1, um, wm
        c = r // 2
        d = r % 2
        u0, v0 = st.u[r], st.w[r]
        c2 = (3.0 * (u1 - u0) / h - 2.0 * v0 - w1) / h
        c3 = (2.0 * (u0 - u1) / h + v0 + w1) / (h * h)
        w.motion.u0[c, d] = u0
        w.motion.v0[c, d] = v0
        w.motion.a[c, d] = 2.0 * c2
        w.motion.j[c, d] = 6.0 * c3


@njit(cache=True)
def _rk4_with_estimate(y, t, h, model, motion, rate, w):
    """RK4 (sub-stepped where friction is stiff) from y into w.ytr, the end derivative in w.k5
    and the embedded third-order error h/6 (k4 - k5) summed over sub-steps in w.err. False if the
    state stops being finite."""
    m = max(1, int(math.ceil(rate * h / 2.0)))
    s = h / m
    w.ytr[:] = y
    w.err[:] = 0.0
    n = w.ytr.shape[0]
    for k in range(m):
        if not rk4_step(w.ytr, t + k * s, s, model, motion, k * s, w.rk4):
            return False
        rhs(t + (k + 1) * s, w.ytr, w.k5, model, motion, (k + 1) * s)
        k4 = w.rk4[3]
        for q in range(n):
            w.err[q] += s / 6.0 * (k4[q] - w.k5[q])
    return True


@njit(cache=True)
def hermite_map(st, t, h, model, cache, slot, rate, w, derivatives):
    """X = (F1, Fm) -> G(X): the forces at the step's end and at mid-step after RK4 of the
    granules under the contacts' motion that X implies. Fills w.G, w.iface, w.iface_m (with the
    law's derivatives if asked), w.ytr, w.k5, w.err. False if the granular state stopped being
    finite."""
    _motion_and_ends(st, cache, slot, h, w)
    if not _rk4_with_estimate(st.y, t, h, model, w.motion, rate, w):
        return False
    nc = st.F.shape[0]
    m2 = 2 * nc
    # the granules at mid-step: the cubic Hermite through the step's ends and their derivatives
    # (fourth-order locally; the end derivative w.k5 comes with the RK4's error estimate)
    for q in range(w.ymid.shape[0]):
        w.ymid[q] = 0.5 * (st.y[q] + w.ytr[q]) + 0.125 * h * (st.dy[q] - w.k5[q])
    interface_forces(w.ytr, model, w.u1.reshape(nc, 2), w.w1.reshape(nc, 2), w.iface, derivatives)
    interface_forces(w.ymid, model, w.um.reshape(nc, 2), w.wm.reshape(nc, 2), w.iface_m, derivatives)
    for r in range(m2):
        w.G[r] = w.iface.F[r // 2, r % 2]
        w.G[m2 + r] = w.iface_m.F[r // 2, r % 2]
    return True


@njit(cache=True)
def _jacobian_rows(J, row0, Du, Dw, Cu, Cw, h, tau, inv_m, spin, tangent):
    """Rows row0.. of J = dG/dX for one evaluation point at tau into the step (end or mid-step):
    the forces there move with the point's displacement (Du) and velocity (Dw), which move with F1
    directly (Hermite datum 2) and through the slope F1' (datum 3, dF1'/dF1 = 4/h, dF1'/dFm =
    -8/h). The granule's own response is kept to leading order: a force change ramping up over the
    step moves it by -M^-1 dG tau^2/6 and changes its velocity by -M^-1 dG tau/2, so each contact's
    2x2 block is premultiplied by (I - (Du tau^2/6 + Dw tau/2) M^-1)^-1, with M^-1 = I/m + t t' R^2/I
    (the spin carries the tangential part); the paper's Assumption 3 drops this where the granules
    are heavy against the solid's compliance, and it matters where friction is stiff."""
    m2 = Cu.shape[1]
    Mi, A, Ai = np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2))
    row2, row3 = np.empty(2), np.empty(2)
    for c in range(m2 // 2):
        # A = I - (Du tau^2 / 6 + Dw tau / 2) Minv, and its inverse
        tx, ty = tangent[c, 0], tangent[c, 1]
        Mi[0, 0] = inv_m[c] + spin[c] * tx * tx
        Mi[0, 1] = spin[c] * tx * ty
        Mi[1, 0] = Mi[0, 1]
        Mi[1, 1] = inv_m[c] + spin[c] * ty * ty
        for a in range(2):
            for b in range(2):
                acc = 0.0
                for k in range(2):
                    acc += (Du[c, a, k] * tau * tau / 6.0 + Dw[c, a, k] * 0.5 * tau) * Mi[k, b]
                A[a, b] = (1.0 if a == b else 0.0) - acc
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        Ai[0, 0], Ai[0, 1], Ai[1, 0], Ai[1, 1] = A[1, 1] / det, -A[0, 1] / det, -A[1, 0] / det, A[0, 0] / det
        for q in range(m2):
            for d in range(2):
                row2[d] = Du[c, d, 0] * Cu[2, 2 * c, q] + Du[c, d, 1] * Cu[2, 2 * c + 1, q] \
                    + Dw[c, d, 0] * Cw[2, 2 * c, q] + Dw[c, d, 1] * Cw[2, 2 * c + 1, q]
                row3[d] = Du[c, d, 0] * Cu[3, 2 * c, q] + Du[c, d, 1] * Cu[3, 2 * c + 1, q] \
                    + Dw[c, d, 0] * Cw[3, 2 * c, q] + Dw[c, d, 1] * Cw[3, 2 * c + 1, q]
            for d in range(2):
                u2 = Ai[d, 0] * row2[0] + Ai[d, 1] * row2[1]
                u3 = Ai[d, 0] * row3[0] + Ai[d, 1] * row3[1]
                J[row0 + 2 * c + d, q] = -(u2 + 4.0 / h * u3)
                J[row0 + 2 * c + d, m2 + q] = 8.0 / h * u3


@njit(cache=True)
def _newton_step(w, cache, slot, h, frame, law):
    """X <- X + dX with M dX = G - X, M ~ d(X - G)/dX from the contact law's derivatives
    (`_jacobian_rows`); then the exact local friction root for the end force where the friction
    map is not contractive (the tangential velocity response to F1 at fixed Fm). (A Broyden
    update of M between iterations was tried: more iterations, 6.5 against 5.3 on average.)"""
    m2 = w.u1.shape[0]
    nc = m2 // 2
    M = w.J
    for r in range(2 * m2):
        w.r[r] = w.G[r] - w.X[r]
    _jacobian_rows(M, 0, w.iface.Du, w.iface.Dw, cache.Cu[slot], cache.Cw[slot], h, h, w.inv_m, w.spin, frame.tangent)
    _jacobian_rows(M, m2, w.iface_m.Du, w.iface_m.Dw, cache.Cum[slot], cache.Cwm[slot], h, 0.5 * h, w.inv_m, w.spin,
                   frame.tangent)
    for r in range(2 * m2):
        M[r, r] += 1.0
    dX = np.linalg.solve(M, w.r)
    for c in range(nc):
        tx, ty = frame.tangent[c, 0], frame.tangent[c, 1]
        sj = w.X[2 * c] * tx + w.X[2 * c + 1] * ty
        for k in (2 * c, 2 * c + 1, m2 + 2 * c, m2 + 2 * c + 1):
            w.X[k] += dX[k]
        if w.iface.normal[c] <= 0.0 or not frame.has_tangent[c]:
            continue
        # the end velocity's response to F1, directly (datum 2) and through F1' (datum 3, 4/h)
        beta = core.tangential_compliance(cache.Cw[slot, 2], c, tx, ty) + 4.0 / h * core.tangential_compliance(cache.Cw[slot, 3], c, tx, ty)
        w.X[2 * c], w.X[2 * c + 1] = core.stiff_friction_root(w.X[2 * c], w.X[2 * c + 1], tx, ty, sj, w.iface.normal[c],
                                                              w.iface.vrel[c], beta, law)


@njit(cache=True)
def hermite_solve(st, t, h, model, cache, slot, cfg, frame, w):
    """Iterate X = G(X) for one step of size h (Newton, or the fixed point). Returns (status,
    iterations); on success w holds the end state."""
    nc = st.F.shape[0]
    m2 = 2 * nc
    # guess: the force continues from the start along its slope
    for r in range(m2):
        w.X[r] = st.F[r // 2, r % 2] + h * st.Fd[r // 2, r % 2]
        w.X[m2 + r] = st.F[r // 2, r % 2] + 0.5 * h * st.Fd[r // 2, r % 2]
    mo = w.motion
    for c in range(nc):
        mo.u0[c, 0] = st.u[2 * c]
        mo.u0[c, 1] = st.u[2 * c + 1]
    rate = 1.5 * friction_rate(st.y, model, mo)
    w.rate[0] = rate
    gr = model.granules
    for c in range(nc):
        g = model.points.g[c]
        w.inv_m[c] = 1.0 / gr.mass[g]
        w.spin[c] = gr.radius[g] ** 2 / gr.inertia[g]
    for it in range(1, cfg.max_iterations + 1):
        if not hermite_map(st, t, h, model, cache, slot, rate, w, cfg.newton):
            return core.NON_FINITE, it
        if frame.fixed:
            w.X[:] = w.G
            return core.CONVERGED, it
        ok = True
        for r in range(2 * m2):
            if abs(w.G[r] - w.X[r]) > cfg.abstol + cfg.reltol * abs(w.X[r]):
                ok = False
        if ok or not cfg.newton:
            w.X[:] = w.G
            if ok:
                return core.CONVERGED, it
            continue
        _newton_step(w, cache, slot, h, frame, model.law)
    return core.NO_CONVERGENCE, cfg.max_iterations


# ---------------------------------------------------------------- error, accept, step loop


@njit(cache=True, inline="always")
def propagate_mode(hom, wd, wv, i, eta0, etad0, q0, qd0, q1, qd1):
    """Mode i's displacement and velocity after a step (or at a point inside it) from its start
    state and its modal Hermite force data (P'F0, P'F0', P'F1, P'F1'), with the weights of
    `solid.propagation.weights_at`."""
    eta = hom[i, 0] * eta0 + hom[i, 1] * etad0 + wd[i, 0] * q0 + wd[i, 1] * qd0 + wd[i, 2] * q1 + wd[i, 3] * qd1
    etad = hom[i, 2] * eta0 + hom[i, 0] * etad0 + wv[i, 0] * q0 + wv[i, 1] * qd0 + wv[i, 2] * q1 + wv[i, 3] * qd1
    return eta, etad


@njit(cache=True)
def trial_ledger(st, solid, cache, slot, model, w):
    """E_solid + E_granular + D - W (eq. 13) at the end of the trial step: the modes' energy from
    their exact end state (P' F1, P' F1' kept in w for the accept), the dropped modes' static
    energy 1/2 F1' R F1, the granules' energy (11) and the ledger's accumulators."""
    m2 = st.u.shape[0]
    nr = st.eta.shape[0]
    f1 = w.X[:m2]
    if nr > 0:
        w.qF1[:] = np.dot(f1, solid.P)
        w.qFd1[:] = np.dot(w.Fd1, solid.P)
    hom, wd, wv = cache.hom[slot], cache.wd[slot], cache.wv[slot]
    es = 0.0
    for i in range(nr):
        e, v = propagate_mode(hom, wd, wv, i, st.eta[i], st.etad[i], st.qF[i], st.qFd[i], w.qF1[i], w.qFd1[i])
        es += 0.5 * (v * v + solid.omega[i] ** 2 * e * e)
    for r in range(m2):
        for q in range(m2):
            es += 0.5 * f1[r] * solid.R[r, q] * f1[q]
    nc = m2 // 2
    kin, rot, pot = granule_energies(w.ytr, model, w.u1.reshape(nc, 2))
    n = kin.shape[0]
    return es + kin.sum() + rot.sum() + pot.sum() + w.ytr[6 * n] + w.ytr[6 * n + 1] - w.ytr[6 * n + 2]


@njit(cache=True)
def step_error(y, w, cfg, granules, h, defect):
    """The scaled local error of the coupled step (<= 1: accept): the largest embedded RK4 error
    of a granule's velocity or spin velocity R omega against atol + rtol v_ref, and the step's
    energy-ledger defect (13) against its share h / duration of ledger_tol e_ref."""
    radius = granules.radius
    n = radius.shape[0]
    V = 3 * n
    OM = 5 * n
    ev = 0.0
    for i in range(n):
        ev = max(ev, abs(w.err[V + 2 * i]), abs(w.err[V + 2 * i + 1]), radius[i] * abs(w.err[OM + i]))
    w.parts[0] = ev / (cfg.atol + cfg.rtol * cfg.v_ref)
    w.parts[1] = abs(defect) / (cfg.ledger_tol * cfg.e_ref * h / cfg.duration)
    return max(w.parts[0], w.parts[1])


@njit(cache=True)
def accept(st, solid, cache, slot, h, w, rate, ledger):
    """The accepted step: modes, interface data and the granules to t + h; the start kept for
    dense output."""
    nc = st.F.shape[0]
    m2 = 2 * nc
    nr = st.eta.shape[0]
    st.y0[:] = st.y
    st.dy0[:] = st.dy
    st.eta0[:] = st.eta
    st.etad0[:] = st.etad
    st.F0[:, :] = st.F
    st.Fd0[:, :] = st.Fd
    st.qF0[:] = st.qF
    st.qFd0[:] = st.qFd
    f1 = w.X[:m2]
    fd1 = w.Fd1
    qF1, qFd1 = w.qF1, w.qFd1  # from `trial_ledger`
    hom, wd, wv = cache.hom[slot], cache.wd[slot], cache.wv[slot]
    for i in range(nr):
        st.eta[i], st.etad[i] = propagate_mode(hom, wd, wv, i, st.eta[i], st.etad[i], st.qF[i], st.qFd[i], qF1[i], qFd1[i])
        st.qF[i] = qF1[i]
        st.qFd[i] = qFd1[i]
    for r in range(m2):
        st.F[r // 2, r % 2] = f1[r]
        st.Fd[r // 2, r % 2] = fd1[r]
        st.u[r] = w.u1[r]
        st.w[r] = w.w1[r]
    mo, sm = w.motion, st.step_motion
    sm.u0[:, :] = mo.u0
    sm.v0[:, :] = mo.v0
    sm.a[:, :] = mo.a
    sm.j[:, :] = mo.j
    st.y[:] = w.ytr
    st.dy[:] = w.k5
    st.normal[:] = w.iface.normal
    st.vrel[:] = w.iface.vrel
    st.clock[1] = st.clock[0]
    st.clock[0] += h
    st.clock[3] = rate
    st.clock[4] = ledger


@njit(cache=True)
def friction_slopes(st, law, cache, slot, frame, lam):
    """The slope of each contact's local friction map over the step just taken, the analogue of
    (A9) for this integrator: mu k_s |N| t' Cw t / cosh^2(k_s v_t), Cw the tangential velocity
    response to the end force."""
    for c in range(lam.shape[0]):
        if not frame.has_tangent[c]:
            lam[c] = 0.0
            continue
        ctt = core.tangential_compliance(cache.Cw[slot, 2], c, frame.tangent[c, 0], frame.tangent[c, 1])
        lam[c] = friction_map_slope(law.mu, law.k_s, st.normal[c], st.vrel[c], ctt)


@njit(cache=True)
def free_response(st, solid, cache, slot, w):
    """The contacts' displacement and velocity at the end and at mid-step with no force data
    (w.uf, w.wf, w.umf, w.wmf): P applied to the modes' free response."""
    nr = st.eta.shape[0]
    if nr == 0:
        w.uf[:] = 0.0
        w.wf[:] = 0.0
        w.umf[:] = 0.0
        w.wmf[:] = 0.0
        return
    ww = w.ww
    for hom, out_u, out_w in ((cache.hom[slot], w.uf, w.wf), (cache.homm[slot], w.umf, w.wmf)):
        for i in range(nr):
            ww[i] = hom[i, 0] * st.eta[i] + hom[i, 1] * st.etad[i]
        out_u[:] = np.dot(solid.P, ww)
        for i in range(nr):
            ww[i] = hom[i, 2] * st.eta[i] + hom[i, 0] * st.etad[i]
        out_w[:] = np.dot(solid.P, ww)


@njit(cache=True)
def next_level(lev, err, err_prev, cfg):
    """PI control (exponents 0.7/4 and 0.4/4 for the third-order estimate) with a 0.9 safety
    factor and growth between 1/5 and 2, on the continuous level lev (the step h_max 2^(-lev/4));
    the step taken is on the grid at ceil(lev), so that operators are cached per grid level while
    small changes still add up (rounding each step's change to the grid stalled the step
    wherever the PI factor stayed between 1 and 2^(1/4): at errors around 0.07)."""
    if not cfg.adaptive:
        return 0.0
    e = max(err, 1e-10)
    fac = 0.9 * e ** (-0.7 / 4.0) * max(err_prev, 1e-4) ** (0.4 / 4.0)
    fac = min(2.0, max(0.2, fac))
    return min(float(cfg.levels), max(0.0, lev - GRID_PER_OCTAVE * math.log2(fac)))


@njit(cache=True, inline="always")
def grid_level(lev):
    """The grid level of a continuous level: the step is never above the controller's."""
    return int(math.ceil(lev - 1e-9))


@njit(cache=True)
def advance_exact(st, model, ref_pos, solid, cache, cfg, t_target, kinks, log):
    """Accepted steps until the clock passes t_target (dense output covers the output itself).
    Returns (status, steps logged): core.DONE, core.REBUILD, core.LOG_FULL, core.NO_CONVERGENCE,
    core.NON_FINITE or core.BALANCE_LOST (the ledger (13) drifted beyond cfg.ledger_limit)."""
    nc = st.F.shape[0]
    n = model.granules.radius.shape[0]
    w = work_for(st.y, nc, st.eta.shape[0])
    lim2 = cfg.max_disp * cfg.max_disp
    lam = np.zeros(nc)
    off = cache.ready.shape[0] - 1
    k = 0
    while st.clock[0] < t_target:
        if k >= log.t.shape[0]:
            return core.LOG_FULL, k
        level = st.meta[0]
        h = cfg.h_max / 2.0 ** (level / GRID_PER_OCTAVE)
        slot = level
        t = st.clock[0]
        for q in range(kinks.shape[0]):  # never step across a load's kink (nor stop just short of it)
            if t + 1e-6 * h < kinks[q] < t + h:
                h = kinks[q] - t
                slot = off
        ensure_ops(cache, solid, slot, h)
        free_response(st, solid, cache, slot, w)
        status, its = hermite_solve(st, t, h, model, cache, slot, cfg, solid.frame, w)
        if status != core.CONVERGED:
            if level + 2 * GRID_PER_OCTAVE <= cfg.levels:
                st.meta[0] = level + 2 * GRID_PER_OCTAVE  # a quarter of the step (fixed steps: then dt again)
                st.clock[6] = st.meta[0]
                st.meta[1] += 1
                continue
            return status, k
        ledger = trial_ledger(st, solid, cache, slot, model, w)
        err = step_error(w.ytr, w, cfg, model.granules, h, ledger - st.clock[4]) if cfg.adaptive else 0.0
        if err > 1.0 and level < cfg.levels:
            st.clock[6] = max(level + 1.0, next_level(st.clock[6], err, 1.0, cfg))
            st.meta[0] = grid_level(st.clock[6])
            st.meta[1] += 1
            continue
        if abs(ledger - st.clock[5]) > cfg.ledger_limit:
            return core.BALANCE_LOST, k  # even the smallest step lost the energy balance (13)
        accept(st, solid, cache, slot, h, w, w.rate[0], ledger)
        friction_slopes(st, model.law, cache, slot, solid.frame, lam)
        log.t[k] = st.clock[0]
        log.h[k] = h
        log.iterations[k] = its
        log.lam[k, :] = lam
        k += 1
        st.clock[6] = next_level(st.clock[6], err, st.clock[2], cfg)
        st.meta[0] = grid_level(st.clock[6])
        st.clock[2] = max(err, 1e-4)
        if moved_beyond(st.y, n, ref_pos, lim2):
            return core.REBUILD, k
    return core.DONE, k


@njit(cache=True)
def dense_state(st, solid, model, t_out, yo, eta_o, etad_o, F_o):
    """The state at t_out inside the last accepted step [t0, t]: the granules by RK4 from the
    step's start over tau = t_out - t0 under the step's own contact motion (full RK4 accuracy,
    the step itself unchanged), the modes by their exact response to the step's cubic force, and
    the interface force by its Hermite cubic."""
    t0, t1 = st.clock[1], st.clock[0]
    h = t1 - t0
    tau = t_out - t0
    if h <= 0.0 or tau >= h:
        yo[:] = st.y
        eta_o[:] = st.eta
        etad_o[:] = st.etad
        F_o[:, :] = st.F
        return
    yo[:] = st.y0
    if tau > 0.0:
        rk4_substepped(yo, t0, tau, model, st.step_motion, st.clock[3], np.empty((5, yo.shape[0])))
    T, H, dH = np.empty((4, 4)), np.empty(4), np.empty(4)
    hermite_taylor(h, T)
    hermite_values(T, tau, H, dH)
    for c in range(st.F.shape[0]):
        for d in range(2):
            F_o[c, d] = H[0] * st.F0[c, d] + H[1] * st.Fd0[c, d] + H[2] * st.F[c, d] + H[3] * st.Fd[c, d]
    nr = st.eta.shape[0]
    hom, wd, wv, wa = np.empty((nr, 3)), np.empty((nr, 4)), np.empty((nr, 4)), np.empty((nr, 4))
    weights_at(solid.omega, h, tau, hom, wd, wv, wa)
    for i in range(nr):
        eta_o[i], etad_o[i] = propagate_mode(hom, wd, wv, i, st.eta0[i], st.etad0[i], st.qF0[i], st.qFd0[i], st.qF[i], st.qFd[i])
