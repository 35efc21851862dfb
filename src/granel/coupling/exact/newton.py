"""Newton on the exact integrator's interface equations X = G(X): the matrix I - dG/dX from the
contact law's derivatives (A5, A7) and each contact granule's own response, restricted to the
touching contacts and reused across steps while it contracts well; where a contact's friction is
stiff (its local map not contractive, the paper's |lambda| > 1, A6), its tangential forces come
from the root of its local friction model."""

from __future__ import annotations

import numpy as np

from ...granular.contact import friction_map_slope, tanh_friction
from ...guard.jit import njit
from .. import core
from .state import node_iface

# Newton's matrix serves later steps (a chord across steps) while their grid level is within
# REUSE_LEVELS of the one it was built at and the iteration contracts by REUSE_RATE or better
REUSE_LEVELS = 2
REUSE_RATE = 0.2


@njit(cache=True)
def jacobian_rows(M, rows, c, iface, Cu, Cw):
    """Contact c's two rows (at rows, rows + 1) of M = -dG/dX at fixed granules for one unknown
    node (A5): its forces move with the node's displacement (Du) and velocity (Dw), which move
    with each unknown force datum b >= 1 through Cu[b], Cw[b]."""
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
def granule_response(unknowns, newton, cache, slot, c, tangent, A):
    """(I - Dg) for contact c over its unknown nodes (2nn x 2nn): the contact granule feels the
    opposite of the force change, so at node j it has moved by -sum_b I2_jb dG_b / m and its
    contact velocity has changed by -sum_b M^-1 I1_jb dG_b (M^-1 = I/m + t t' R^2/I), which
    changes the forces by Dg dG. The granule's other contacts are left out."""
    nn = cache.nodes.shape[0] - 1
    tx, ty = tangent[c, 0], tangent[c, 1]
    im, sp = newton.inv_mass[c], newton.spin[c]
    Mi00, Mi01, Mi11 = im + sp * tx * tx, sp * tx * ty, im + sp * ty * ty
    for j in range(nn):
        iface = node_iface(unknowns, j)
        Du, Dw = iface.Du, iface.Dw
        for b in range(nn):
            i1, i2 = cache.I1[slot, j, 1 + b], cache.I2[slot, j, 1 + b]
            for d in range(2):
                g0 = Du[c, d, 0] * im * i2 + (Dw[c, d, 0] * Mi00 + Dw[c, d, 1] * Mi01) * i1
                g1 = Du[c, d, 1] * im * i2 + (Dw[c, d, 0] * Mi01 + Dw[c, d, 1] * Mi11) * i1
                A[2 * j + d, 2 * b] = (1.0 if (j == b and d == 0) else 0.0) - g0
                A[2 * j + d, 2 * b + 1] = (1.0 if (j == b and d == 1) else 0.0) - g1


@njit(cache=True)
def friction_residual(s, s0, vt0, normal, B, mu, ks, out):
    """The local friction model's residual s_j - mu N_j tanh(k_s vt_j(s)) (eq. 5), vt_j(s) =
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
    model holds fixed (A6): s_j = mu N_j tanh(k_s vt_j), vt_j = vt0_j - sum_b B_jb (s_b - s0_b);
    s comes in as the Newton update and leaves as the root (damped Newton, each s_j within
    +-mu N_j)."""
    nn = s.shape[0]
    mu, ks = law.mu, law.k_s
    trial = np.empty(2)
    rt = np.empty(2)
    norm = friction_residual(s, s0, vt0, normal, B, mu, ks, r)
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
            tn = friction_residual(trial[:nn], s0, vt0, normal, B, mu, ks, rt)
            if tn < norm or lam < 1e-6:
                break
            lam *= 0.5
        if tn >= norm:
            return
        core.copy1(s, trial[:nn])
        core.copy1(r[:nn], rt[:nn])
        norm = tn


@njit(cache=True)
def update_touching(work, nc, nn):
    """Mark the contacts touching at some unknown node; True if the set changed."""
    changed = False
    touching_now = work.newton.touching
    for c in range(nc):
        touching = False
        for j in range(nn):
            if node_iface(work.unknowns, j).normal[c] > 0.0:
                touching = True
        if touching != touching_now[c]:
            changed = True
        touching_now[c] = touching
    return changed


@njit(cache=True)
def newton_matrix(work, cache, slot, frame):
    """I - dG/dX on the touching contacts' unknowns, factorised (their indices in newton.index,
    their count in the trial record): dG/dX from the contact law's derivatives (`jacobian_rows`)
    and each contact granule's own response (`granule_response`), dG = (I - Dg)^-1 (dG at fixed
    granules); the full rows in newton.J (for the open contacts' columns). False if singular."""
    unknowns, newton = work.unknowns, work.newton
    nn = cache.nodes.shape[0] - 1
    m2 = work.nodes.u.shape[1]
    nc = m2 // 2
    n = nn * m2
    M, A, rows, idx, piv = newton.J, newton.response, newton.rows, newton.index, newton.pivots
    na = 0
    for j in range(nn):
        for c in range(nc):
            if newton.touching[c]:
                idx[na] = j * m2 + 2 * c
                idx[na + 1] = j * m2 + 2 * c + 1
                na += 2
    work.trial[0].touching = na
    for c in range(nc):
        if not newton.touching[c]:
            continue
        for j in range(nn):
            jacobian_rows(rows, 2 * j, c, node_iface(unknowns, j), cache.Cu[slot, j], cache.Cw[slot, j])
        granule_response(unknowns, newton, cache, slot, c, frame.tangent, A)
        if not core.lu_factor(A, 2 * nn, piv):
            return False
        Ai = newton.response_inv
        for i in range(2 * nn):  # A^-1, column by column
            for k in range(2 * nn):
                newton.column[k] = 1.0 if k == i else 0.0
            core.lu_solve(A, 2 * nn, piv, newton.column)
            for k in range(2 * nn):
                Ai[k, i] = newton.column[k]
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
            newton.matrix[a, b] = M[idx[a], idx[b]] + (1.0 if a == b else 0.0)
    return na == 0 or core.lu_factor(newton.matrix, np.int64(na), newton.pivots_touching)  # typed: one signature


@njit(cache=True)
def newton_step(work, cache, slot, frame, law):
    """X <- X + dX with (I - dG/dX) dX = G - X (`newton_matrix`, possibly from an earlier iterate
    or step). A contact open at every node exerts no force whatever X: its forces are set to
    zero, and the system is solved for the touching contacts only. Then, where a contact's
    friction is stiff, its tangential forces at all nodes come from the root of its local
    friction model (`local_friction_solve`)."""
    unknowns, newton, fr = work.unknowns, work.newton, work.friction
    X, G, dX = unknowns.X, unknowns.G, newton.dX
    nn = cache.nodes.shape[0] - 1
    m2 = work.nodes.u.shape[1]
    nc = m2 // 2
    n = nn * m2
    M, idx = newton.J, newton.index
    na = work.trial[0].touching
    for j in range(nn):
        for c in range(nc):
            for d in range(2):
                k = j * m2 + 2 * c + d
                dX[k] = 0.0 if newton.touching[c] else -X[k]
    for a in range(na):
        ra = idx[a]
        acc = G[ra] - X[ra]
        for q in range(n):
            if dX[q] != 0.0:
                acc -= M[ra, q] * dX[q]
        newton.rhs[a] = acc
    if na > 0:
        core.lu_solve(newton.matrix, na, newton.pivots_touching, newton.rhs)
        for a in range(na):
            dX[idx[a]] = newton.rhs[a]
    s, s0, vt0, N, B = fr.s, fr.s0, fr.vt0, fr.normal, fr.B
    for c in range(nc):
        tx, ty = frame.tangent[c, 0], frame.tangent[c, 1]
        stiff = False
        for j in range(nn):
            iface = node_iface(unknowns, j)
            k = j * m2 + 2 * c
            s0[j] = X[k] * tx + X[k + 1] * ty
            X[k] += dX[k]
            X[k + 1] += dX[k + 1]
            s[j] = X[k] * tx + X[k + 1] * ty
            vt0[j] = iface.vrel[c]
            N[j] = max(iface.normal[c], 0.0)
            for b in range(nn):
                B[j, b] = core.tangential_compliance(cache.Cw[slot, j, 1 + b], c, tx, ty) \
                    + (newton.inv_mass[c] + newton.spin[c]) * cache.I1[slot, j, 1 + b]
            if N[j] > 0.0 and friction_map_slope(law.mu, law.k_s, N[j], 0.0, B[j, j]) > 1.0:
                stiff = True
        if not stiff or not frame.has_tangent[c]:
            continue
        local_friction_solve(s, s0, vt0, N, B, law, fr.residual, fr.jacobian)
        for j in range(nn):
            k = j * m2 + 2 * c
            now = X[k] * tx + X[k + 1] * ty
            X[k] += (s[j] - now) * tx
            X[k + 1] += (s[j] - now) * ty
