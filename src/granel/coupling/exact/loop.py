"""The exact integrator's step loop: steps through a batch of output times, each step solved
(`interface`), judged (`ledger`) and accepted or retried smaller, the outputs it passes filled by
dense output (`dense`)."""

from __future__ import annotations

import numpy as np

from ...granular.bundles import ACC_WORK, ledger_offset
from ...granular.contact import friction_map_slope
from ...granular.kernels import moved_beyond
from ...guard.jit import njit
from .. import core
from .dense import dense, dense_state, trial_step
from .interface import interface_solve
from .ledger import (LEDGER_ACCEPT, LEDGER_NOISE, contact_roundoff, control_error, grid_level, ledger_bound, next_level,
                     state_ledger, step_error, trial_ledger)
from .operators import ensure_ops, free_response
from .state import GRID_PER_OCTAVE, DenseOut, node_iface, work_for


@njit(cache=True)
def accept(state, cache, slot, h, work, ledger):
    """The accepted step: modes, interface data and the granules to t + h; the step kept for dense
    output and the next predictor."""
    unknowns, nodes, granular = work.unknowns, work.nodes, work.granular
    nc = state.F.shape[0]
    m2 = 2 * nc
    nb = cache.nodes.shape[0]
    nn = nb - 1
    last = state.last
    core.copy1(last.y0, state.y)
    core.copy1(last.eta0, state.eta)
    core.copy1(last.etad0, state.etad)
    core.copy2(last.Fs[0], state.F)
    for b in range(1, nb):
        for r in range(m2):
            last.Fs[b, r // 2, r % 2] = unknowns.X[(b - 1) * m2 + r]
    core.copy2(last.qs, unknowns.modal_force)  # from `ledger.trial_ledger`
    core.copy2(last.Ts, cache.T[slot])
    core.copy1(state.eta, unknowns.eta_end)
    core.copy1(state.etad, unknowns.etad_end)
    core.copy2(state.F, last.Fs[nb - 1])
    core.copy1(state.q, last.qs[nb - 1])
    core.copy1(state.u, nodes.u[nn - 1])
    core.copy1(state.w, nodes.w[nn - 1])
    mo, sm = nodes.motion, last.motion
    core.copy2(sm.u0, mo.u0)
    core.copy2(sm.v0, mo.v0)
    core.copy2(sm.a, mo.a)
    core.copy2(sm.j, mo.j)
    core.copy2(sm.d4, mo.d4)
    core.copy2(sm.d5, mo.d5)
    core.copy1(state.y, granular.y)
    core.copy1(state.dy, granular.dy_end)
    end = node_iface(unknowns, nn - 1)
    core.copy1(state.normal, end.normal)
    core.copy1(state.vrel, end.vrel)
    clock = state.clock[0]
    clock.t_start = clock.t
    clock.t += h
    clock.friction_rate = work.trial[0].rate
    clock.ledger = ledger


@njit(cache=True)
def friction_slopes(state, law, cache, slot, frame, lam):
    """The slope of each contact's local friction map over the step just taken, the analogue of
    (A9) for this integrator: mu k_s |N| t' Cw t / cosh^2(k_s v_t), Cw the end velocity's
    response to the end force."""
    nb = cache.nodes.shape[0]
    for c in range(lam.shape[0]):
        if not frame.has_tangent[c]:
            lam[c] = 0.0
            continue
        ctt = core.tangential_compliance(cache.Cw[slot, nb - 2, nb - 1], c, frame.tangent[c, 0], frame.tangent[c, 1])
        lam[c] = friction_map_slope(law.mu, law.k_s, state.normal[c], state.vrel[c], ctt)


@njit(cache=True)
def advance_outputs(state, model, ref_pos, solid, cache, cfg, targets, kinks, log, out, done):
    """Accepted steps through the output times `targets`, from output done[0] on: a step that
    reaches outputs fills their states in `out` (a `DenseOut` of arrays, one row per output) by
    dense output and, when adaptive, is accepted only if their energy ledgers (13) stay within
    the bound too;
    done[0] counts the outputs filled. Returns (status, steps logged): core.DONE once all are
    filled, core.REBUILD, core.LOG_FULL, core.NO_CONVERGENCE, core.NON_FINITE or
    core.BALANCE_LOST (the ledger (13) drifted beyond cfg.ledger_limit)."""
    work = work_for(state.y, state.F.shape[0], state.eta.shape[0], cache.nodes.shape[0])
    unknowns, trial = work.unknowns, work.trial[0]
    clock = state.clock[0]
    nc = state.F.shape[0]
    nb = cache.nodes.shape[0]
    n = model.granules.radius.shape[0]
    lim2 = cfg.max_disp * cfg.max_disp
    lam = np.zeros(nc)
    off = cache.ready.shape[0] - 1
    oy, oeta, oetad, oF = out.y, out.eta, out.etad, out.F
    # outputs the last accepted step already passed (it ended a previous batch beyond its last output)
    while done[0] < targets.shape[0] and targets[done[0]] <= clock.t:
        o = done[0]
        dense_state(state, solid, model, targets[o], DenseOut(oy[o], oeta[o], oetad[o], oF[o]))
        done[0] += 1
    k = 0
    while done[0] < targets.shape[0]:
        if k >= log.t.shape[0]:
            return core.LOG_FULL, k
        level = clock.grid_level
        h = cfg.h_max / 2.0 ** (level / GRID_PER_OCTAVE)
        slot = level
        t = clock.t
        for q in range(kinks.shape[0]):  # never step across a load's kink (nor stop just short of it)
            if t + 1e-6 * h < kinks[q] < t + h:
                h = kinks[q] - t
                slot = off
        ensure_ops(cache, solid, slot, h)
        free_response(state, solid, cache, slot, work.nodes)
        status, its = interface_solve(state, t, h, model, solid, cache, slot, cfg, work)
        if status != core.CONVERGED:
            if level + 2 * GRID_PER_OCTAVE <= cfg.levels:
                clock.grid_level = level + 2 * GRID_PER_OCTAVE  # a quarter of the step (fixed steps: then dt again)
                clock.level = clock.grid_level
                clock.rejected += 1
                continue
            return status, k
        ledger = trial_ledger(state, solid, cache, slot, model, work)
        tol = ledger_bound(cfg, clock)
        trial.roundoff = max(trial.roundoff, contact_roundoff(work.granular.y, state.dy, model,
                                                              work.nodes.u[nb - 2].reshape(nc, 2), t + h))
        ok = step_error(work, cfg, model.granules, t, h, ledger - clock.ledger, clock.ledger - clock.ledger_start, tol)
        # the outputs this step reaches, by dense output from its start (the last one may be its end)
        filled = 0
        worst_dense = 0.0
        while done[0] + filled < targets.shape[0] and targets[done[0] + filled] <= (t + h) * (1.0 + 1e-12):
            o = done[0] + filled
            tau = targets[o] - t
            if tau >= h * (1.0 - 1e-12):
                core.copy1(oy[o], work.granular.y)
                core.copy1(oeta[o], unknowns.eta_end)
                core.copy1(oetad[o], unknowns.etad_end)
                for r in range(2 * nc):
                    oF[o, r // 2, r % 2] = unknowns.X[(nb - 2) * 2 * nc + r]
            else:
                dense(trial_step(state, cache, slot, work), solid, model, tau, DenseOut(oy[o], oeta[o], oetad[o], oF[o]))
                defect = state_ledger(oy[o], oeta[o], oetad[o], solid, model) - clock.ledger
                floor = max(LEDGER_NOISE * trial.iteration_noise, trial.roundoff)
                if abs(defect) > floor:
                    worst_dense = max(worst_dense, (abs(clock.ledger - clock.ledger_start + defect) - floor) / tol)
            filled += 1
        if cfg.adaptive and (not ok or worst_dense > 1.0) and level < cfg.levels:
            worst = max(trial.velocity_error, trial.ledger_part / LEDGER_ACCEPT, trial.drift_part, worst_dense)
            clock.level = max(level + 1.0, next_level(clock.level, worst, cfg))
            clock.grid_level = grid_level(clock.level)
            clock.rejected += 1
            continue
        if abs(ledger - clock.ledger_start) > cfg.ledger_limit * max(1.0, clock.work_max / cfg.e_ref):
            return core.BALANCE_LOST, k  # even the smallest step lost the energy balance (13)
        ectl = control_error(trial, clock, h)  # before the clock moves: it rescales from the last step
        accept(state, cache, slot, h, work, ledger)
        clock.work_max = max(clock.work_max, abs(state.y[ledger_offset(n) + ACC_WORK]))
        done[0] += filled
        friction_slopes(state, model.law, cache, slot, solid.frame, lam)
        log.t[k] = clock.t
        log.h[k] = h
        log.iterations[k] = its
        core.copy1(log.lam[k], lam)
        k += 1
        clock.level = next_level(clock.level, ectl, cfg)
        clock.grid_level = grid_level(clock.level)
        if moved_beyond(state.y, n, ref_pos, lim2):
            return core.REBUILD, k
    return core.DONE, k


def compile_plan(state, model, ref_pos, solid, cache, cfg, targets, kinks, log, out, done):
    """The kernels `advance_outputs` calls, with arguments of the types it calls them with, in the
    order a second process compiles them ahead of the first (`guard.ahead`): the first reaches
    `interface_solve`, the largest, last of its early callees, then takes the others in call
    order while this one takes them from the end. Called with `advance_outputs`'s arguments;
    the signatures must stay those of the calls above (tests/test_compile_ahead.py)."""
    nc, nr, nb = state.F.shape[0], state.eta.shape[0], cache.nodes.shape[0]
    work = work_for.py_func(state.y, nc, nr, nb)  # in Python: the first process compiles work_for
    t, h, slot, ledger = float(state.clock[0]["t"]), float(cfg.h_max), 0, float(state.clock[0]["ledger"])
    oy, oeta, oetad = out.y, out.eta, out.etad
    yield interface_solve, (state, t, h, model, solid, cache, slot, cfg, work)
    yield accept, (state, cache, slot, h, work, ledger)
    yield friction_slopes, (state, model.law, cache, slot, solid.frame, np.zeros(nc))
    yield state_ledger, (oy[0], oeta[0], oetad[0], solid, model)
    yield trial_step, (state, cache, slot, work)
    yield step_error, (work, cfg, model.granules, t, h, ledger, ledger, ledger)
