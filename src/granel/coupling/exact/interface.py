"""The interface map of the exact integrator and its iteration: the unknowns X are the interface
forces at the force polynomial's nodes; X -> G(X) moves the contacts by the modes' exact response
to the polynomial, integrates the granules by RK4 under that motion and returns the contact law's
forces at the nodes (eqs. 2, 5); X = G(X) is solved by Newton (`newton`) or the fixed point,
with the convergence test (A4) per component."""

from __future__ import annotations

import numpy as np

from ...granular.kernels import friction_rate, friction_substeps, interface_forces, rhs, rk4_step
from ...guard.jit import njit
from ...solid.propagation import basis_values
from .. import core
from .newton import REUSE_LEVELS, REUSE_RATE, newton_matrix, newton_step, update_touching
from .state import node_iface


@njit(cache=True)
def motion_at_nodes(state, cache, slot, h, work):
    """For the unknowns X: the contacts' displacement and velocity at every unknown node (affine
    in X), and the motion the granules' RK4 sees: the polynomial through the exact displacements
    and velocities at the step's start and at every node (a cubic, or a quintic through the
    mid-step node too), so that the forces at the nodes are the ones the granules feel there."""
    nodes, X = work.nodes, work.unknowns.X
    m2 = state.u.shape[0]
    nb = cache.nodes.shape[0]
    nn = nb - 1
    for j in range(nn):
        Cu, Cw = cache.Cu[slot, j], cache.Cw[slot, j]
        for r in range(m2):
            u = nodes.u_free[j, r]
            v = nodes.w_free[j, r]
            for b in range(1, nb):
                for q in range(m2):
                    x = X[(b - 1) * m2 + q]
                    u += Cu[b, r, q] * x
                    v += Cw[b, r, q] * x
            nodes.u[j, r] = u
            nodes.w[j, r] = v
    e = nn - 1
    mo = nodes.motion
    for r in range(m2):
        c = r // 2
        d = r % 2
        u0, v0, u1, w1 = state.u[r], state.w[r], nodes.u[e, r], nodes.w[e, r]
        c2 = (3.0 * (u1 - u0) / h - 2.0 * v0 - w1) / h
        c3 = (2.0 * (u0 - u1) / h + v0 + w1) / (h * h)
        c4 = c5 = 0.0
        if nn == 2:
            # through the mid-step node too: add tau^2 (tau - h)^2 (al + be tau), which leaves the
            # ends alone and meets the exact displacement and velocity at h/2
            hh = 0.5 * h
            du = nodes.u[0, r] - (u0 + (v0 + (c2 + c3 * hh) * hh) * hh)
            dw = nodes.w[0, r] - (v0 + (2.0 * c2 + 3.0 * c3 * hh) * hh)
            be = 16.0 * dw / h**4
            al = 16.0 * du / h**4 - be * hh
            c2 += al * h * h
            c3 += be * h * h - 2.0 * h * al
            c4 = al - 2.0 * h * be
            c5 = be
        mo.u0[c, d] = u0
        mo.v0[c, d] = v0
        mo.a[c, d] = 2.0 * c2
        mo.j[c, d] = 6.0 * c3
        mo.d4[c, d] = 24.0 * c4
        mo.d5[c, d] = 120.0 * c5


@njit(cache=True)
def rk4_with_estimate(state, t, h, model, motion, rate, granular):
    """RK4 (sub-stepped where friction is stiff) from the step's start into granular.y, the first
    stage being the state's derivative (first same as last), the end derivative in
    granular.dy_end and the embedded third-order error h/6 (k4 - k5) summed over sub-steps in
    granular.err. False if the state stops being finite."""
    m = friction_substeps(rate, h)
    s = h / m
    core.copy1(granular.y, state.y)
    granular.err[:] = 0.0
    n = granular.y.shape[0]
    for k in range(m):
        if k == 0:
            core.copy1(granular.stages[0], state.dy)
        if not rk4_step(granular.y, t + k * s, s, model, motion, k * s, granular.stages, k == 0):
            return False
        rhs(t + (k + 1) * s, granular.y, granular.dy_end, model, motion, (k + 1) * s)
        k4 = granular.stages[3]
        for q in range(n):
            granular.err[q] += s / 6.0 * (k4[q] - granular.dy_end[q])
    return True


@njit(cache=True)
def force_map(state, t, h, model, cache, slot, rate, work, derivatives):
    """X -> G(X): the forces at the unknown nodes after RK4 of the granules under the contacts'
    motion that X implies. Fills the unknowns' G and contact-law buffers (with the law's
    derivatives if asked) and the granular scratch. False if the granular state stopped being
    finite."""
    motion_at_nodes(state, cache, slot, h, work)
    granular, unknowns, nodes = work.granular, work.unknowns, work.nodes
    if not rk4_with_estimate(state, t, h, model, nodes.motion, rate, granular):
        return False
    nc = state.F.shape[0]
    m2 = 2 * nc
    node_times = cache.nodes
    for j in range(node_times.shape[0] - 1):
        s = node_times[j + 1]
        yj = granular.y
        if s < 1.0:
            # the granules at an interior node: the cubic Hermite through the step's ends and their
            # derivatives (fourth order locally; the end derivative comes with the error estimate)
            h00, h10 = (2.0 * s - 3.0) * s * s + 1.0, ((s - 2.0) * s + 1.0) * s * h
            h01, h11 = (3.0 - 2.0 * s) * s * s, (s - 1.0) * s * s * h
            for q in range(granular.y_node.shape[0]):
                granular.y_node[q] = h00 * state.y[q] + h10 * state.dy[q] + h01 * granular.y[q] + h11 * granular.dy_end[q]
            yj = granular.y_node
        iface = node_iface(unknowns, j)
        interface_forces(yj, model, nodes.u[j].reshape(nc, 2), nodes.w[j].reshape(nc, 2), iface, derivatives)
        for r in range(m2):
            unknowns.G[j * m2 + r] = iface.F[r // 2, r % 2]
    return True


@njit(cache=True)
def predict(state, cache, h, X):
    """The unknowns' first guess: the last step's force polynomial continued into the new step
    (the current force where that step is much shorter than the new one, or at the start)."""
    node_times = cache.nodes
    nb = node_times.shape[0]
    m2 = state.u.shape[0]
    clock = state.clock[0]
    hp = clock.t - clock.t_start
    H, dH = np.empty(nb), np.empty(nb)
    for j in range(nb - 1):
        if hp <= 0.0 or h > 2.0 * hp:
            for r in range(m2):
                X[j * m2 + r] = state.F[r // 2, r % 2]
            continue
        basis_values(state.last.Ts, hp + node_times[j + 1] * h, H, dH)
        for r in range(m2):
            acc = 0.0
            for b in range(nb):
                acc += H[b] * state.last.Fs[b, r // 2, r % 2]
            X[j * m2 + r] = acc


@njit(cache=True)
def iteration_noise(state, work, nn, m2):
    """What the converged iteration leaves open in the step's energy ledger (13): the forces the
    granules felt (G) and the ones the solid takes (X) differ within the tolerance, and the
    difference works through the contacts' displacement over the step: sum |G - X| |u_j - u_0|."""
    total = 0.0
    G, X, u = work.unknowns.G, work.unknowns.X, work.nodes.u
    for j in range(nn):
        for r in range(m2):
            total += abs(G[j * m2 + r] - X[j * m2 + r]) * abs(u[j, r] - state.u[r])
    return total


@njit(cache=True)
def interface_solve(state, t, h, model, solid, cache, slot, cfg, work):
    """Iterate X = G(X) for one step of size h (Newton, or the fixed point). Returns (status,
    iterations); on success the work holds the end state."""
    nc = state.F.shape[0]
    m2 = 2 * nc
    nn = cache.nodes.shape[0] - 1
    n = nn * m2
    unknowns, newton, trial = work.unknowns, work.newton, work.trial[0]
    X, G = unknowns.X, unknowns.G
    predict(state, cache, h, X)
    mo = work.nodes.motion
    for c in range(nc):
        mo.u0[c, 0] = state.u[2 * c]
        mo.u0[c, 1] = state.u[2 * c + 1]
    rate = friction_rate(state.y, model, mo)
    trial.rate = rate
    gr = model.granules
    for c in range(nc):
        g = model.points.g[c]
        newton.inv_mass[c] = 1.0 / gr.mass[g]
        newton.spin[c] = gr.radius[g] ** 2 / gr.inertia[g]
    last = np.inf
    backtracks = 0
    for it in range(1, cfg.max_iterations + 1):
        # the first iterate's RK4 sub-steps where friction is stiff; later iterates take one RK4
        # step, whose embedded error the controller reads (sub-steps in every iterate hid the
        # friction's error from it: docs/performance.md, "RK4 sub-steps in every iterate")
        substep_rate = rate if it == 1 else 0.0
        if not force_map(state, t, h, model, cache, slot, substep_rate, work, cfg.newton):
            return core.NON_FINITE, it
        if solid.frame.fixed:
            core.copy1(X, G)
            return core.CONVERGED, it
        ok = True
        worst = 0.0  # the largest residual against its tolerance, (A4)
        for r in range(n):
            ratio = abs(G[r] - X[r]) / (cfg.abstol + cfg.reltol * abs(X[r]))
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
                X[r] = 0.5 * (X[r] + unknowns.X_prev[r])
            continue
        backtracks = 0
        contraction = worst / last if it > 1 else 0.0
        last = worst
        if ok or not cfg.newton:
            if ok:
                trial.iteration_noise = iteration_noise(state, work, nn, m2)
            core.copy1(X, G)
            if ok:
                trial.iterations = it
                return core.CONVERGED, it
            continue
        # a chord Newton: the matrix serves the step's later iterates and the next steps near its
        # size while it contracts well, unless a contact opened or closed
        changed = update_touching(work, nc, nn)
        stale = abs(trial.matrix_level - slot) > REUSE_LEVELS or slot == cache.ready.shape[0] - 1 or trial.matrix_level < 0
        if changed or (it == 1 and stale) or (it > 1 and trial.matrix_iteration == 0 and contraction > REUSE_RATE):
            if not newton_matrix(work, cache, slot, solid.frame):
                return core.NO_CONVERGENCE, it
            trial.matrix_level = slot
            trial.matrix_iteration = it  # built at this iteration of this step (0: inherited from the last step)
        elif it == 1:
            trial.matrix_iteration = 0
        core.copy1(unknowns.X_prev, X)
        newton_step(work, cache, slot, solid.frame, model.law)
    return core.NO_CONVERGENCE, cfg.max_iterations
