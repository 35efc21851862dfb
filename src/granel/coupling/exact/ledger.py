"""The exact integrator's error control: a step's local error is the embedded RK4 error of the
granules' velocities and the step's defect of the energy ledger (13) against its share of the
run's bound; the controller picks the next step on a geometric grid of sizes (docs/coupling.md
explains the control and docs/performance.md its tuning)."""

from __future__ import annotations

import math

import numpy as np

from ...granular.bundles import ACC_FRIC, ACC_VISC, ACC_WORK, ledger_offset, spin_offset, velocity_offset
from ...granular.contact import hertz_force
from ...granular.kernels import load_value, overlaps
from ...guard.jit import njit
from .. import core
from ..observation import energy_ledger, granular_energy, modal_energy
from .operators import modes_of_contacts, propagate_mode
from .state import GRID_PER_OCTAVE

# a step's defect of the ledger is accepted up to LEDGER_ACCEPT times its share (`ledger_share`),
# and the running mean square of defect / share (each clipped at LEDGER_CLIP, filter weight
# LEDGER_FILTER) aims at LEDGER_RMS^2
LEDGER_RMS = 0.4
LEDGER_FILTER = 0.2
LEDGER_CLIP = 1.0
LEDGER_ACCEPT = 2.0
ORDER = 4.5  # a step's ledger part goes as h^5 over a share as h^(1/2)
LEDGER_NOISE = 4.0  # a defect within this many times the iteration's noise passes ...
LEDGER_ROUNDOFF = 2.220446049250313e-16  # ... or within the ledger's round-off


@njit(cache=True)
def trial_ledger(state, solid, cache, slot, model, work):
    """E_solid + E_granular + D - W (eq. 13) at the end of the trial step: the modes' energy from
    their exact end state (kept in the work for the accept), the granules' energy (11) and the
    ledger's accumulators; the ledger's round-off goes to the trial record."""
    unknowns = work.unknowns
    m2 = state.u.shape[0]
    nr = state.eta.shape[0]
    nn = cache.nodes.shape[0] - 1
    if nr > 0:
        core.copy1(unknowns.modal_force[0], state.q)
        modes_of_contacts(unknowns.X.reshape(nn, m2), solid.P, unknowns.modal_force[1:])
    free = cache.free[slot, nn - 1]
    disp, vel = cache.end_disp[slot], cache.end_vel[slot]
    for i in range(nr):
        unknowns.eta_end[i], unknowns.etad_end[i] = propagate_mode(free, disp, vel, i, state.eta[i], state.etad[i],
                                                                   unknowns.modal_force)
    kinetic, potential = modal_energy(unknowns.eta_end, unknowns.etad_end, solid.omega)
    es = kinetic + potential
    y = work.granular.y
    eg = granular_energy(y, model, work.nodes.u[nn - 1].reshape(m2 // 2, 2))
    acc = ledger_offset(model.granules.radius.shape[0])
    visc, fric, work_in = y[acc + ACC_VISC], y[acc + ACC_FRIC], y[acc + ACC_WORK]
    work.trial[0].roundoff = LEDGER_ROUNDOFF * (es + abs(eg) + abs(visc + fric) + abs(work_in))
    return energy_ledger(es, eg, visc, fric, work_in)


@njit(cache=True)
def contact_roundoff(y, dy, model, su, t):
    """The rounding of the contacts' potential energy in the ledger (13): each overlap is a
    difference of lengths of the size of the radii, rounded to LEDGER_ROUNDOFF of that, which its
    force A delta^(3/2) turns into energy; and rounding a granule's position changes its
    contacts' energy by the net contact force on it (m a minus the loads; dy holds a) times
    that (the loads and weights too). Under a static preload these are far above the energies' own
    rounding."""
    gr = model.granules
    radius = gr.radius
    n = radius.shape[0]
    V = velocity_offset(n)
    pairs, walls, points, loads = model.pairs, model.walls, model.points, model.loads
    dp, dw, ds = overlaps(y, model, su)
    sq = 0.0  # the contacts' roundings are independent: they add in quadrature
    for c in range(dp.shape[0]):
        if dp[c] > 0.0:
            sq += (hertz_force(pairs.A[c], dp[c]) * (radius[pairs.i[c]] + radius[pairs.j[c]])) ** 2
    for c in range(dw.shape[0]):
        if dw[c] > 0.0:
            sq += (hertz_force(walls.A[c], dw[c]) * radius[walls.g[c]]) ** 2
    for c in range(ds.shape[0]):
        if ds[c] > 0.0:
            sq += (hertz_force(points.A[c], ds[c]) * radius[points.g[c]]) ** 2
    total = math.sqrt(sq)
    for i in range(n):
        total += gr.mass[i] * math.hypot(dy[V + 2 * i], dy[V + 2 * i + 1]) * max(abs(y[2 * i]), abs(y[2 * i + 1]))
    for e in range(loads.g.shape[0]):
        i = loads.g[e]
        total += abs(load_value(loads, e, t)) * max(abs(y[2 * i]), abs(y[2 * i + 1]))
    for i in range(n):  # the weights, like the loads
        total += math.hypot(gr.weight[i, 0], gr.weight[i, 1]) * max(abs(y[2 * i]), abs(y[2 * i + 1]))
    return LEDGER_ROUNDOFF * total


@njit(cache=True)
def state_ledger(y, eta, etad, solid, model):
    """E_solid + E_granular + D - W (eq. 13) of a state (the granules y, the modes eta, eta')."""
    nc = solid.P.shape[0] // 2
    kinetic, potential = modal_energy(eta, etad, solid.omega)
    es = kinetic + potential
    su = np.dot(solid.P, eta) if eta.shape[0] else np.zeros(2 * nc)
    acc = ledger_offset(model.granules.radius.shape[0])
    return energy_ledger(es, granular_energy(y, model, su.reshape(nc, 2)), y[acc + ACC_VISC], y[acc + ACC_FRIC],
                         y[acc + ACC_WORK])


@njit(cache=True, inline="always")
def ledger_bound(cfg, clock):
    """The run's bound on the energy ledger (13): ledger_tol times the larger of the energy scale
    e_ref (the loads' and initial motion's, known before the run) and the largest |input work| so
    far (the energy the loads actually move, which e_ref cannot foresee, as a preload's
    exchange with a small drive)."""
    return cfg.ledger_tol * max(cfg.e_ref, clock.work_max)


@njit(cache=True)
def ledger_share(cfg, t, h, drift, tol):
    """What a step of size h from time t may add to the energy ledger (13), drifted by `drift`
    so far against the bound tol: its random-walk share tol sqrt(h / T) while the drift is small
    (fading out as the drift reaches tol / 2), or the room left spread over the time left,
    whichever is larger."""
    room = max(tol - abs(drift), 0.0)
    walk = tol * math.sqrt(h / cfg.duration) * max(0.0, 1.0 - 2.0 * abs(drift) / tol)
    return max(walk, room * h / max(cfg.duration - t, h))


@njit(cache=True)
def next_level(lev, err, cfg):
    """The next continuous level lev (the step h_max 2^(-lev/4)) for a scaled error err that goes
    as h^ORDER, aiming at err = 1, with growth between 1/5 and 2."""
    if not cfg.adaptive:
        return 0.0
    fac = min(2.0, max(0.2, max(err, 1e-10) ** (-1.0 / ORDER)))
    return min(float(cfg.levels), max(0.0, lev - GRID_PER_OCTAVE * math.log2(fac)))


@njit(cache=True)
def control_error(trial, clock, h):
    """The scaled error the controller aims at 1 after an accepted step of size h: the larger of
    the velocity part and the ledger part's running mean square (each clipped at LEDGER_CLIP,
    rescaled to h) over LEDGER_RMS. Updates the running mean square in the clock."""
    hp = clock.t - clock.t_start
    r2 = min(trial.ledger_part, LEDGER_CLIP) ** 2
    if hp > 0.0 and clock.ledger_ms > 0.0:
        r2 = (1.0 - LEDGER_FILTER) * clock.ledger_ms * (h / hp) ** (2.0 * ORDER) + LEDGER_FILTER * r2
    clock.ledger_ms = r2
    return max(trial.velocity_error, math.sqrt(r2) / LEDGER_RMS)


@njit(cache=True, inline="always")
def grid_level(lev):
    """The grid level of a continuous level: the step is never above the controller's."""
    return int(math.ceil(lev - 1e-9))


@njit(cache=True)
def step_error(work, cfg, granules, t, h, defect, drift, tol):
    """The parts of the scaled local error of the coupled step from t to t + h, in the trial
    record: the largest embedded RK4 error of a granule's velocity or spin velocity R omega
    against atol + rtol v_ref; the step's defect of the energy ledger (13) against its share of
    the bound tol (`ledger_share`); the drift after the step against tol. A defect within
    LEDGER_NOISE times the iteration's noise, or within the ledger's round-off, passes both.
    True if the step is accepted."""
    trial = work.trial[0]
    err = work.granular.err
    radius = granules.radius
    n = radius.shape[0]
    V = velocity_offset(n)
    OM = spin_offset(n)
    ev = 0.0
    for i in range(n):
        ev = max(ev, abs(err[V + 2 * i]), abs(err[V + 2 * i + 1]), radius[i] * abs(err[OM + i]))
    trial.velocity_error = ev / (cfg.atol + cfg.rtol * cfg.v_ref)
    # no step is asked to close the ledger below the iteration's own floor, nor below its round-off
    noise = max(LEDGER_NOISE * trial.iteration_noise, trial.roundoff)
    trial.ledger_part = abs(defect) / max(ledger_share(cfg, t, h, drift, tol), noise, 1e-300)
    # a defect within the floor cannot be made smaller, whatever the drift: only a larger one counts
    trial.drift_part = max(abs(drift + defect) - noise, 0.0) / tol if abs(defect) > noise else 0.0
    return trial.velocity_error <= 1.0 and trial.ledger_part <= LEDGER_ACCEPT and trial.drift_part <= 1.0
