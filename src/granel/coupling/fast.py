"""granel's fast coupled solver (`--solver fast`, the default).

Same time discretisation as the paper's algorithm (Newmark average acceleration for the solid,
the constant-average-acceleration interpolation (A3) of the contact motion, RK4 for the granules,
interface forces at the end of the step), solved differently:

* The solid runs in mass-normalised modal coordinates with *all* modes: Newmark is then a
  scalar recursion per mode, exactly the full Newmark (to round-off) at a cost linear in the
  number of modes; the contact points' response to interface forces over one step is the small
  compliance matrix C = P D P' (P = B Phi, D = 1 / (1 + w^2 dt^2 / 4)).
* The interface forces are found by Newton iterations on F = G(F) with the analytic Jacobian of
  the contact laws at the contact points (the granules' sensitivity neglected, as in the paper's
  Assumption 3), instead of the fixed-point iteration. This converges whatever the friction
  eigenvalue (A9), so the step no longer has to be halved to keep |lambda| <= 1/2.
* The whole step loop runs compiled (numba) between output times.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from pathlib import Path

import numpy as np
from numba import njit

from ..granular import kernels
from ..solid.modal import DENSE_LIMIT, Modes, modal_analysis


# ---------------------------------------------------------------- modes with an on-disk cache


def cache_dir() -> Path:
    return Path(os.environ.get("GRANEL_CACHE", Path.home() / ".cache" / "granel"))


def all_modes(model) -> Modes:
    """All modes of the solid, cached on disk by a hash of M and K."""
    h = hashlib.sha256()
    for A in (model.M, model.K):
        A = A.tocsr()
        A.sort_indices()
        for arr in (A.indptr, A.indices, A.data):
            h.update(np.ascontiguousarray(arr).tobytes())
    key = h.hexdigest()[:20]
    path = cache_dir() / f"modes-{model.kind}-{model.ndof}-{key}.npz"
    if path.exists():
        try:
            with np.load(path) as z:
                return Modes(z["omega"], z["shapes"])
        except (OSError, ValueError, KeyError):
            pass
    modes = modal_analysis(model, None)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            np.savez(fh, omega=modes.omega, shapes=modes.shapes)
        os.replace(tmp, path)
    except OSError:
        pass
    return modes


# ---------------------------------------------------------------- compiled kernels


@njit(cache=True)
def contact_forces_jacobian(y, n, radius, mu, k_s, sg, sp, sn, sA, sG, u, w):
    """Forces on the solid at the contact points (nc, 2), |N|, v_t, and the 2x2 derivatives of
    each force with respect to that contact point's displacement (Du) and velocity (Dw)."""
    nc = sg.shape[0]
    F = np.zeros((nc, 2))
    normal = np.zeros(nc)
    vrel = np.zeros(nc)
    Du = np.zeros((nc, 2, 2))
    Dw = np.zeros((nc, 2, 2))
    V = 3 * n
    OM = 5 * n
    for c in range(nc):
        i = sg[c]
        nx, ny = sn[c, 0], sn[c, 1]
        tx, ty = -ny, nx
        delta = kernels.point_overlap(y, i, c, radius, sp, sn, u[c, 0], u[c, 1])
        rvx = y[V + 2 * i] - w[c, 0]
        rvy = y[V + 2 * i + 1] - w[c, 1]
        vt = rvx * tx + rvy * ty + radius[i] * y[OM + i]
        vrel[c] = vt
        if delta <= 0.0:
            continue
        dd = rvx * nx + rvy * ny
        d25 = math.sqrt(math.sqrt(delta))
        fn = sA[c] * delta * math.sqrt(delta) + sG[c] * d25 * dd
        th = math.tanh(k_s * vt)
        ft = -mu * abs(fn) * th
        F[c, 0] = fn * nx - ft * tx
        F[c, 1] = fn * ny - ft * ty
        normal[c] = abs(fn)
        sgn = 1.0 if fn >= 0 else -1.0
        # d fn / d u = -(1.5 A delta^0.5 + 0.25 G delta^-0.75 ddelta) n ; d fn / d w = -G delta^0.25 n
        a_u = -(1.5 * sA[c] * math.sqrt(delta) + 0.25 * sG[c] * dd / (d25 * d25 * d25))
        a_w = -sG[c] * d25
        sech2 = 1.0 - th * th
        for j in range(2):
            nj = nx if j == 0 else ny
            tj = tx if j == 0 else ty
            dfn_u = a_u * nj
            dfn_w = a_w * nj
            dft_u = -mu * sgn * th * dfn_u
            dft_w = -mu * sgn * th * dfn_w + mu * abs(fn) * k_s * sech2 * tj
            Du[c, 0, j] = nx * dfn_u - tx * dft_u
            Du[c, 1, j] = ny * dfn_u - ty * dft_u
            Dw[c, 0, j] = nx * dfn_w - tx * dft_w
            Dw[c, 1, j] = ny * dfn_w - ty * dft_w
    return F, normal, vrel, Du, Dw


@njit(cache=True)
def _local_friction_root(muN, k_s, vt, beta, sj):
    """Root s of g(s) = s - muN tanh(k_s (vt - beta (s - sj))), increasing in s, in [-muN, muN]."""
    lo = -muN
    hi = muN
    s = 0.5 * (lo + hi)
    for _ in range(100):
        arg = k_s * (vt - beta * (s - sj))
        th = math.tanh(arg)
        g = s - muN * th
        if g > 0.0:
            hi = s
        else:
            lo = s
        dg = 1.0 + muN * k_s * beta * (1.0 - th * th)
        s_new = s - g / dg
        if s_new <= lo or s_new >= hi:
            s_new = 0.5 * (lo + hi)
        if abs(s_new - s) <= 1e-14 * muN:
            return s_new
        s = s_new
    return s


@njit(cache=True, fastmath=True)
def _matvec(A, x, out):
    for r in range(A.shape[0]):
        acc = 0.0
        for i in range(A.shape[1]):
            acc += A[r, i] * x[i]
        out[r] = acc


@njit(cache=True)
def fast_advance(
    y, t, dt, nsteps, n, ref_pos, max_disp,
    radius, mass, inertia, mu, k_s,
    pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, sG,
    eg, edir, ekind, epar, eoff, tab_t, tab_v,
    w2, P, eta, etad, etaa, F, abstol, reltol, max_iter, ct,
    out_iters, out_lam, out_normal, out_vrel,
):
    """Advance the coupled system by up to nsteps steps of size dt. Returns (steps done, status):
    status 0 ok, 1 neighbour list must be rebuilt, 2 no convergence, 3 the trial state was not
    finite; on 2 and 3 the state is left at the last accepted step.

    Per step the modal work is two (2nc x nmodes) products: Q z for the Newmark predictor at the
    contacts (Q = -P D W^2, z = eta + eta' dt + eta'' dt^2 / 4) and P' F for the accepted
    accelerations; the contact motion itself is advanced with the same (A2)-(A3) algebra."""
    nm = w2.shape[0]
    nc = sg.shape[0]
    m2 = 2 * nc
    D = np.empty(nm)
    for i in range(nm):
        D[i] = 1.0 / (1.0 + 0.25 * w2[i] * dt * dt)
    C = np.zeros((m2, m2))
    for a in range(m2):
        for b in range(a, m2):
            acc = 0.0
            for i in range(nm):
                acc += P[a, i] * D[i] * P[b, i]
            C[a, b] = acc
            C[b, a] = acc
    Q = np.empty((m2, nm))
    for a in range(m2):
        for i in range(nm):
            Q[a, i] = -P[a, i] * D[i] * w2[i]
    Pt = np.ascontiguousarray(P.T)
    z = np.empty(nm)
    g = np.empty(nm)
    ytr = np.empty_like(y)
    # contact motion at the current state: u = P eta, v = P eta', a = P eta''
    u0f = np.empty(m2)
    v0f = np.empty(m2)
    a0f = np.empty(m2)
    _matvec(P, eta, u0f)
    _matvec(P, etad, v0f)
    _matvec(P, etaa, a0f)
    bapf = np.empty(m2)
    u0 = np.zeros((nc, 2))
    v0 = np.zeros((nc, 2))
    abar = np.zeros((nc, 2))
    u1 = np.zeros((nc, 2))
    v1 = np.zeros((nc, 2))
    a1f = np.empty(m2)
    Jm = np.zeros((m2, m2))
    rhs = np.empty(m2)
    lim2 = max_disp * max_disp
    for s in range(nsteps):
        for i in range(nm):
            z[i] = eta[i] + etad[i] * dt + 0.25 * dt * dt * etaa[i]
        bapf[:] = np.dot(Q, z)
        for c in range(nc):
            for d in range(2):
                u0[c, d] = u0f[2 * c + d]
                v0[c, d] = v0f[2 * c + d]
        # stiff friction (large k_s): RK4 sub-steps for the granules inside the coupled step
        rate = kernels.friction_rate(y, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
                                     wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, u0)
        rate *= 1.5  # forces may grow within the step
        converged = False
        it = 0
        F_start = F.copy()
        normal = np.zeros(nc)
        vrel = np.zeros(nc)
        while it < max_iter:
            it += 1
            for r in range(m2):
                acc = bapf[r]
                for q in range(m2):
                    acc += C[r, q] * F[q // 2, q % 2]
                a1f[r] = acc
                c = r // 2
                d = r % 2
                abar[c, d] = 0.5 * (a0f[r] + acc)
                u1[c, d] = u0f[r] + v0f[r] * dt + 0.5 * abar[c, d] * dt * dt
                v1[c, d] = v0f[r] + abar[c, d] * dt
            ytr[:] = y
            kernels.rk4_substepped(ytr, t, dt, n, ref_pos, radius, mass, inertia, mu, k_s,
                                   pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
                                   sg, sp, sn, sA, sG, u0, v0, abar, eg, edir, ekind, epar, eoff, tab_t, tab_v, rate)
            G, normal, vrel, Du, Dw = contact_forces_jacobian(ytr, n, radius, mu, k_s, sg, sp, sn, sA, sG, u1, v1)
            ok = True
            for c in range(nc):
                for d in range(2):
                    if abs(G[c, d] - F[c, d]) > abstol + reltol * abs(F[c, d]):
                        ok = False
            if ok:
                for c in range(nc):
                    F[c, 0] = G[c, 0]
                    F[c, 1] = G[c, 1]
                converged = True
                break
            # Newton: (I - J) dF = G - F, J = Du (dt^2/4) C + Dw (dt/2) C (block rows per contact)
            for r in range(m2):
                c = r // 2
                d = r % 2
                for q in range(m2):
                    Jm[r, q] = -(Du[c, d, 0] * C[2 * c, q] + Du[c, d, 1] * C[2 * c + 1, q]) * 0.25 * dt * dt \
                        - (Dw[c, d, 0] * C[2 * c, q] + Dw[c, d, 1] * C[2 * c + 1, q]) * 0.5 * dt
                Jm[r, r] += 1.0
            for c in range(nc):
                rhs[2 * c] = G[c, 0] - F[c, 0]
                rhs[2 * c + 1] = G[c, 1] - F[c, 1]
            dF = np.linalg.solve(Jm, rhs)
            for c in range(nc):
                F[c, 0] += dF[2 * c]
                F[c, 1] += dF[2 * c + 1]
            # stiff friction: where the contact's local friction map is not contractive
            # (mu k_s |N| beta > 1, the paper's |lambda| > 1), Newton's linear model overshoots
            # the saturating tanh; there take the tangential force from the exact root of the
            # local map s = mu |N| tanh(k_s (v_t - beta (s - s_j))) (monotone, bracketed)
            for c in range(nc):
                if normal[c] <= 0.0:
                    continue
                tx = -sn[c, 1]
                ty = sn[c, 0]
                ctt = tx * (C[2 * c, 2 * c] * tx + C[2 * c, 2 * c + 1] * ty) + ty * (C[2 * c + 1, 2 * c] * tx + C[2 * c + 1, 2 * c + 1] * ty)
                beta = 0.5 * dt * ctt
                muN = mu * normal[c]
                if muN * k_s * beta <= 1.0:
                    continue
                sj = (F[c, 0] - dF[2 * c]) * tx + (F[c, 1] - dF[2 * c + 1]) * ty
                root = _local_friction_root(muN, k_s, vrel[c], beta, sj)
                snew = F[c, 0] * tx + F[c, 1] * ty
                F[c, 0] += (root - snew) * tx
                F[c, 1] += (root - snew) * ty
        finite = True
        for k in range(y.shape[0]):
            if not math.isfinite(ytr[k]):
                finite = False
                break
        if not converged or not finite:
            # leave the state at the last accepted step: the caller retries with a smaller step
            F[:, :] = F_start
            return s, 2 if not converged else 3
        # accept: modal Newmark with the converged forces
        for r in range(m2):
            rhs[r] = F[r // 2, r % 2]
        g[:] = np.dot(Pt, rhs)
        for i in range(nm):
            an = -w2[i] * D[i] * z[i] + D[i] * g[i]
            aa = 0.5 * (etaa[i] + an)
            eta[i] += etad[i] * dt + 0.5 * aa * dt * dt
            etad[i] += aa * dt
            etaa[i] = an
        # the contact motion follows by the same algebra (B applied to the modal update)
        for r in range(m2):
            acc = bapf[r]
            for q in range(m2):
                acc += C[r, q] * rhs[q]
            ab = 0.5 * (a0f[r] + acc)
            u0f[r] += v0f[r] * dt + 0.5 * ab * dt * dt
            v0f[r] += ab * dt
            a0f[r] = acc
        y[:] = ytr
        t += dt
        out_iters[s] = it
        for c in range(nc):
            out_lam[s, c] = 0.5 * mu * k_s * normal[c] * dt * ct[c] * (1.0 - math.tanh(k_s * vrel[c]) ** 2)
            out_normal[c] = normal[c]
            out_vrel[c] = vrel[c]
        for i in range(n):
            ddx = y[2 * i] - ref_pos[i, 0]
            ddy = y[2 * i + 1] - ref_pos[i, 1]
            if ddx * ddx + ddy * ddy > lim2:
                return s + 1, 1
    return nsteps, 0


# ---------------------------------------------------------------- driver


def simulate_fast(sc, progress=None, checkpoint=None, resume=None):
    """Run a scenario with an elastic solid by the fast solver; returns the result Dataset."""
    from .. import scenario as S
    from ..checkpoint import checkpoint_period, fingerprint, load_checkpoint, save_checkpoint
    from ..granular.system import GranularState, Stepper, build_neighbours
    from ..solid.build import build_solid
    from .coupled import ConvergenceError, _dataset, pack_records, unpack_records
    from .rigid import Recorder

    sim = sc.simulation
    system, g0, media = S.build_granular(sc, sc.base)
    stepper = Stepper(system)
    model = build_solid(sc, system)
    if model.ndof > DENSE_LIMIT:
        # all modes are out of reach: sparse-direct Newmark with the same Newton coupling
        from .coupled import simulate_sparse

        return simulate_sparse(sc, progress, checkpoint, resume, newton=True, model=model)
    modes = all_modes(model)
    B = model.contact_map()
    P = np.ascontiguousarray((B @ modes.shapes))
    w2 = modes.omega**2
    nm = len(w2)
    nc = len(system.solid_contacts)
    tangents = np.array([[-c.normal[1], c.normal[0]] for c in system.solid_contacts]).reshape(-1, 2)
    nrm = np.array([c.normal for c in system.solid_contacts]).reshape(-1, 2)
    dt = sim.dt
    # tangential compliance of (A8) for the lambda diagnostic: t' B S^-1 B' t
    D = 1.0 / (1.0 + 0.25 * w2 * dt * dt)
    C = (P * D) @ P.T
    has_t = np.array([c.dof_y >= 0 for c in model.contacts])
    ct = np.array([tangents[k] @ C[2 * k:2 * k + 2, 2 * k:2 * k + 2] @ tangents[k] if has_t[k] else 0.0 for k in range(nc)])
    eta, etad, etaa = np.zeros(nm), np.zeros(nm), np.zeros(nm)
    F = np.zeros((nc, 2))
    y = g0.y.copy()
    t = 0.0
    per = max(1, int(round(sim.output_every / dt)))
    nout = int(np.ceil(sim.duration / (per * dt) - 1e-9))
    solid_per = max(1, int(round(sim.solid_output_every / sim.output_every))) if sim.solid_output_every > 0 else 1
    rec = Recorder()
    steps: dict[str, list] = {"t": [], "dt": [], "iterations": [], "lambda": []}
    solid_rec: dict[str, list] = {"t": [], "eta": [], "eta_dot": []}
    fp = fingerprint(S.to_toml(sc) + "fast")
    out_iters = np.zeros(per, dtype=np.int64)
    out_lam = np.zeros((per, nc))
    out_normal = np.zeros(nc)
    out_vrel = np.zeros(nc)

    def snapshot():
        g = GranularState(y, t)
        u = (P @ eta).reshape(nc, 2)
        ek = 0.5 * float(etad @ etad)
        ep = 0.5 * float(eta @ (w2 * eta))
        rec.snapshot(stepper, g, ek + ep, u, energy_solid_kinetic=ek, energy_solid_potential=ep,
                     contact_force_normal=np.einsum("ij,ij->i", F, nrm), contact_force_tangential=np.einsum("ij,ij->i", F, tangents))

    def solid_snapshot():
        solid_rec["t"].append(t)
        solid_rec["eta"].append(eta.astype(np.float32))
        solid_rec["eta_dot"].append(etad.astype(np.float32))

    start = 0
    if resume is not None:
        arrays, recorded, times = load_checkpoint(resume, fp)
        y[:] = arrays["y"]
        eta[:], etad[:], etaa[:] = arrays["eta"], arrays["etad"], arrays["etaa"]
        F[:] = arrays["F"]
        t = float(arrays["t"])
        stepper.nl = build_neighbours(system, arrays["ref_pos"])
        unpack_records(recorded, times, rec, steps, solid_rec)
        start = int(arrays["k"])
    else:
        snapshot()
        solid_snapshot()
    ck_per = checkpoint_period(checkpoint, sim.checkpoint_every, per, dt)
    s_ = system
    ex = stepper.ex
    t_wall = time.perf_counter()
    H = sim.max_halvings
    for k in range(start, nout):
        # the interval [t, t + per dt] in ticks of dt / 2^H; a failed step halves the step for
        # the rest of the interval (Newton not converging or a non-finite trial state)
        level = 0
        ticks_left = per * 2**H
        while ticks_left > 0:
            h = dt / 2**level
            nsteps = ticks_left // 2 ** (H - level)
            if len(out_iters) < nsteps:
                out_iters = np.zeros(nsteps, dtype=np.int64)
                out_lam = np.zeros((nsteps, nc))
            nl = stepper.nl
            m, status = fast_advance(
                y, t, h, nsteps, s_.n, nl.ref_pos, 0.5 * s_.skin,
                s_.radius, s_.mass, s_.inertia, s_.law.mu, s_.law.k_s,
                nl.pi, nl.pj, nl.pA, nl.pG, nl.wg, nl.ww, nl.wA, nl.wG, s_.wall_p0, s_.wall_dir, s_.wall_len, s_.wall_n,
                s_.sg, s_.sp, s_.sn, s_.sA, s_.sG,
                ex.eg, ex.edir, ex.ekind, ex.epar, ex.eoff, ex.tab_t, ex.tab_v,
                w2, P, eta, etad, etaa, F, sim.abstol, sim.reltol, sim.max_iterations, ct * (h / dt),
                out_iters, out_lam, out_normal, out_vrel,
            )
            for j in range(m):
                steps["t"].append(t + (j + 1) * h)
                steps["dt"].append(h)
                steps["iterations"].append(int(out_iters[j]))
                steps["lambda"].append(out_lam[j].copy())
            t += m * h
            ticks_left -= m * 2 ** (H - level)
            if status in (2, 3):
                if level == H:
                    why = "Newton on the interface forces did not converge" if status == 2 else "the state became non-finite"
                    raise ConvergenceError(
                        f"t = {t:.6e} s: {why} even at dt = {h:.3e} s ({H} halvings of {dt:.3e} s); reduce "
                        "simulation.dt, raise simulation.max_halvings or simulation.max_iterations, or lower k_s")
                level += 1
                continue
            if status == 1:
                stepper.nl = build_neighbours(system, GranularState(y, t).pos.copy())
                stepper.rebuilds += 1
        snapshot()
        if (k + 1) % solid_per == 0:
            solid_snapshot()
        if progress is not None:
            progress(t)
        if ck_per and (k + 1) % ck_per == 0 and k + 1 < nout:
            save_checkpoint(checkpoint, fp, {"y": y, "eta": eta, "etad": etad, "etaa": etaa, "F": F, "t": t,
                                             "ref_pos": stepper.nl.ref_pos, "k": k + 1},
                            pack_records(rec, steps, solid_rec), rec.times)
    wall = time.perf_counter() - t_wall

    class _Prob:  # what _dataset reads
        pass

    prob = _Prob()
    prob.stepper = stepper
    ds = _dataset(sc, system, model, rec, steps, solid_rec, wall, prob, solver_name="fast", modes=modes)
    return ds
