"""The one compiled coupled-step core (Sec. II C, Appendices A and B), shared by every coupled
solver. A step: its size from the step policy (constant, or (B1): `step_level`); the Newmark
predictor at the contacts (A1)-(A2); the interface iteration to (A4) (`interface_solve`: contact
motion by (A3), the granules' RK4), by the fixed point F <- G(F) or by Newton (Assumption 3);
accept by (A2). The solid runs on all its modes (`advance_modal`; a rigid solid has none);
larger solids use `coupling.sparse`. docs/coupling.md ("One step") describes the step."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..granular.bundles import InterfaceForces, Motion, interface_buffers, motion_buffers
from ..granular.contact import friction_eigenvalue, friction_map_slope
from ..granular.kernels import friction_rate, interface_forces, moved_beyond, rk4_substepped
from ..guard.jit import njit

# step policies and statuses
POLICY_CONSTANT, POLICY_B1 = 0, 1
DONE, REBUILD, LOG_FULL, NO_CONVERGENCE, NON_FINITE, BALANCE_LOST = 0, 1, 2, 3, 4, 5
CONVERGED = 0


class CoupledConfig(NamedTuple):
    """How the core steps. Times in seconds; ticks are dt0 / 2^H."""

    dt0: float
    halvings: int  # H: the smallest step is dt0 / 2^H
    policy: int  # POLICY_CONSTANT or POLICY_B1
    lambda_max: float  # (B1): halve until max |lambda| <= this
    newton: bool  # interface iteration: Newton (True) or the paper's fixed point (False)
    abstol: float  # (A4) [N]
    reltol: float  # (A4)
    max_iterations: int
    retry: bool  # a failed step is retried at half the step (for the rest of the output interval)
    max_disp: float  # a granule farther than this from the neighbour list's reference: rebuild


class ContactFrame(NamedTuple):
    """Each solid contact's unit tangent t = k x n (nc, 2), whether the point can move
    tangentially (the beam's cannot), and whether the points cannot move at all (a rigid solid:
    the forces do not feed back, so one evaluation per step is exact)."""

    tangent: np.ndarray
    has_tangent: np.ndarray
    fixed: bool


class ModalSolid(NamedTuple):
    """The solid as its contacts see it: squared natural frequencies w2 (nm,) and the contact
    modal matrix P = B Phi (2nc, nm)."""

    w2: np.ndarray
    P: np.ndarray
    frame: ContactFrame


class StepCache(NamedTuple):
    """Per halving level n (h = dt0 / 2^n), computed on first use: D_n (nm,), C_n (2nc, 2nc) and
    the tangential compliance c_t of (A8) per contact."""

    ready: np.ndarray  # (H+1,) bool
    D: np.ndarray  # (H+1, nm)
    C: np.ndarray  # (H+1, 2nc, 2nc)
    ct: np.ndarray  # (H+1, nc)


# the clock of the Newmark step loop (one record: st.clock[0].t, ...)
STEP_CLOCK = np.dtype([
    ("t", np.float64),  # the current time
    ("ticks", np.int64),  # ... in ticks of dt0 / 2^H, so that steps land exactly on the outputs
    ("level", np.int64),  # the halving level of the last accepted step
    ("forced", np.int64),  # the smallest level allowed (raised after a failed step)
])


def new_clock() -> np.ndarray:
    return np.zeros(1, STEP_CLOCK)


def upgraded_state(arrays: dict) -> dict:
    """A checkpoint's `CoupledState` arrays in today's layout: one written before the clock was a
    record ([t] and [ticks, level, forced level]) is translated; the values are the same."""
    if "st:ticks" not in arrays:
        return arrays
    out = {k: v for k, v in arrays.items() if k not in ("st:clock", "st:ticks")}
    clock = new_clock()
    ticks = np.asarray(arrays["st:ticks"], np.int64)
    clock[0]["t"] = float(np.asarray(arrays["st:clock"], float)[0])
    clock[0]["ticks"], clock[0]["level"], clock[0]["forced"] = int(ticks[0]), int(ticks[1]), int(ticks[2])
    out["st:clock"] = clock
    return out


class CoupledState(NamedTuple):
    """Everything that evolves: the granular state y, the modal state (eta, eta', eta''), the
    interface forces F on the solid (nc, 2), the contacts' motion (u, v, a flat, 2nc), |N| and the
    relative tangential velocity at the last accepted step, and the clock (a STEP_CLOCK record)."""

    y: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    etaa: np.ndarray
    F: np.ndarray
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    normal: np.ndarray
    vrel: np.ndarray
    clock: np.ndarray


class StepLog(NamedTuple):
    """Per accepted step: end time, size, iterations, |lambda| (A9) at each contact."""

    t: np.ndarray
    h: np.ndarray
    iterations: np.ndarray
    lam: np.ndarray  # (cap, nc)


LOG_CAPACITY = 65536  # steps per compiled call at most


def step_log(nc: int) -> StepLog:
    """An empty per-step log of LOG_CAPACITY steps for nc contacts (the compiled loops fill it)."""
    return StepLog(t=np.zeros(LOG_CAPACITY), h=np.zeros(LOG_CAPACITY), iterations=np.zeros(LOG_CAPACITY, np.int64),
                   lam=np.zeros((LOG_CAPACITY, nc)))


class Prediction(NamedTuple):
    """The contacts' motion at the step's start (u, v, a, flat 2nc) and their predicted
    acceleration at its end without interface forces (a_pred)."""

    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    a_pred: np.ndarray


class IterWork(NamedTuple):
    """Scratch of `interface_solve`."""

    ytr: np.ndarray
    rk4: np.ndarray  # (5, len(y))
    motion: Motion  # (nc, 2) arrays: u0, v0, average acceleration
    u1: np.ndarray  # (nc, 2)
    v1: np.ndarray
    a1: np.ndarray  # (2nc,)
    F_start: np.ndarray  # (nc, 2)
    J: np.ndarray  # (2nc, 2nc)
    r: np.ndarray  # (2nc,)
    iface: InterfaceForces


# ---------------------------------------------------------------- copies


@njit(cache=True)
def copy1(dst, src):
    """dst[:] = src for 1-d arrays of one length, as a loop: numba's slice assignment compiles
    a broadcast and a formatted shape error at every use, a large part of the kernels' compile
    time (docs/performance.md)."""
    for k in range(dst.shape[0]):
        dst[k] = src[k]


@njit(cache=True)
def copy2(dst, src):
    """dst[:, :] = src for 2-d arrays of one shape, as loops (`copy1`)."""
    for k in range(dst.shape[0]):
        for m in range(dst.shape[1]):
            dst[k, m] = src[k, m]


# ---------------------------------------------------------------- small dense systems


@njit(cache=True)
def lu_factor(A, n, piv):
    """LU factorisation with partial pivoting of the leading n x n block of A, in place (the
    interface systems are small: no allocation, no LAPACK call). False if A is singular."""
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        piv[k] = p
        if big == 0.0:
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        inv = 1.0 / A[k, k]
        for i in range(k + 1, n):
            f = A[i, k] * inv
            A[i, k] = f
            if f != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= f * A[k, j]
    return True


@njit(cache=True)
def lu_solve(A, n, piv, b):
    """Solve (LU from `lu_factor`) x = b in place for the leading n entries of b."""
    for k in range(n):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(n):
        acc = b[i]
        for j in range(i):
            acc -= A[i, j] * b[j]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


# ---------------------------------------------------------------- the interface iteration


@njit(cache=True)
def local_friction_root(muN, k_s, vt, beta, sj):
    """The root s of g(s) = s - muN tanh(k_s (vt - beta (s - sj))) in [-muN, muN] (g increases in
    s): the tangential force that the contact's local friction map (A6) holds fixed, with beta the
    tangential velocity response to the force (A8). Safeguarded Newton on a bracket."""
    lo = -muN
    hi = muN
    s = 0.0
    for _ in range(100):
        th = math.tanh(k_s * (vt - beta * (s - sj)))
        g = s - muN * th
        if g > 0.0:
            hi = s
        else:
            lo = s
        s_new = s - g / (1.0 + muN * k_s * beta * (1.0 - th * th))
        if s_new <= lo or s_new >= hi:
            s_new = 0.5 * (lo + hi)
        if abs(s_new - s) <= 1e-14 * muN:
            return s_new
        s = s_new
    return s


@njit(cache=True, inline="always")
def tangential_compliance(C, c, tx, ty):
    """t' C_cc t: the tangential component of contact c's response C (2nc, 2nc) to its own force."""
    return tx * (C[2 * c, 2 * c] * tx + C[2 * c, 2 * c + 1] * ty) + ty * (C[2 * c + 1, 2 * c] * tx + C[2 * c + 1, 2 * c + 1] * ty)


@njit(cache=True)
def stiff_friction_root(fx, fy, tx, ty, s_prev, normal, vrel, beta, law):
    """The force (fx, fy) with its tangential part from the exact local root (`local_friction_root`)
    where the contact's local friction map is not contractive (its steepest slope mu k_s |N| beta
    exceeds 1, the paper's |lambda| > 1): Newton's linear model overshoots the saturating tanh
    there. beta: the tangential velocity's response to the tangential force; s_prev: the
    tangential force before the Newton update."""
    if friction_map_slope(law.mu, law.k_s, normal, 0.0, beta) <= 1.0:
        return fx, fy
    root = local_friction_root(law.mu * normal, law.k_s, vrel, beta, s_prev)
    s_now = fx * tx + fy * ty
    return fx + (root - s_now) * tx, fy + (root - s_now) * ty


@njit(cache=True)
def _newton_update(F, C, h, iface, w, tangent, has_tangent, law):
    """F <- F + dF with (I - J) dF = G - F, J = Du (h^2/4) C + Dw (h/2) C block-row by contact;
    then the exact local root for stiff friction (`stiff_friction_root`, beta = h c_t / 2)."""
    nc = F.shape[0]
    m2 = 2 * nc
    Du, Dw, G = iface.Du, iface.Dw, iface.F
    J = w.J
    for r in range(m2):
        c = r // 2
        d = r % 2
        for q in range(m2):
            J[r, q] = -(Du[c, d, 0] * C[2 * c, q] + Du[c, d, 1] * C[2 * c + 1, q]) * 0.25 * h * h \
                - (Dw[c, d, 0] * C[2 * c, q] + Dw[c, d, 1] * C[2 * c + 1, q]) * 0.5 * h
        J[r, r] += 1.0
        w.r[r] = G[c, d] - F[c, d]
    dF = np.linalg.solve(J, w.r)
    for c in range(nc):
        sj = F[c, 0] * tangent[c, 0] + F[c, 1] * tangent[c, 1]
        F[c, 0] += dF[2 * c]
        F[c, 1] += dF[2 * c + 1]
        if iface.normal[c] <= 0.0 or not has_tangent[c]:
            continue
        tx, ty = tangent[c, 0], tangent[c, 1]
        beta = 0.5 * h * tangential_compliance(C, c, tx, ty)
        F[c, 0], F[c, 1] = stiff_friction_root(F[c, 0], F[c, 1], tx, ty, sj, iface.normal[c], iface.vrel[c], beta, law)


@njit(cache=True)
def interface_map(y, t, h, model, pred, C, F, rate, w, derivatives):
    """The nonlinear map F -> G(F) of Appendix A, steps 2-5, whose fixed point is the step's
    interface forces: the contacts' acceleration at s+1 under F (A2), their motion inside the
    step (A3), RK4 for the granules under it, and the forces at s+1 (eqs. 2, 5). Leaves the
    granular state at t + h in w.ytr and G(F) with |N|, v_t (and, with `derivatives`, dG/du and
    dG/dw) in w.iface. Returns False if the granular state stopped being finite."""
    nc = F.shape[0]
    mo = w.motion
    for r in range(2 * nc):
        acc = pred.a_pred[r]
        for q in range(2 * nc):
            acc += C[r, q] * F[q // 2, q % 2]
        w.a1[r] = acc
        c = r // 2
        d = r % 2
        ab = 0.5 * (pred.a[r] + acc)
        mo.u0[c, d] = pred.u[r]
        mo.v0[c, d] = pred.v[r]
        mo.a[c, d] = ab
        w.u1[c, d] = pred.u[r] + pred.v[r] * h + 0.5 * ab * h * h
        w.v1[c, d] = pred.v[r] + ab * h
    copy1(w.ytr, y)
    if rk4_substepped(w.ytr, t, h, model, mo, rate, w.rk4) < 0:
        return False
    interface_forces(w.ytr, model, w.u1, w.v1, w.iface, derivatives)
    return True


@njit(cache=True)
def interface_solve(y, t, h, model, pred, C, F, cfg, frame, w):
    """Step 6 of Appendix A for one step of size h from (y, t): iterate the interface forces F
    (nc, 2; in: the guess, out: the converged forces) until (A4) holds, by the fixed point
    F <- G(F) or by Newton. On success w.ytr holds the granular state at t + h and w.iface the
    contact state there. Returns (status, iterations); on failure F is left at its guess."""
    nc = F.shape[0]
    copy2(w.F_start, F)
    for c in range(nc):
        for d in range(2):
            w.motion.u0[c, d] = pred.u[2 * c + d]
    rate = friction_rate(y, model, w.motion)  # stiff friction: RK4 sub-steps
    for it in range(1, cfg.max_iterations + 1):
        if not interface_map(y, t, h, model, pred, C, F, rate, w, cfg.newton):
            copy2(F, w.F_start)
            return NON_FINITE, it
        G = w.iface.F
        if frame.fixed:  # the points do not move: G does not depend on F
            copy2(F, G)
            return CONVERGED, it
        ok = True
        for c in range(nc):
            for d in range(2):
                if abs(G[c, d] - F[c, d]) > cfg.abstol + cfg.reltol * abs(F[c, d]):
                    ok = False
        if ok or not cfg.newton:  # (A4) met, or the paper's fixed point F <- G(F)
            copy2(F, G)
            if ok:
                return CONVERGED, it
            continue
        _newton_update(F, C, h, w.iface, w, frame.tangent, frame.has_tangent, model.law)
    copy2(F, w.F_start)
    return NO_CONVERGENCE, cfg.max_iterations


# ---------------------------------------------------------------- the step policy


@njit(cache=True)
def ensure_level(cache, solid, dt0, n):
    """D, C and c_t of halving level n (h = dt0 / 2^n), computed once."""
    if cache.ready[n]:
        return
    h = dt0 / 2.0**n
    w2, P = solid.w2, solid.P
    nm = w2.shape[0]
    m2 = P.shape[0]
    D = cache.D[n]
    for i in range(nm):
        D[i] = 1.0 / (1.0 + 0.25 * w2[i] * h * h)
    C = cache.C[n]
    for a in range(m2):
        for b in range(a, m2):
            acc = 0.0
            for i in range(nm):
                acc += P[a, i] * D[i] * P[b, i]
            C[a, b] = acc
            C[b, a] = acc
    for c in range(m2 // 2):
        has_t = solid.frame.has_tangent[c]
        cache.ct[n, c] = tangential_compliance(C, c, solid.frame.tangent[c, 0], solid.frame.tangent[c, 1]) if has_t else 0.0
    cache.ready[n] = True


@njit(cache=True)
def eigenvalues_at(st, law, ct_n, h, out):
    """|lambda_k| of (A9) at every contact for a step h, from |N| and v_t of the last accepted
    step; returns the largest."""
    top = 0.0
    for c in range(out.shape[0]):
        out[c] = friction_eigenvalue(law.mu, law.k_s, st.normal[c], st.vrel[c], h, ct_n[c])
        top = max(top, out[c])
    return top


@njit(cache=True)
def step_level(st, law, cache, solid, cfg, ticks_to_output, lam):
    """The halving level of the next step. (B1): the smallest n with max |lambda(dt0 / 2^n)| <=
    lambda_max, one common step for all contacts; a constant policy keeps dt0. Either way at least
    the forced level (after a failed step), and a longer step only where the clock lines up with
    it, never past the next output. Fills `lam` at the chosen step. Returns -1 if (B1) cannot be
    met within the allowed halvings."""
    H = cfg.halvings
    clock = st.clock[0]
    n = clock.forced
    if cfg.policy == POLICY_B1:
        while True:
            ensure_level(cache, solid, cfg.dt0, n)
            if eigenvalues_at(st, law, cache.ct[n], cfg.dt0 / 2.0**n, lam) <= cfg.lambda_max:
                break
            if n == H:
                return -1
            n += 1
    while n < H and (clock.ticks % 2 ** (H - n) != 0 or 2 ** (H - n) > ticks_to_output):
        n += 1
    ensure_level(cache, solid, cfg.dt0, n)
    eigenvalues_at(st, law, cache.ct[n], cfg.dt0 / 2.0**n, lam)
    return n


# ---------------------------------------------------------------- the modal step loop


@njit(cache=True)
def modal_predictor(st, solid, D, h, dvec, a_pred):
    """(A2) without interface forces, mode by mode: dvec = -D w^2 (eta + eta' h + eta'' h^2/4), the
    modal accelerations at s+1, and a_pred = P dvec at the contacts."""
    eta, etad, etaa, w2 = st.eta, st.etad, st.etaa, solid.w2
    for i in range(eta.shape[0]):
        dvec[i] = -D[i] * w2[i] * (eta[i] + etad[i] * h + 0.25 * h * h * etaa[i])
    if eta.shape[0]:
        copy1(a_pred, np.dot(solid.P, dvec))
    else:
        a_pred[:] = 0.0


@njit(cache=True)
def modal_accept(st, solid, D, h, f, dvec):
    """Step 7 / (A2) in modal coordinates with the converged forces f (flat 2nc): eta'' at s+1 =
    dvec + D P' f, then the average-acceleration update."""
    eta, etad, etaa = st.eta, st.etad, st.etaa
    if eta.shape[0] == 0:
        return
    g = np.dot(f, solid.P)  # P' f
    for i in range(eta.shape[0]):
        an = dvec[i] + D[i] * g[i]
        aa = 0.5 * (etaa[i] + an)
        eta[i] += etad[i] * h + 0.5 * aa * h * h
        etad[i] += aa * h
        etaa[i] = an


@njit(cache=True)
def contact_accept(st, C, h, a_pred, f):
    """The contacts' motion after the step by the same algebra as the modes, (A2) (it stays B Phi
    eta to round-off): a = a_pred + C f, then the average-acceleration update."""
    m2 = f.shape[0]
    for r in range(m2):
        acc = a_pred[r]
        for q in range(m2):
            acc += C[r, q] * f[q]
        ab = 0.5 * (st.a[r] + acc)
        st.u[r] += st.v[r] * h + 0.5 * ab * h * h
        st.v[r] += ab * h
        st.a[r] = acc


@njit(cache=True)
def advance_modal(st, model, ref_pos, solid, cache, cfg, target, log):
    """Accepted coupled steps until the clock reaches tick `target` (an output time). Returns
    (status, steps logged): DONE; REBUILD (a granule moved far: rebuild the neighbour list and
    call again); LOG_FULL (flush the log and call again); NO_CONVERGENCE or NON_FINITE (the
    state is left at the last accepted step)."""
    H = cfg.halvings
    nm = st.eta.shape[0]
    nc = st.F.shape[0]
    n = model.granules.radius.shape[0]
    w = iter_work(st.y, nc)
    dvec = np.empty(nm)
    f = np.empty(2 * nc)
    pred = Prediction(st.u, st.v, st.a, np.empty(2 * nc))
    lam = np.empty(nc)
    lim2 = cfg.max_disp * cfg.max_disp
    clock = st.clock[0]
    k = 0
    while clock.ticks < target:
        if k >= log.t.shape[0]:
            return LOG_FULL, k
        level = step_level(st, model.law, cache, solid, cfg, target - clock.ticks, lam)
        if level < 0:
            return NO_CONVERGENCE, k
        h = cfg.dt0 / 2.0**level
        D = cache.D[level]
        modal_predictor(st, solid, D, h, dvec, pred.a_pred)
        status, its = interface_solve(st.y, clock.t, h, model, pred, cache.C[level], st.F, cfg, solid.frame, w)
        if status != CONVERGED:
            if cfg.retry and clock.forced < H:
                clock.forced += 1  # retry at half the step (the state is untouched)
                continue
            return NO_CONVERGENCE if status == NO_CONVERGENCE else NON_FINITE, k
        for r in range(2 * nc):
            f[r] = st.F[r // 2, r % 2]
        modal_accept(st, solid, D, h, f, dvec)
        contact_accept(st, cache.C[level], h, pred.a_pred, f)
        copy1(st.y, w.ytr)
        copy1(st.normal, w.iface.normal)
        copy1(st.vrel, w.iface.vrel)
        clock.t += h
        clock.ticks += 2 ** (H - level)
        clock.level = level
        log.t[k] = clock.t
        log.h[k] = h
        log.iterations[k] = its
        copy1(log.lam[k], lam)
        k += 1
        if moved_beyond(st.y, n, ref_pos, lim2):
            return REBUILD, k
    return DONE, k


@njit(cache=True)
def iter_work(y, nc):
    """Scratch arrays of `interface_solve` for nc contacts and a state like y."""
    return IterWork(ytr=np.empty_like(y), rk4=np.empty((5, y.shape[0])), motion=motion_buffers(nc), u1=np.zeros((nc, 2)),
                    v1=np.zeros((nc, 2)), a1=np.zeros(2 * nc), F_start=np.zeros((nc, 2)), J=np.zeros((2 * nc, 2 * nc)),
                    r=np.zeros(2 * nc), iface=interface_buffers(nc))
