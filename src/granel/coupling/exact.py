"""The exact modal integrator of the shared core (the fast method's solid integrator): every mode
is propagated in closed form under an interface force that is a polynomial over the step, and the
step size is error-controlled.

The solid's modes are the eigenmodes below the cut-off and the residual modes of the dropped ones
(`coupling.solver.residual_modes`: Rayleigh-Ritz on the dropped modes' static shapes, so the
static compliance at the contacts is exact and those shapes keep their inertia). Over a step
[t0, t0 + h] the contacts move as
    u(tau) = P eta(tau),     eta_i'' + w_i^2 eta_i = (P' F(tau))_i,
and the force F(tau) is the Lagrange polynomial through its values at the nodes s_b h: the start
value F0 (known) and the unknowns X, the forces at the other nodes. Two force models:
  quadratic  nodes (0, 1/2, 1), the points where the granules' RK4 evaluates its stages: the solid
             feels the force the granules feel at every stage, and the energy the two sides
             exchange agrees to the order of Simpson's rule (default);
  linear     nodes (0, 1): the force linear over the step (second order; for convergence studies).
A force polynomial carries no memory from step to step: a contact that opens has F = 0 at every
node and exerts nothing. (A C1 cubic whose start slope came from the previous step kept the slope
of a contact's last loaded step after it opened and pushed and pulled the solid through an open
contact; a massless residual compliance R made the contacts' velocity R F' follow the force's
slope, so that friction saw the slope with a gain R / h. Both broke Newton and leaked energy;
docs/performance.md has the measurements.)

`solid.propagation` gives each mode's displacement and velocity per unit force datum at each node,
so the contacts' motion at the nodes is affine in X. The granules are integrated by RK4 under the
polynomial through the contacts' exact displacements and velocities at the step's start and at
every node (a cubic for the linear model, a quintic for the quadratic one); the map X -> G(X)
returns the contact law's forces (eqs. 2, 5) at the nodes, the granular state at an interior node
by cubic Hermite interpolation of the step's ends and derivatives. Newton on X = G(X) uses the
contact law's derivatives and each contact granule's own response (`_granule_response`).

Local error of the whole coupled step (`step_error`): the embedded third-order solution of
classical RK4 with the end-of-step derivative (FSAL weights (1, 2, 2, 0, 1)/6, err = h/6 (k4 - k5)
per RK4 sub-step) on the granules' velocities and spin velocities against atol + rtol v_ref, and
the step's defect of the energy ledger (13) against the run's bound ledger_tol e_ref: its
random-walk share (the defects are RK4's and the interface's local energy errors, fifth order and
of either sign) and the room the ledger's drift has left. The controller (`next_level`) picks the
next step on a geometric grid h_k = h_max 2^(-k/4) (so the per-step operators are cached), a step
never crosses a load's kink, and outputs come by dense output inside the step that passes them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..granular.bundles import ACC_WORK, InterfaceForces, Motion, interface_buffers, motion_buffers
from ..granular.contact import friction_map_slope, tanh_friction
from ..granular.kernels import (friction_rate, granule_energies, interface_forces, load_value, motion_at, moved_beyond,
                                overlaps, rhs, rk4_step, rk4_substepped, wall_forces)
from ..guard.jit import njit
from ..solid.propagation import basis_values, interpolation_taylor, weights_at
from . import core

GRID_PER_OCTAVE = 4
# Newton's matrix serves later steps (a chord across steps) while their grid level is within
# REUSE_LEVELS of the one it was built at and the iteration contracts by REUSE_RATE or better
REUSE_LEVELS = 2
REUSE_RATE = 0.2
# the energy-ledger control (`step_error`, `control_error`): a step's defect of the ledger (13) is
# accepted up to LEDGER_ACCEPT times its share (`ledger_share`), and the running mean square of
# defect / share (each clipped at LEDGER_CLIP, filter weight LEDGER_FILTER) aims at LEDGER_RMS^2
LEDGER_RMS = 0.4
LEDGER_FILTER = 0.2
LEDGER_CLIP = 1.0
LEDGER_ACCEPT = 2.0
ORDER = 4.5  # a step's ledger part goes as h^5 over a share as h^(1/2)
LEDGER_NOISE = 4.0  # a defect within this many times the iteration's noise (`_iteration_noise`) passes
# ... or within the ledger's round-off (`contact_roundoff`): a preloaded chain stores far more elastic
# energy than a small drive moves, and no step can close the ledger below its rounding
LEDGER_ROUNDOFF = 2.220446049250313e-16
FORCE_NODES = {"quadratic": (0.0, 0.5, 1.0), "linear": (0.0, 1.0)}


class ExactSolid(NamedTuple):
    """The solid's modes as the integrator propagates them (retained eigenmodes, then residual
    modes): omega (nr,), the contacts' modal matrix P = B Phi (2nc, nr), and the contacts' frame."""

    omega: np.ndarray
    P: np.ndarray
    frame: core.ContactFrame


class OpsCache(NamedTuple):
    """The force model's nodes (nb,: 0, then the nn = nb - 1 unknown nodes, the last at 1) and, per
    step size h (grid level k: h_max 2^(-k/4); the last slot for an off-grid step cut at a load's
    kink), computed on first use: the Lagrange basis's Taylor rows T, the modes' free-response
    weights at each unknown node (hom), their end displacement and velocity per unit modal datum
    (wd, wv), the contacts' displacement and velocity at each unknown node j per unit force datum b
    (Cu, Cw), and the basis's first and second integrals from the start to each unknown node."""

    nodes: np.ndarray  # (nb,)
    ready: np.ndarray  # (L+1,) bool
    T: np.ndarray  # (L+1, nb, 4)
    hom: np.ndarray  # (L+1, nn, nr, 3)
    wd: np.ndarray  # (L+1, nr, nb)
    wv: np.ndarray
    Cu: np.ndarray  # (L+1, nn, nb, 2nc, 2nc)
    Cw: np.ndarray
    I1: np.ndarray  # (L+1, nn, nb)
    I2: np.ndarray


def ops_cache(model: str, levels: int, nr: int, nc: int) -> OpsCache:
    """An empty operator cache of a force model for `levels` grid levels plus the off-grid slot."""
    nodes = np.asarray(FORCE_NODES[model], float)
    nb, L, m2 = len(nodes), levels + 2, 2 * nc
    nn = nb - 1
    return OpsCache(nodes, np.zeros(L, bool), np.zeros((L, nb, 4)), np.zeros((L, nn, nr, 3)), np.zeros((L, nr, nb)),
                    np.zeros((L, nr, nb)), np.zeros((L, nn, nb, m2, m2)), np.zeros((L, nn, nb, m2, m2)), np.zeros((L, nn, nb)),
                    np.zeros((L, nn, nb)))


class ExactConfig(NamedTuple):
    h_max: float
    levels: int  # L: the smallest grid step is h_max 2^(-L/4)
    adaptive: bool  # False: every step is h_max (a fixed step), but for retries of a failed one
    rtol: float
    atol: float  # [m/s]
    v_ref: float  # velocity scale of the error norm [m/s]
    e_ref: float  # energy scale of the error norm [J]
    ledger_tol: float  # the energy ledger (13) stays within ledger_tol e_ref
    ledger_limit: float  # [J] a drift beyond this stops the run (the control has failed)
    duration: float
    newton: bool
    abstol: float
    reltol: float
    max_iterations: int
    max_disp: float


class ExactState(NamedTuple):
    """The state at the current time: y and the granules' derivative dy there (the next step's
    first RK4 stage), the modes (eta, eta'), the interface force F on the solid (nc, 2) and its
    modal projection q = P'F, the contacts' displacement u and velocity w (2nc,), |N| and v_t; and
    the last step, for dense output and the next step's predictor: its start (suffix 0), its force
    data Fs (nb, nc, 2) at the nodes (Fs[-1] is F) with their projections qs (nb, nr) and basis Ts
    (nb, 4), and the contacts' motion over it. clock = [t, t0, the controller's running mean square
    of the ledger part, friction rate of the last step, energy ledger (13), its initial value, the
    controller's continuous level, the largest |input work| so far (`ledger_bound`)];
    meta = [grid level of the next step, rejected]."""

    y: np.ndarray
    dy: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    F: np.ndarray
    q: np.ndarray
    u: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    vrel: np.ndarray
    y0: np.ndarray
    eta0: np.ndarray
    etad0: np.ndarray
    Fs: np.ndarray
    qs: np.ndarray
    Ts: np.ndarray
    step_motion: Motion
    clock: np.ndarray
    meta: np.ndarray


def initial_state(y, dy, nr: int, nc: int, nb: int, ledger: float, level: int) -> ExactState:
    """The state at t = 0: the solid at rest, no interface force."""
    z, zc = (lambda k: np.zeros(k)), (lambda: np.zeros((nc, 2)))  # noqa: E731
    return ExactState(y, dy, z(nr), z(nr), zc(), z(nr), z(2 * nc), z(2 * nc), z(nc), z(nc), y.copy(), z(nr), z(nr),
                      np.zeros((nb, nc, 2)), np.zeros((nb, nr)), np.zeros((nb, 4)), Motion(zc(), zc(), zc(), zc(), zc(), zc()),
                      np.array([0.0, 0.0, 0.0, 0.0, ledger, ledger, float(level), 0.0]), np.array([level, 0], np.int64))


class Work(NamedTuple):
    """Scratch of one step: the trial granular state, RK4 stages and error, the contacts at the
    nodes, the unknowns and the map's values, Newton's system, the modal data of the trial."""

    ytr: np.ndarray
    rk4: np.ndarray  # (5, len(y))
    k5: np.ndarray
    err: np.ndarray  # embedded error of the granular state
    ynode: np.ndarray  # the granular state at an interior node
    motion: Motion
    un: np.ndarray  # (nn, 2nc) the contacts at the unknown nodes ...
    wn: np.ndarray
    uf: np.ndarray  # ... and their part that does not depend on X (free response and F0's share)
    wf: np.ndarray
    X: np.ndarray  # (nn 2nc,) unknowns: the forces at the unknown nodes, node-major
    Xprev: np.ndarray  # before the last Newton step
    G: np.ndarray
    r: np.ndarray
    iface0: InterfaceForces  # at the first unknown node ...
    iface1: InterfaceForces  # ... and at the second (quadratic model)
    ww: np.ndarray  # (2 nn, nr) modal scratch
    cw: np.ndarray  # (2nc, 2 nn) its values at the contacts
    rate: np.ndarray  # (1,): the friction rate of the step's RK4 sub-steps
    parts: np.ndarray  # (3,): the last step's scaled velocity error and energy-ledger parts (`step_error`)
    qdat: np.ndarray  # (nb, nr): the modal force data of the trial step (P'F0, P'X)
    eta1: np.ndarray  # (nr,): the modes at the trial step's end
    etad1: np.ndarray
    inv_m: np.ndarray  # (nc,): 1/m and R^2/I of each contact's granule
    spin: np.ndarray
    # Newton: the rows of -dG/dX, the touching contacts' factorised system, local problems
    J: np.ndarray  # (nn 2nc, nn 2nc)
    dX: np.ndarray
    touching: np.ndarray  # (nc,) bool
    idx: np.ndarray  # (nn 2nc,) int: the touching unknowns
    na: np.ndarray  # (1,) int: their count
    mslot: np.ndarray  # (3,) int: the matrix's step level, the last step's iterations, the iteration it was built at
    piv: np.ndarray
    pivA: np.ndarray
    Ma: np.ndarray
    rhs_a: np.ndarray
    A: np.ndarray  # (2nn, 2nn)
    Ai: np.ndarray
    rows: np.ndarray  # (2nn, nn 2nc)
    col: np.ndarray
    ls: np.ndarray  # (nn,) the local friction problem
    ls0: np.ndarray
    lvt: np.ndarray
    lN: np.ndarray
    lB: np.ndarray
    lr: np.ndarray
    lJ: np.ndarray
    noise: np.ndarray  # (2,): the converged forces' work uncertainty over the step (`_iteration_noise`), the
    # ledger's round-off (`trial_ledger`)


@njit(cache=True)
def work_for(y, nc, nr, nb):
    m2 = 2 * nc
    nn = nb - 1
    n = nn * m2
    v = lambda k: np.zeros(k)  # noqa: E731
    return Work(np.empty_like(y), np.empty((5, y.shape[0])), np.empty_like(y), np.zeros_like(y), np.empty_like(y),
                motion_buffers(nc), np.zeros((nn, m2)), np.zeros((nn, m2)), np.zeros((nn, m2)), np.zeros((nn, m2)), v(n), v(n),
                v(n), v(n), interface_buffers(nc), interface_buffers(nc), np.zeros((2 * nn, nr)), np.zeros((m2, 2 * nn)),
                v(1), v(3), np.zeros((nb, nr)), v(nr), v(nr), v(nc), v(nc), np.zeros((n, n)), v(n), np.zeros(nc, np.bool_),
                np.zeros(n, np.int64), np.zeros(1, np.int64), np.array([-1, 99, 0], np.int64), np.zeros(n, np.int64),
                np.zeros(n, np.int64), np.zeros((n, n)), v(n),
                np.zeros((2 * nn, 2 * nn)), np.zeros((2 * nn, 2 * nn)), np.zeros((2 * nn, n)), v(2 * nn), v(nn), v(nn), v(nn),
                v(nn), np.zeros((nn, nn)), v(2), np.zeros((2, 2)), v(2))


@njit(cache=True, inline="always")
def node_iface(w, j):
    """The interface-force buffer of unknown node j."""
    return w.iface0 if j == 0 else w.iface1


# ---------------------------------------------------------------- per-step operators


@njit(cache=True)
def ensure_ops(cache, solid, slot, h):
    """Fill `cache` slot `slot` for step size h (once per grid level; always for the off-grid slot):
    per unknown node j at tau_j the modes' free response, the contacts' displacement and velocity
    per unit force datum, P diag(wd_b) P' and P diag(wv_b) P', and the basis's integrals; and the
    modes' end weights."""
    if cache.ready[slot]:
        return
    omega, P = solid.omega, solid.P
    nodes = cache.nodes
    nb = nodes.shape[0]
    nr = omega.shape[0]
    T = cache.T[slot]
    interpolation_taylor(nodes, np.zeros(nb, np.int64), h, T)
    wd, wv = np.empty((nr, nb)), np.empty((nr, nb))
    for j in range(nb - 1):
        tau = nodes[j + 1] * h
        weights_at(omega, tau, T, cache.hom[slot, j], wd, wv)
        for b in range(nb):
            cache.Cu[slot, j, b, :, :] = np.dot(P * wd[:, b].copy(), P.T)
            cache.Cw[slot, j, b, :, :] = np.dot(P * wv[:, b].copy(), P.T)
            i1 = 0.0
            i2 = 0.0
            fact = 1.0
            for k in range(4):  # int_0^tau H_b = sum_k T[b, k] tau^(k+1) / (k+1)!, and the double integral
                fact *= k + 1
                i1 += T[b, k] * tau ** (k + 1) / fact
                i2 += T[b, k] * tau ** (k + 2) / (fact * (k + 2))
            cache.I1[slot, j, b] = i1
            cache.I2[slot, j, b] = i2
    cache.wd[slot, :, :] = wd  # the last node is the step's end
    cache.wv[slot, :, :] = wv
    cache.ready[slot] = slot < cache.ready.shape[0] - 1  # the off-grid slot is recomputed each time


@njit(cache=True, fastmath={"reassoc", "nsz", "contract"})
def contacts_of_modes(P, V, out):
    """out[r, k] = sum_i P[r, i] V[k, i]: modal vectors V (K, nr) seen at the contacts. The sums
    are reassociated (vectorised; their rounding differs from a BLAS product's at 1e-16), and
    the rows of V are taken two at a time with P's row read once per pair: on the paper's plate
    (20 x 988, K = 4) 2.6 us against 7.8 us for np.dot."""
    m2, nr = P.shape
    K = V.shape[0]
    for r in range(m2):
        k = 0
        while k + 1 < K:
            a0 = 0.0
            a1 = 0.0
            for i in range(nr):
                p = P[r, i]
                a0 += p * V[k, i]
                a1 += p * V[k + 1, i]
            out[r, k] = a0
            out[r, k + 1] = a1
            k += 2
        if k < K:
            a0 = 0.0
            for i in range(nr):
                a0 += P[r, i] * V[k, i]
            out[r, k] = a0


@njit(cache=True)
def modes_of_contacts(X, P, out):
    """out[a, i] = sum_r X[a, r] P[r, i]: contact vectors X (A, 2nc) projected on the modes (P'
    applied to each row), accumulated along P's rows (2.5 us against 7.6 us for np.dot with
    A = 2 on the paper's plate)."""
    A, m2 = X.shape
    nr = P.shape[1]
    for a in range(A):
        for i in range(nr):
            out[a, i] = 0.0
        for r in range(m2):
            x = X[a, r]
            if x == 0.0:
                continue
            for i in range(nr):
                out[a, i] += x * P[r, i]


@njit(cache=True)
def free_response(st, solid, cache, slot, w):
    """The part of the contacts' displacement and velocity at each unknown node that does not
    depend on X (w.uf, w.wf): P applied to the modes' free response, plus the start force's
    share."""
    nr = st.eta.shape[0]
    m2 = st.u.shape[0]
    nn = cache.nodes.shape[0] - 1
    if nr == 0:
        w.uf[:, :] = 0.0
        w.wf[:, :] = 0.0
        return
    ww = w.ww
    for j in range(nn):
        hom = cache.hom[slot, j]
        for i in range(nr):
            ww[2 * j, i] = hom[i, 0] * st.eta[i] + hom[i, 1] * st.etad[i]
            ww[2 * j + 1, i] = hom[i, 2] * st.eta[i] + hom[i, 0] * st.etad[i]
    out = w.cw
    contacts_of_modes(solid.P, ww, out)
    for j in range(nn):
        Cu, Cw = cache.Cu[slot, j, 0], cache.Cw[slot, j, 0]
        for r in range(m2):
            u = out[r, 2 * j]
            v = out[r, 2 * j + 1]
            for q in range(m2):
                f0 = st.F[q // 2, q % 2]
                u += Cu[r, q] * f0
                v += Cw[r, q] * f0
            w.uf[j, r] = u
            w.wf[j, r] = v


# ---------------------------------------------------------------- the interface map


@njit(cache=True)
def _motion_at_nodes(st, cache, slot, h, w):
    """For the unknowns w.X: the contacts' displacement and velocity at every unknown node (affine
    in X), and the motion the granules' RK4 sees: the polynomial through the exact displacements
    and velocities at the step's start and at every node, so that the forces at the nodes are the
    ones the granules feel there."""
    m2 = st.u.shape[0]
    nb = cache.nodes.shape[0]
    nn = nb - 1
    X = w.X
    for j in range(nn):
        Cu, Cw = cache.Cu[slot, j], cache.Cw[slot, j]
        for r in range(m2):
            u = w.uf[j, r]
            v = w.wf[j, r]
            for b in range(1, nb):
                for q in range(m2):
                    x = X[(b - 1) * m2 + q]
                    u += Cu[b, r, q] * x
                    v += Cw[b, r, q] * x
            w.un[j, r] = u
            w.wn[j, r] = v
    e = nn - 1
    for r in range(m2):
        c = r // 2
        d = r % 2
        u0, v0, u1, w1 = st.u[r], st.w[r], w.un[e, r], w.wn[e, r]
        c2 = (3.0 * (u1 - u0) / h - 2.0 * v0 - w1) / h
        c3 = (2.0 * (u0 - u1) / h + v0 + w1) / (h * h)
        c4 = c5 = 0.0
        if nn == 2:
            # through the mid-step node too: add tau^2 (tau - h)^2 (al + be tau), which leaves the
            # ends alone and meets the exact displacement and velocity at h/2 (a quintic)
            hh = 0.5 * h
            du = w.un[0, r] - (u0 + (v0 + (c2 + c3 * hh) * hh) * hh)
            dw = w.wn[0, r] - (v0 + (2.0 * c2 + 3.0 * c3 * hh) * hh)
            be = 16.0 * dw / h**4
            al = 16.0 * du / h**4 - be * hh
            c2 += al * h * h
            c3 += be * h * h - 2.0 * h * al
            c4 = al - 2.0 * h * be
            c5 = be
        w.motion.u0[c, d] = u0
        w.motion.v0[c, d] = v0
        w.motion.a[c, d] = 2.0 * c2
        w.motion.j[c, d] = 6.0 * c3
        w.motion.d4[c, d] = 24.0 * c4
        w.motion.d5[c, d] = 120.0 * c5


@njit(cache=True)
def _rk4_with_estimate(st, t, h, model, motion, rate, w):
    """RK4 (sub-stepped where friction is stiff) from the step's start into w.ytr, the first
    stage being the state's derivative st.dy (first same as last: the contacts start where the
    last step left them), the end derivative in w.k5 and the embedded third-order error
    h/6 (k4 - k5) summed over sub-steps in w.err. False if the state stops being finite."""
    m = max(1, int(math.ceil(rate * h / 2.0)))
    s = h / m
    w.ytr[:] = st.y
    w.err[:] = 0.0
    n = w.ytr.shape[0]
    for k in range(m):
        if k == 0:
            w.rk4[0, :] = st.dy
        if not rk4_step(w.ytr, t + k * s, s, model, motion, k * s, w.rk4, k == 0):
            return False
        rhs(t + (k + 1) * s, w.ytr, w.k5, model, motion, (k + 1) * s)
        k4 = w.rk4[3]
        for q in range(n):
            w.err[q] += s / 6.0 * (k4[q] - w.k5[q])
    return True


@njit(cache=True)
def force_map(st, t, h, model, cache, slot, rate, w, derivatives):
    """X -> G(X): the forces at the unknown nodes after RK4 of the granules under the contacts'
    motion that X implies. Fills w.G, the nodes' interface buffers (with the law's derivatives if
    asked), w.ytr, w.k5, w.err. False if the granular state stopped being finite."""
    _motion_at_nodes(st, cache, slot, h, w)
    if not _rk4_with_estimate(st, t, h, model, w.motion, rate, w):
        return False
    nc = st.F.shape[0]
    m2 = 2 * nc
    nodes = cache.nodes
    for j in range(nodes.shape[0] - 1):
        s = nodes[j + 1]
        yj = w.ytr
        if s < 1.0:
            # the granules at an interior node: the cubic Hermite through the step's ends and their
            # derivatives (fourth order locally; the end derivative comes with the error estimate)
            h00, h10 = (2.0 * s - 3.0) * s * s + 1.0, ((s - 2.0) * s + 1.0) * s * h
            h01, h11 = (3.0 - 2.0 * s) * s * s, (s - 1.0) * s * s * h
            for q in range(w.ynode.shape[0]):
                w.ynode[q] = h00 * st.y[q] + h10 * st.dy[q] + h01 * w.ytr[q] + h11 * w.k5[q]
            yj = w.ynode
        iface = node_iface(w, j)
        interface_forces(yj, model, w.un[j].reshape(nc, 2), w.wn[j].reshape(nc, 2), iface, derivatives)
        for r in range(m2):
            w.G[j * m2 + r] = iface.F[r // 2, r % 2]
    return True


# ---------------------------------------------------------------- Newton on X = G(X)


@njit(cache=True)
def _jacobian_rows(M, rows, c, iface, Cu, Cw):
    """Contact c's two rows (at rows, rows + 1) of M = -dG/dX at fixed granules for one unknown
    node: its forces move with the node's displacement (Du) and velocity (Dw), which move with
    each unknown force datum b >= 1 through Cu[b], Cw[b]."""
    m2 = Cu.shape[1]
    nb = Cu.shape[0]
    Du, Dw = iface.Du, iface.Dw
    for b in range(1, nb):
        col0 = (b - 1) * m2
        for q in range(m2):
            for d in range(2):
                M[rows + d, col0 + q] = -(Du[c, d, 0] * Cu[b, 2 * c, q] + Du[c, d, 1] * Cu[b, 2 * c + 1, q]
                                          + Dw[c, d, 0] * Cw[b, 2 * c, q] + Dw[c, d, 1] * Cw[b, 2 * c + 1, q])


@njit(cache=True)
def _granule_response(w, cache, slot, c, tangent, A):
    """(I - Dg) for contact c over its unknown nodes (2nn x 2nn): the contact granule feels the
    opposite of the force change, sum_b H_b(tau) dG_b, so at node j it has moved by
    -sum_b I2_jb dG_b / m and its contact velocity has changed by -sum_b M^-1 I1_jb dG_b (I1, I2:
    the basis's first and second integrals from the step's start; M^-1 = I/m + t t' R^2/I, the spin
    carrying the tangential part), which changes the forces by Dg dG. The granule's other
    contacts are left out (the paper's Assumption 3 drops the whole response)."""
    nn = cache.nodes.shape[0] - 1
    tx, ty = tangent[c, 0], tangent[c, 1]
    im, sp = w.inv_m[c], w.spin[c]
    Mi00, Mi01, Mi11 = im + sp * tx * tx, sp * tx * ty, im + sp * ty * ty
    for j in range(nn):
        iface = node_iface(w, j)
        Du, Dw = iface.Du, iface.Dw
        for b in range(nn):
            i1, i2 = cache.I1[slot, j, 1 + b], cache.I2[slot, j, 1 + b]
            for d in range(2):
                g0 = Du[c, d, 0] * im * i2 + (Dw[c, d, 0] * Mi00 + Dw[c, d, 1] * Mi01) * i1
                g1 = Du[c, d, 1] * im * i2 + (Dw[c, d, 0] * Mi01 + Dw[c, d, 1] * Mi11) * i1
                A[2 * j + d, 2 * b] = (1.0 if (j == b and d == 0) else 0.0) - g0
                A[2 * j + d, 2 * b + 1] = (1.0 if (j == b and d == 1) else 0.0) - g1


@njit(cache=True)
def _friction_residual(s, s0, vt0, normal, B, mu, ks, out):
    """The local friction model's residual s_j - mu N_j tanh(k_s vt_j(s)), vt_j(s) =
    vt0_j - sum_b B_jb (s_b - s0_b); returns its squared norm."""
    total = 0.0
    nn = s.shape[0]
    for j in range(nn):
        vt = vt0[j]
        for b in range(nn):
            vt -= B[j, b] * (s[b] - s0[b])
        out[j] = s[j] + tanh_friction(normal[j], vt, mu, ks)  # eq. (5): the force on the solid is -ft
        total += out[j] * out[j]
    return total


@njit(cache=True)
def local_friction_solve(s, s0, vt0, normal, B, law, r, Jl):
    """The tangential forces s (nn <= 2,) at a contact's unknown nodes that its local friction
    model holds fixed: s_j = mu N_j tanh(k_s vt_j), vt_j = vt0_j - sum_b B_jb (s_b - s0_b), B the
    tangential velocity's response to the tangential forces (solid and granule); s comes in as the
    Newton update and leaves as the root (damped Newton, each s_j within +-mu N_j). Where the tanh
    is steep, Newton's linear model overshoots it; this keeps the nodes' coupling that a root for
    one node at a time would break."""
    nn = s.shape[0]
    mu, ks = law.mu, law.k_s
    trial = np.empty(2)
    rt = np.empty(2)
    norm = _friction_residual(s, s0, vt0, normal, B, mu, ks, r)
    scale = 0.0
    for j in range(nn):
        scale = max(scale, mu * normal[j])
    for _ in range(60):
        if norm <= (1e-13 * scale) ** 2:
            return
        for j in range(nn):
            vt = vt0[j]
            for b in range(nn):
                vt -= B[j, b] * (s[b] - s0[b])
            for b in range(nn):
                Jl[j, b] = (1.0 if j == b else 0.0) + friction_map_slope(mu, ks, normal[j], vt, B[j, b])
        if nn == 1:
            ds0, ds1 = r[0] / Jl[0, 0], 0.0
        else:
            det = Jl[0, 0] * Jl[1, 1] - Jl[0, 1] * Jl[1, 0]
            ds0 = (Jl[1, 1] * r[0] - Jl[0, 1] * r[1]) / det
            ds1 = (Jl[0, 0] * r[1] - Jl[1, 0] * r[0]) / det
        lam = 1.0
        while True:
            for j in range(nn):
                trial[j] = min(mu * normal[j], max(-mu * normal[j], s[j] - lam * (ds0 if j == 0 else ds1)))
            tn = _friction_residual(trial[:nn], s0, vt0, normal, B, mu, ks, rt)
            if tn < norm or lam < 1e-6:
                break
            lam *= 0.5
        if tn >= norm:
            return
        s[:] = trial[:nn]
        r[:nn] = rt[:nn]
        norm = tn


@njit(cache=True)
def _touching(w, nc, nn):
    """Mark the contacts touching at some unknown node; True if the set changed."""
    changed = False
    for c in range(nc):
        touching = False
        for j in range(nn):
            if node_iface(w, j).normal[c] > 0.0:
                touching = True
        if touching != w.touching[c]:
            changed = True
        w.touching[c] = touching
    return changed


@njit(cache=True)
def _newton_matrix(w, cache, slot, frame):
    """I - dG/dX on the touching contacts' unknowns, factorised into w.Ma (their indices in w.idx,
    their count in w.na): dG/dX from the contact law's derivatives (`_jacobian_rows`) and each
    contact granule's own response (`_granule_response`), dG = (I - Dg)^-1 (dG at fixed granules);
    the full rows in w.J (for the open contacts' columns). False if singular."""
    nn = cache.nodes.shape[0] - 1
    m2 = w.un.shape[1]
    nc = m2 // 2
    n = nn * m2
    M, A, rows, idx, piv = w.J, w.A, w.rows, w.idx, w.piv
    na = 0
    for j in range(nn):
        for c in range(nc):
            if w.touching[c]:
                idx[na] = j * m2 + 2 * c
                idx[na + 1] = j * m2 + 2 * c + 1
                na += 2
    w.na[0] = na
    for c in range(nc):
        if not w.touching[c]:
            continue
        for j in range(nn):
            _jacobian_rows(rows, 2 * j, c, node_iface(w, j), cache.Cu[slot, j], cache.Cw[slot, j])
        _granule_response(w, cache, slot, c, frame.tangent, A)
        if not core.lu_factor(A, 2 * nn, piv):
            return False
        Ai = w.Ai
        for i in range(2 * nn):  # A^-1, column by column
            for k in range(2 * nn):
                w.col[k] = 1.0 if k == i else 0.0
            core.lu_solve(A, 2 * nn, piv, w.col)
            for k in range(2 * nn):
                Ai[k, i] = w.col[k]
        for j in range(nn):  # the contact's rows <- A^-1 rows
            for d in range(2):
                i = 2 * j + d
                for q in range(n):
                    acc = 0.0
                    for k in range(2 * nn):
                        acc += Ai[i, k] * rows[k, q]
                    M[j * m2 + 2 * c + d, q] = acc
    for a in range(na):
        for b in range(na):
            w.Ma[a, b] = M[idx[a], idx[b]] + (1.0 if a == b else 0.0)
    return na == 0 or core.lu_factor(w.Ma, na, w.pivA)


@njit(cache=True)
def _newton_step(w, cache, slot, frame, law):
    """X <- X + dX with (I - dG/dX) dX = G - X (`_newton_matrix`, possibly from an earlier iterate
    of the step). A contact open at every node exerts no force whatever X: its forces are set to
    zero, and the system is solved for the touching contacts only. Then, where a contact's
    friction is stiff (its local map is not contractive, the paper's |lambda| > 1), its tangential
    forces at all nodes come from the root of its local friction model (`local_friction_solve`)."""
    nn = cache.nodes.shape[0] - 1
    m2 = w.un.shape[1]
    nc = m2 // 2
    n = nn * m2
    M, idx = w.J, w.idx
    na = w.na[0]
    for j in range(nn):
        for c in range(nc):
            for d in range(2):
                k = j * m2 + 2 * c + d
                w.dX[k] = 0.0 if w.touching[c] else -w.X[k]
    for a in range(na):
        ra = idx[a]
        acc = w.G[ra] - w.X[ra]
        for q in range(n):
            if w.dX[q] != 0.0:
                acc -= M[ra, q] * w.dX[q]
        w.rhs_a[a] = acc
    if na > 0:
        core.lu_solve(w.Ma, na, w.pivA, w.rhs_a)
        for a in range(na):
            w.dX[idx[a]] = w.rhs_a[a]
    s, s0, vt0, N, B = w.ls, w.ls0, w.lvt, w.lN, w.lB
    for c in range(nc):
        tx, ty = frame.tangent[c, 0], frame.tangent[c, 1]
        stiff = False
        for j in range(nn):
            iface = node_iface(w, j)
            k = j * m2 + 2 * c
            s0[j] = w.X[k] * tx + w.X[k + 1] * ty
            w.X[k] += w.dX[k]
            w.X[k + 1] += w.dX[k + 1]
            s[j] = w.X[k] * tx + w.X[k + 1] * ty
            vt0[j] = iface.vrel[c]
            N[j] = max(iface.normal[c], 0.0)
            for b in range(nn):
                B[j, b] = core.tangential_compliance(cache.Cw[slot, j, 1 + b], c, tx, ty) \
                    + (w.inv_m[c] + w.spin[c]) * cache.I1[slot, j, 1 + b]
            if N[j] > 0.0 and friction_map_slope(law.mu, law.k_s, N[j], 0.0, B[j, j]) > 1.0:
                stiff = True
        if not stiff or not frame.has_tangent[c]:
            continue
        local_friction_solve(s, s0, vt0, N, B, law, w.lr, w.lJ)
        for j in range(nn):
            k = j * m2 + 2 * c
            now = w.X[k] * tx + w.X[k + 1] * ty
            w.X[k] += (s[j] - now) * tx
            w.X[k + 1] += (s[j] - now) * ty


@njit(cache=True)
def predict(st, cache, h, X):
    """The unknowns' first guess: the last step's force polynomial continued into the new step
    (the current force where that step is much shorter than the new one, or at the start)."""
    nodes = cache.nodes
    nb = nodes.shape[0]
    m2 = st.u.shape[0]
    hp = st.clock[0] - st.clock[1]
    H, dH = np.empty(nb), np.empty(nb)
    for j in range(nb - 1):
        if hp <= 0.0 or h > 2.0 * hp:
            for r in range(m2):
                X[j * m2 + r] = st.F[r // 2, r % 2]
            continue
        basis_values(st.Ts, hp + nodes[j + 1] * h, H, dH)
        for r in range(m2):
            acc = 0.0
            for b in range(nb):
                acc += H[b] * st.Fs[b, r // 2, r % 2]
            X[j * m2 + r] = acc


@njit(cache=True)
def _iteration_noise(st, w, nn, m2):
    """What the converged iteration leaves open in the step's energy ledger (13): the forces the
    granules felt (G) and the ones the solid takes (X) differ within the tolerance, and the
    difference works through the contacts' displacement over the step: sum |G - X| |u_j - u_0|."""
    total = 0.0
    for j in range(nn):
        for r in range(m2):
            total += abs(w.G[j * m2 + r] - w.X[j * m2 + r]) * abs(w.un[j, r] - st.u[r])
    return total


@njit(cache=True)
def interface_solve(st, t, h, model, solid, cache, slot, cfg, w):
    """Iterate X = G(X) for one step of size h (Newton, or the fixed point). Returns (status,
    iterations); on success w holds the end state."""
    nc = st.F.shape[0]
    m2 = 2 * nc
    nn = cache.nodes.shape[0] - 1
    n = nn * m2
    predict(st, cache, h, w.X)
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
    last = np.inf
    backtracks = 0
    for it in range(1, cfg.max_iterations + 1):
        if not force_map(st, t, h, model, cache, slot, rate, w, cfg.newton):
            return core.NON_FINITE, it
        if solid.frame.fixed:
            w.X[:] = w.G
            return core.CONVERGED, it
        ok = True
        worst = 0.0  # the largest residual against its tolerance
        for r in range(n):
            ratio = abs(w.G[r] - w.X[r]) / (cfg.abstol + cfg.reltol * abs(w.X[r]))
            worst = max(worst, ratio)
            if ratio > 1.0:
                ok = False
        # at the round-off floor (tiny steps amplify it) Newton stalls: a stalled residual within
        # 100 tolerances is converged
        if not ok and it > 1 and worst <= 100.0 and worst > 0.5 * last:
            ok = True
        if not ok and cfg.newton and worst > 2.0 * last and backtracks < 6:
            # the step made things worse (its linear model overshot, e.g. a saturating friction or
            # a contact that opened): halve it
            backtracks += 1
            for r in range(n):
                w.X[r] = 0.5 * (w.X[r] + w.Xprev[r])
            continue
        backtracks = 0
        rate = worst / last if it > 1 else 0.0
        last = worst
        if ok or not cfg.newton:
            if ok:
                w.noise[0] = _iteration_noise(st, w, nn, m2)
            w.X[:] = w.G
            if ok:
                w.mslot[1] = it
                return core.CONVERGED, it
            continue
        # a chord Newton: the matrix serves the step's later iterates (as few iterations as a
        # fresh matrix each time, measured) and the next steps near its size while it contracts
        # well, unless a contact opened or closed
        changed = _touching(w, nc, nn)
        stale = abs(w.mslot[0] - slot) > REUSE_LEVELS or slot == cache.ready.shape[0] - 1 or w.mslot[0] < 0
        if changed or (it == 1 and stale) or (it > 1 and w.mslot[2] == 0 and rate > REUSE_RATE):
            if not _newton_matrix(w, cache, slot, solid.frame):
                return core.NO_CONVERGENCE, it
            w.mslot[0] = slot
            w.mslot[2] = it  # built at this iteration of this step (0: inherited from the last step)
        elif it == 1:
            w.mslot[2] = 0
        w.Xprev[:] = w.X
        _newton_step(w, cache, slot, solid.frame, model.law)
    return core.NO_CONVERGENCE, cfg.max_iterations


# ---------------------------------------------------------------- error, accept, step loop


@njit(cache=True, inline="always")
def propagate_mode(hom, wd, wv, i, eta0, etad0, qdat):
    """Mode i's displacement and velocity after a step (or at a point inside it) from its start
    state and its modal force data qdat (nb, nr), with the weights of
    `solid.propagation.weights_at`."""
    eta = hom[i, 0] * eta0 + hom[i, 1] * etad0
    etad = hom[i, 2] * eta0 + hom[i, 0] * etad0
    for b in range(wd.shape[1]):
        eta += wd[i, b] * qdat[b, i]
        etad += wv[i, b] * qdat[b, i]
    return eta, etad


@njit(cache=True)
def trial_ledger(st, solid, cache, slot, model, w):
    """E_solid + E_granular + D - W (eq. 13) at the end of the trial step: the modes' energy from
    their exact end state (kept in w with the modal data, for the accept), the granules' energy
    (11) and the ledger's accumulators."""
    m2 = st.u.shape[0]
    nr = st.eta.shape[0]
    nn = cache.nodes.shape[0] - 1
    if nr > 0:
        w.qdat[0, :] = st.q
        modes_of_contacts(w.X.reshape(nn, m2), solid.P, w.qdat[1:])
    hom = cache.hom[slot, nn - 1]
    wd, wv = cache.wd[slot], cache.wv[slot]
    es = 0.0
    for i in range(nr):
        e, v = propagate_mode(hom, wd, wv, i, st.eta[i], st.etad[i], w.qdat)
        w.eta1[i] = e
        w.etad1[i] = v
        es += 0.5 * (v * v + solid.omega[i] ** 2 * e * e)
    kin, rot, pot = granule_energies(w.ytr, model, w.un[nn - 1].reshape(m2 // 2, 2))
    n = kin.shape[0]
    eg = kin.sum() + rot.sum() + pot.sum()
    spent = w.ytr[6 * n] + w.ytr[6 * n + 1]
    work = w.ytr[6 * n + 2]
    w.noise[1] = LEDGER_ROUNDOFF * (es + eg + abs(spent) + abs(work))
    return es + eg + spent - work


@njit(cache=True)
def contact_roundoff(y, dy, model, su, t):
    """The rounding of the contacts' potential energy in the ledger (13), in two parts. Each
    overlap is a difference of lengths of the size of the radii, rounded to LEDGER_ROUNDOFF of
    that, which its force A delta^(3/2) turns into energy. And rounding granule i's position
    (LEDGER_ROUNDOFF of its coordinates) changes its contacts' energy by the net contact force on
    it, m a minus the loads (dy holds a, at the step's start), times that. Under a static preload
    these are far above the energies' own rounding: ten steel beads (R = 5 mm) pressed by 10 N
    round their ledger by up to about 1e-17 J a step (measured), 7e-17 J by this estimate."""
    gr = model.granules
    radius = gr.radius
    n = radius.shape[0]
    V = 3 * n
    pairs, walls, points, loads = model.pairs, model.walls, model.points, model.loads
    dp, dw, ds = overlaps(y, model, su)
    sq = 0.0  # the contacts' roundings are independent: they add in quadrature
    for c in range(dp.shape[0]):
        if dp[c] > 0.0:
            sq += (pairs.A[c] * dp[c] * math.sqrt(dp[c]) * (radius[pairs.i[c]] + radius[pairs.j[c]])) ** 2
    for c in range(dw.shape[0]):
        if dw[c] > 0.0:
            sq += (walls.A[c] * dw[c] * math.sqrt(dw[c]) * radius[walls.g[c]]) ** 2
    for c in range(ds.shape[0]):
        if ds[c] > 0.0:
            sq += (points.A[c] * ds[c] * math.sqrt(ds[c]) * radius[points.g[c]]) ** 2
    total = math.sqrt(sq)
    for i in range(n):
        total += gr.mass[i] * math.hypot(dy[V + 2 * i], dy[V + 2 * i + 1]) * max(abs(y[2 * i]), abs(y[2 * i + 1]))
    for e in range(loads.g.shape[0]):
        i = loads.g[e]
        total += abs(load_value(loads, e, t)) * max(abs(y[2 * i]), abs(y[2 * i + 1]))
    return LEDGER_ROUNDOFF * total


@njit(cache=True)
def granular_ledger(y, model, su):
    """The granules' part of the ledger (13), E_granular + D - W, with the solid contact points
    displaced by su (nc, 2)."""
    kin, rot, pot = granule_energies(y, model, su)
    n = kin.shape[0]
    return kin.sum() + rot.sum() + pot.sum() + y[6 * n] + y[6 * n + 1] - y[6 * n + 2]


@njit(cache=True)
def state_ledger(y, eta, etad, solid, model):
    """E_solid + E_granular + D - W (eq. 13) of a state (the granules y, the modes eta, eta')."""
    nc = solid.P.shape[0] // 2
    es = 0.0
    for i in range(eta.shape[0]):
        es += 0.5 * (etad[i] * etad[i] + solid.omega[i] ** 2 * eta[i] * eta[i])
    su = np.dot(solid.P, eta) if eta.shape[0] else np.zeros(2 * nc)
    return es + granular_ledger(y, model, su.reshape(nc, 2))


@njit(cache=True)
def step_error(w, cfg, granules, t, h, defect, drift, tol):
    """The parts of the scaled local error of the coupled step from t to t + h, in w.parts: [0] the
    largest embedded RK4 error of a granule's velocity or spin velocity R omega against
    atol + rtol v_ref; [1] the step's defect of the energy ledger (13) against its share of the
    run's bound tol (`ledger_bound`, `ledger_share`), the ledger having drifted by `drift` so far;
    [2] the drift after the step against tol. A defect within LEDGER_NOISE times what the
    converged iteration leaves open (`_iteration_noise`), or within the ledger's round-off
    (LEDGER_ROUNDOFF of its terms), passes both: tighter steps would not close it. True if the step is accepted: [0] <= 1, [1] <= LEDGER_ACCEPT, [2] <= 1."""
    radius = granules.radius
    n = radius.shape[0]
    V = 3 * n
    OM = 5 * n
    ev = 0.0
    for i in range(n):
        ev = max(ev, abs(w.err[V + 2 * i]), abs(w.err[V + 2 * i + 1]), radius[i] * abs(w.err[OM + i]))
    w.parts[0] = ev / (cfg.atol + cfg.rtol * cfg.v_ref)
    # no step is asked to close the ledger below the iteration's own floor, nor below its round-off
    noise = max(LEDGER_NOISE * w.noise[0], w.noise[1])
    w.parts[1] = abs(defect) / max(ledger_share(cfg, t, h, drift, tol), noise, 1e-300)
    # a defect within the floor cannot be made smaller, whatever the drift: only a larger one counts
    w.parts[2] = max(abs(drift + defect) - noise, 0.0) / tol if abs(defect) > noise else 0.0
    return w.parts[0] <= 1.0 and w.parts[1] <= LEDGER_ACCEPT and w.parts[2] <= 1.0


@njit(cache=True)
def accept(st, cache, slot, h, w, rate, ledger):
    """The accepted step: modes, interface data and the granules to t + h; the step kept for dense
    output and the next predictor."""
    nc = st.F.shape[0]
    m2 = 2 * nc
    nb = cache.nodes.shape[0]
    nn = nb - 1
    st.y0[:] = st.y
    st.eta0[:] = st.eta
    st.etad0[:] = st.etad
    st.Fs[0, :, :] = st.F
    for b in range(1, nb):
        for r in range(m2):
            st.Fs[b, r // 2, r % 2] = w.X[(b - 1) * m2 + r]
    st.qs[:, :] = w.qdat  # from `trial_ledger`
    st.Ts[:, :] = cache.T[slot]
    st.eta[:] = w.eta1
    st.etad[:] = w.etad1
    st.F[:, :] = st.Fs[nb - 1]
    st.q[:] = st.qs[nb - 1]
    st.u[:] = w.un[nn - 1]
    st.w[:] = w.wn[nn - 1]
    mo, sm = w.motion, st.step_motion
    sm.u0[:, :] = mo.u0
    sm.v0[:, :] = mo.v0
    sm.a[:, :] = mo.a
    sm.j[:, :] = mo.j
    sm.d4[:, :] = mo.d4
    sm.d5[:, :] = mo.d5
    st.y[:] = w.ytr
    st.dy[:] = w.k5
    end = node_iface(w, nn - 1)
    st.normal[:] = end.normal
    st.vrel[:] = end.vrel
    st.clock[1] = st.clock[0]
    st.clock[0] += h
    st.clock[3] = rate
    st.clock[4] = ledger


@njit(cache=True)
def friction_slopes(st, law, cache, slot, frame, lam):
    """The slope of each contact's local friction map over the step just taken, the analogue of
    (A9) for this integrator: mu k_s |N| t' Cw t / cosh^2(k_s v_t), Cw the end velocity's
    response to the end force."""
    nb = cache.nodes.shape[0]
    for c in range(lam.shape[0]):
        if not frame.has_tangent[c]:
            lam[c] = 0.0
            continue
        ctt = core.tangential_compliance(cache.Cw[slot, nb - 2, nb - 1], c, frame.tangent[c, 0], frame.tangent[c, 1])
        lam[c] = friction_map_slope(law.mu, law.k_s, st.normal[c], st.vrel[c], ctt)


@njit(cache=True, inline="always")
def ledger_bound(cfg, st):
    """The run's bound on the energy ledger (13): ledger_tol times the larger of the energy scale
    e_ref (the loads' and initial motion's, known before the run) and the largest |input work| so
    far. The second counts the energy the loads actually move, which e_ref cannot foresee: a
    small drive on a preloaded chain makes the preload exchange F0 x with the contacts, far more
    than the drive's own work, and a bound below that exchange's round-off would stall the steps."""
    return cfg.ledger_tol * max(cfg.e_ref, st.clock[7])


@njit(cache=True)
def ledger_share(cfg, t, h, drift, tol):
    """What a step of size h from time t may add to the energy ledger (13), which has drifted by
    `drift` so far, tol being the run's bound (`ledger_bound`): its random-walk share
    tol sqrt(h / T) while the drift is small (fading out as the drift reaches tol / 2), or the
    room left spread evenly over the time left, (tol - |drift|) h / (T - t), whichever is larger.
    The defects, RK4's and the interface's local energy errors, are fifth order and mostly of
    either sign (they cancel over a collision), so they add up like a random walk, whose spread
    over the run is tol when every step spends its share; where they keep one sign, the drift
    grows and the even spread of the room left takes over, so the drift never passes tol."""
    room = max(tol - abs(drift), 0.0)
    walk = tol * math.sqrt(h / cfg.duration) * max(0.0, 1.0 - 2.0 * abs(drift) / tol)
    return max(walk, room * h / max(cfg.duration - t, h))


@njit(cache=True)
def next_level(lev, err, cfg):
    """The next continuous level lev (the step h_max 2^(-lev/4)) for a scaled error err that goes
    as h^ORDER, aiming at err = 1, with growth between 1/5 and 2; the step taken is on the grid
    at ceil(lev), so that operators are cached per grid level while small changes still add up."""
    if not cfg.adaptive:
        return 0.0
    fac = min(2.0, max(0.2, max(err, 1e-10) ** (-1.0 / ORDER)))
    return min(float(cfg.levels), max(0.0, lev - GRID_PER_OCTAVE * math.log2(fac)))


@njit(cache=True)
def control_error(w, st, h):
    """The scaled error the controller aims at 1 after an accepted step of size h: the velocity
    part, the ledger's random-walk part as the running mean square of the last steps' parts (the
    defect's size swings within a collision: one step's value is a poor guide to the next), each
    clipped at LEDGER_CLIP and rescaled to h, over LEDGER_RMS (the room left, once the drift has
    used the random walk's share, is in that part through `ledger_share`; the drift itself is
    past and no step size undoes it, so it only rejects steps, `step_error`). Updates the
    running mean square in st.clock[2]."""
    hp = st.clock[0] - st.clock[1]
    r2 = min(w.parts[1], LEDGER_CLIP) ** 2
    if hp > 0.0 and st.clock[2] > 0.0:
        r2 = (1.0 - LEDGER_FILTER) * st.clock[2] * (h / hp) ** (2.0 * ORDER) + LEDGER_FILTER * r2
    st.clock[2] = r2
    return max(w.parts[0], math.sqrt(r2) / LEDGER_RMS)


@njit(cache=True, inline="always")
def grid_level(lev):
    """The grid level of a continuous level: the step is never above the controller's."""
    return int(math.ceil(lev - 1e-9))


@njit(cache=True)
def advance_outputs(st, model, ref_pos, solid, cache, cfg, targets, kinks, log, out, done):
    """Accepted steps through the output times `targets`, from output done[0] on: a step that
    reaches outputs fills their states in `out` (y, eta, eta', F per output) by dense output
    (`dense_state`) and, when adaptive, is accepted only if their energy ledgers (13) stay within
    the bound too (inside a step the interface's work is not the symmetric quadrature it is at
    the step's end); done[0] counts the outputs filled. Returns (status, steps logged): core.DONE
    once all are filled, core.REBUILD, core.LOG_FULL, core.NO_CONVERGENCE, core.NON_FINITE or
    core.BALANCE_LOST (the ledger (13) drifted beyond cfg.ledger_limit)."""
    w = work_for(st.y, st.F.shape[0], st.eta.shape[0], cache.nodes.shape[0])
    nc = st.F.shape[0]
    nb = cache.nodes.shape[0]
    n = model.granules.radius.shape[0]
    lim2 = cfg.max_disp * cfg.max_disp
    lam = np.zeros(nc)
    off = cache.ready.shape[0] - 1
    oy, oeta, oetad, oF = out
    # outputs the last accepted step already passed (it ended a previous batch beyond its last output)
    while done[0] < targets.shape[0] and targets[done[0]] <= st.clock[0]:
        o = done[0]
        dense_state(st, solid, model, targets[o], DenseOut(oy[o], oeta[o], oetad[o], oF[o]))
        done[0] += 1
    k = 0
    while done[0] < targets.shape[0]:
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
        status, its = interface_solve(st, t, h, model, solid, cache, slot, cfg, w)
        if status != core.CONVERGED:
            if level + 2 * GRID_PER_OCTAVE <= cfg.levels:
                st.meta[0] = level + 2 * GRID_PER_OCTAVE  # a quarter of the step (fixed steps: then dt again)
                st.clock[6] = st.meta[0]
                st.meta[1] += 1
                continue
            return status, k
        ledger = trial_ledger(st, solid, cache, slot, model, w)
        tol = ledger_bound(cfg, st)
        w.noise[1] = max(w.noise[1], contact_roundoff(w.ytr, st.dy, model, w.un[nb - 2].reshape(nc, 2), t + h))
        ok = step_error(w, cfg, model.granules, t, h, ledger - st.clock[4], st.clock[4] - st.clock[5], tol)
        # the outputs this step reaches, by dense output from its start (the last one may be its end)
        filled = 0
        worst_dense = 0.0
        while done[0] + filled < targets.shape[0] and targets[done[0] + filled] <= (t + h) * (1.0 + 1e-12):
            o = done[0] + filled
            tau = targets[o] - t
            if tau >= h * (1.0 - 1e-12):
                oy[o, :] = w.ytr
                oeta[o, :] = w.eta1
                oetad[o, :] = w.etad1
                for r in range(2 * nc):
                    oF[o, r // 2, r % 2] = w.X[(nb - 2) * 2 * nc + r]
            else:
                dense(trial_step(st, cache, slot, w), solid, model, tau, DenseOut(oy[o], oeta[o], oetad[o], oF[o]))
                defect = state_ledger(oy[o], oeta[o], oetad[o], solid, model) - st.clock[4]
                floor = max(LEDGER_NOISE * w.noise[0], w.noise[1])
                if abs(defect) > floor:
                    worst_dense = max(worst_dense, (abs(st.clock[4] - st.clock[5] + defect) - floor) / tol)
            filled += 1
        if cfg.adaptive and (not ok or worst_dense > 1.0) and level < cfg.levels:
            worst = max(w.parts[0], w.parts[1] / LEDGER_ACCEPT, w.parts[2], worst_dense)
            st.clock[6] = max(level + 1.0, next_level(st.clock[6], worst, cfg))
            st.meta[0] = grid_level(st.clock[6])
            st.meta[1] += 1
            continue
        if abs(ledger - st.clock[5]) > cfg.ledger_limit * max(1.0, st.clock[7] / cfg.e_ref):
            return core.BALANCE_LOST, k  # even the smallest step lost the energy balance (13)
        ectl = control_error(w, st, h)  # before the clock moves: it rescales from the last step
        accept(st, cache, slot, h, w, w.rate[0], ledger)
        st.clock[7] = max(st.clock[7], abs(st.y[6 * n + ACC_WORK]))
        done[0] += filled
        friction_slopes(st, model.law, cache, slot, solid.frame, lam)
        log.t[k] = st.clock[0]
        log.h[k] = h
        log.iterations[k] = its
        log.lam[k, :] = lam
        k += 1
        st.clock[6] = next_level(st.clock[6], ectl, cfg)
        st.meta[0] = grid_level(st.clock[6])
        if moved_beyond(st.y, n, ref_pos, lim2):
            return core.REBUILD, k
    return core.DONE, k


class OutputQuantities(NamedTuple):
    """Filled by `output_quantities` for a batch of K outputs."""

    media: np.ndarray  # (K, n_media)
    solid: np.ndarray  # (K, 2): kinetic, potential
    su: np.ndarray  # (K, nc, 2)
    overlap: np.ndarray  # (K,)
    where: np.ndarray  # (K, 2) int: kind, index
    walls: np.ndarray  # (K, n_walls, 2): the force each wall takes


@njit(cache=True)
def output_quantities(oy, oeta, oetad, model, solid, medium, n_media, q, times):
    """Per output o of a batch: each medium's energy (11) in q.media[o], the solid's kinetic and
    potential energy, the contacts' displacement, the deepest overlap (eq. 2) over the smaller
    radius with its kind (0 pair, 1 wall, 2 solid) and index, and the force on each wall (at the
    outputs' `times`, for moving walls)."""
    nc = solid.P.shape[0] // 2
    radius = model.granules.radius
    pairs, walls, points = model.pairs, model.walls, model.points
    for o in range(oy.shape[0]):
        su = np.dot(solid.P, oeta[o]) if solid.P.shape[1] else np.zeros(2 * nc)
        ep = 0.0
        for i in range(oeta.shape[1]):
            ep += 0.5 * solid.omega[i] ** 2 * oeta[o, i] ** 2
        q.solid[o, 0] = 0.5 * np.dot(oetad[o], oetad[o])
        q.solid[o, 1] = ep
        sup = su.reshape(nc, 2)
        q.su[o, :, :] = sup
        kin, rot, pot = granule_energies(oy[o], model, sup)
        for m in range(n_media):
            q.media[o, m] = 0.0
        for i in range(kin.shape[0]):
            q.media[o, medium[i]] += kin[i] + rot[i] + pot[i]
        dp, dw, ds = overlaps(oy[o], model, sup)
        best, kind, idx = 0.0, -1, -1
        for c in range(dp.shape[0]):
            r = dp[c] / min(radius[pairs.i[c]], radius[pairs.j[c]])
            if r > best:
                best, kind, idx = r, 0, c
        for c in range(dw.shape[0]):
            r = dw[c] / radius[walls.g[c]]
            if r > best:
                best, kind, idx = r, 1, c
        for c in range(ds.shape[0]):
            r = ds[c] / radius[points.g[c]]
            if r > best:
                best, kind, idx = r, 2, c
        q.overlap[o] = best
        q.where[o, 0] = kind
        q.where[o, 1] = idx
        wall_forces(oy[o], model, q.walls[o], times[o])


class StepData(NamedTuple):
    """A step as dense output reads it: its start (granules y0, modes eta0, eta0', time t0), its
    force data Fs (nb, nc, 2) with their modal projections qs (nb, nr) and basis Ts (nb, 4), the
    contacts' motion over it and the friction rate of its RK4 sub-steps."""

    y0: np.ndarray
    eta0: np.ndarray
    etad0: np.ndarray
    t0: float
    Fs: np.ndarray
    qs: np.ndarray
    Ts: np.ndarray
    motion: Motion
    rate: float


class DenseOut(NamedTuple):
    """One output's state, filled by `dense`: granules, modes, interface force (nc, 2)."""

    y: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    F: np.ndarray


@njit(cache=True)
def dense(step, solid, model, tau, out):
    """The state at tau inside a step: the granules by RK4 from the step's start over tau under the
    step's contact motion (full RK4 accuracy, the step itself unchanged), the modes by their exact
    response to the step's force polynomial, and the interface force as the contact law gives it
    there (what the granules feel: the polynomial the solid takes differs from it by its
    interpolation error inside the step)."""
    out.y[:] = step.y0
    if tau > 0.0:
        rk4_substepped(out.y, step.t0, tau, model, step.motion, step.rate, np.empty((5, out.y.shape[0])))
    nc = out.F.shape[0]
    if nc:
        u, w = np.empty((nc, 2)), np.empty((nc, 2))
        for c in range(nc):
            u[c, 0], u[c, 1], w[c, 0], w[c, 1] = motion_at(step.motion, c, tau)
        iface = interface_buffers(nc)
        interface_forces(out.y, model, u, w, iface, False)
        out.F[:, :] = iface.F
    nb, nr = step.Ts.shape[0], step.eta0.shape[0]
    hom, wd, wv = np.empty((nr, 3)), np.empty((nr, nb)), np.empty((nr, nb))
    weights_at(solid.omega, tau, step.Ts, hom, wd, wv)
    for i in range(nr):
        out.eta[i], out.etad[i] = propagate_mode(hom, wd, wv, i, step.eta0[i], step.etad0[i], step.qs)


@njit(cache=True)
def trial_step(st, cache, slot, w):
    """The trial step (before it is accepted) as `dense` reads it."""
    nb = cache.nodes.shape[0]
    nc = st.F.shape[0]
    Fs = np.empty((nb, nc, 2))
    Fs[0] = st.F
    for b in range(1, nb):
        for r in range(2 * nc):
            Fs[b, r // 2, r % 2] = w.X[(b - 1) * 2 * nc + r]
    return StepData(st.y, st.eta, st.etad, st.clock[0], Fs, w.qdat, cache.T[slot], w.motion, w.rate[0])


@njit(cache=True)
def dense_state(st, solid, model, t_out, out):
    """The state at t_out inside the last accepted step [t0, t] (`dense`), or its end."""
    t0, t1 = st.clock[1], st.clock[0]
    tau = t_out - t0
    if t1 - t0 <= 0.0 or tau >= t1 - t0:
        out.y[:] = st.y
        out.eta[:] = st.eta
        out.etad[:] = st.etad
        out.F[:, :] = st.F
        return
    dense(StepData(st.y0, st.eta0, st.etad0, t0, st.Fs, st.qs, st.Ts, st.step_motion, st.clock[3]), solid, model, tau, out)
