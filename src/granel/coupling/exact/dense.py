"""Dense output of the exact integrator: the state at any time inside a step, from the step's
start and its force polynomial, so that outputs fall where they are asked without cutting steps."""

from __future__ import annotations

import numpy as np

from ...granular.bundles import interface_buffers
from ...granular.kernels import interface_forces, motion_at, rk4_substepped
from ...guard.jit import njit
from .. import core
from ...solid.propagation import weights_at
from ..observation import modal_energy
from .operators import propagate_mode
from .state import StepData


@njit(cache=True)
def dense(step, solid, model, tau, out):
    """The state at tau inside a step: the granules by RK4 from the step's start over tau under the
    step's contact motion, the modes by their exact response to the step's force polynomial, and
    the interface force as the contact law gives it there (what the granules feel)."""
    core.copy1(out.y, step.y0)
    if tau > 0.0:
        rk4_substepped(out.y, step.t0, tau, model, step.motion, step.rate, np.empty((5, out.y.shape[0])))
    nc = out.F.shape[0]
    if nc:
        u, w = np.empty((nc, 2)), np.empty((nc, 2))
        for c in range(nc):
            u[c, 0], u[c, 1], w[c, 0], w[c, 1] = motion_at(step.motion, c, tau)
        iface = interface_buffers(nc)
        interface_forces(out.y, model, u, w, iface, np.bool_(False))  # a typed flag, not a literal: one signature
        core.copy2(out.F, iface.F)
    nb, nr = step.Ts.shape[0], step.eta0.shape[0]
    free, disp, vel = np.empty((nr, 3)), np.empty((nr, nb)), np.empty((nr, nb))
    weights_at(solid.omega, tau, step.Ts, free, disp, vel)
    for i in range(nr):
        out.eta[i], out.etad[i] = propagate_mode(free, disp, vel, i, step.eta0[i], step.etad0[i], step.qs)


@njit(cache=True)
def trial_step(state, cache, slot, work):
    """The trial step (before it is accepted) as `dense` reads it."""
    nb = cache.nodes.shape[0]
    nc = state.F.shape[0]
    X = work.unknowns.X
    Fs = np.empty((nb, nc, 2))
    core.copy2(Fs[0], state.F)
    for b in range(1, nb):
        for r in range(2 * nc):
            Fs[b, r // 2, r % 2] = X[(b - 1) * 2 * nc + r]
    return StepData(state.y, state.eta, state.etad, state.clock[0].t, Fs, work.unknowns.modal_force, cache.T[slot],
                    work.nodes.motion, work.trial[0].rate)


@njit(cache=True)
def dense_state(state, solid, model, t_out, out):
    """The state at t_out inside the last accepted step (`dense`), or its end."""
    clock, last = state.clock[0], state.last
    t0, t1 = clock.t_start, clock.t
    tau = t_out - t0
    if t1 - t0 <= 0.0 or tau >= t1 - t0:
        core.copy1(out.y, state.y)
        core.copy1(out.eta, state.eta)
        core.copy1(out.etad, state.etad)
        core.copy2(out.F, state.F)
        return
    dense(StepData(last.y0, last.eta0, last.etad0, t0, last.Fs, last.qs, last.Ts, last.motion, clock.friction_rate),
          solid, model, tau, out)


@njit(cache=True)
def solid_at_outputs(P, omega, oeta, oetad, su, energy):
    """Per output o of a batch (modes oeta, oetad): the contacts' displacement su[o] = P eta (nc,
    2) and the solid's kinetic and potential energy (eq. 11) in energy[o]."""
    nc = P.shape[0] // 2
    for o in range(oeta.shape[0]):
        u = np.dot(P, oeta[o]) if P.shape[1] else np.zeros(2 * nc)
        core.copy2(su[o], u.reshape(nc, 2))
        energy[o, 0], energy[o, 1] = modal_energy(oeta[o], oetad[o], omega)
