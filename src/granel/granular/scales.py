"""The scales of a run, derived once from its built granular system: the speed and energy the
loads impart, the Hertz collision time and contact frequency (eq. 2) and the bounds they set
(the largest safe step, the automatic mode cut-off), and the times where a load or a wall's
motion is not smooth."""

from __future__ import annotations

import math

import numpy as np

from .contact import hertz_overlap, hertz_stiffness, impact_overlap
from .materials import pair_coefficients, wall_coefficients
from .system import GranularState, GranularSystem

# a Hertz impact lasts HERTZ_DURATION delta_max / v: 2 (2/5) B(2/5, 1/2)
HERTZ_DURATION = 0.8 * math.gamma(0.4) * math.sqrt(math.pi) / math.gamma(0.9)

# the dropped modes' quasi-static error in the energies: about TRUNCATION_ERROR (f_H / f_cut)^2 of
# the input (fitted to the measurements in docs/performance.md, "Modes")
TRUNCATION_ERROR = 0.1


def load_scales(system: GranularSystem, state: GranularState, duration: float = 0.0) -> tuple[float, float]:
    """A run of `duration` seconds: its velocity and energy scales. The velocity: the largest speed
    a load can give its granule (peak impulse / mass), gravity in a free fall over the run, or the
    initial motion's. The energy: the
    kinetic energy that speed carries, or, for a drive (harmonic, chirp), the work its amplitude
    does at that speed over the time it drives, A v D / 2, which over many cycles is what flows
    through the system; 1 m/s and 1 J if nothing is bounded (constant loads alone)."""
    scales = []
    for e in system.excitations:
        m, h = system.mass[e.granule], e.history
        v = h.peak_impulse() / m
        if not (np.isfinite(v) and v > 0):
            continue
        energy = 0.5 * m * v * v
        driving = h.driving_time(duration) if duration > 0 else 0.0
        if driving > 0:
            energy = max(energy, 0.5 * h.peak() * v * driving)
        scales.append((v, energy))
    for w in system.walls:  # a shaker: the speed it gives a granule, and that granule's energy then
        if w.drive is not None and system.n:
            sp = w.drive.peak_speed()
            scales.append((sp, 0.5 * float(system.mass.max()) * sp * sp))
    accel = float(np.hypot(*system.gravity))
    if accel > 0 and duration > 0 and system.n:  # the most speed gravity gives a granule in the run: free fall
        sp = accel * duration
        scales.append((sp, 0.5 * float(system.mass.max()) * sp * sp))
    v = np.abs(state.vel)
    for g in (np.flatnonzero(v.max(axis=1) > 0) if v.size else []):
        sp = float(np.hypot(*state.vel[g]))
        scales.append((sp, 0.5 * system.mass[g] * sp * sp))
    if not scales:
        return 1.0, 1.0
    return max(s for s, _ in scales), max(e for _, e in scales)


def collision_time(m_star, speed, A):
    """The duration of an undamped Hertz impact at closing speed v (eq. 2): HERTZ_DURATION
    delta_max / v, delta_max its largest overlap (`contact.impact_overlap`)."""
    return HERTZ_DURATION * impact_overlap(m_star, speed, A) / speed


def linear_frequency(m_star, A, delta) -> float:
    """The frequency [Hz] of small oscillations of a Hertz contact about the overlap delta (eq. 2):
    sqrt(k / m*) / 2 pi, k = `contact.hertz_stiffness`."""
    return float(np.sqrt(hertz_stiffness.py_func(A, delta) / m_star)) / (2 * np.pi)


def contact_frequency(system: GranularSystem, v_ref: float) -> float:
    """The highest Hertz contact frequency at the solid [Hz]: each solid contact's granule striking
    it at v_ref, `linear_frequency` at the impact's peak overlap."""
    best = 0.0
    for c, sc in enumerate(system.solid_contacts):
        m, A = float(system.mass[sc.granule]), float(system.points.A[c])
        best = max(best, linear_frequency(m, A, impact_overlap(m, v_ref, A)))
    return best


def safe_time_step(system, excitations, init_speed: float = 0.0) -> float:
    """An upper bound for the RK4 step: 1/20 of the shortest Hertz collision time expected
    (granule pairs of each size and granule-wall impacts at the largest speed an excitation
    or an initial velocity can impart, impulse / mass), 1/20 of the period of such a contact
    compressed by the largest load (constant and tabulated loads included, or the granules' whole
    weight), and 1/10 of the
    shortest pulse duration."""
    bounds = []
    speed = init_speed
    force = max((e.history.peak() for e in excitations if math.isfinite(e.history.peak())), default=0.0)
    force = max(force, float(np.hypot(*system.weights.sum(axis=0))) if system.n else 0.0)  # all the weight on one contact
    for e in excitations:
        m = system.mass[e.granule]
        J = e.history.peak_impulse()
        if math.isfinite(J) and J > 0:
            speed = max(speed, J / m)
        bounds.append(e.history.step_bound())
    for w in system.walls:  # a shaker: its period, and the impacts at its speed
        if w.drive is not None:
            bounds.append(1.0 / (w.drive.frequency * 20.0))
            speed = max(speed, w.drive.peak_speed())
    if (speed > 0 or force > 0) and system.n:
        kinds = np.column_stack([system.radius, system.E, system.nu, system.mass])
        for g in np.unique(kinds, axis=0, return_index=True)[1]:
            body, m = system.bodies(g), system.mass[g]
            pair = float(pair_coefficients(body, body, 0.0)[0]), m / 2
            wall = float(wall_coefficients(body, 0.0)[0]), m
            for A, ms in (pair, wall):
                if speed > 0:
                    bounds.append(collision_time(ms, speed, A) / 20.0)
                if force > 0:  # a sustained load: the contact's period about the overlap it compresses to
                    bounds.append(1.0 / linear_frequency(ms, A, hertz_overlap(force, A)) / 20.0)
    return min(bounds) if bounds else math.inf


def auto_mode_cutoff(system: GranularSystem, v_ref: float, rtol: float) -> float:
    """The exact integrator's mode cut-off from its tolerance [Hz]: where the dropped modes'
    quasi-static error, about TRUNCATION_ERROR (f_H / f_cut)^2 with f_H the stiffest solid
    contact's Hertz frequency (`contact_frequency`), is 3 rtol; 2 MHz without solid contacts."""
    f_h = contact_frequency(system, v_ref)
    return f_h * float(np.sqrt(TRUNCATION_ERROR / (3.0 * rtol))) if f_h > 0 else 2e6


def load_kinks(system: GranularSystem) -> list[float]:
    """Times where a load's history or a wall's motion is not smooth: a step never crosses them."""
    return [t for e in system.excitations for t in e.history.kinks()] + \
        [t for w in system.walls if w.drive is not None for t in w.drive.kinks()]
