"""The scales of a run, derived once from its built granular system: the speed and energy the
loads impart, the Hertz contact frequency at the solid (eq. 2) and the automatic mode cut-off
it sets, and the times where a load or a wall's motion is not smooth."""

from __future__ import annotations

import numpy as np

from .materials import impact_overlap
from .system import GranularState, GranularSystem

# the dropped modes' quasi-static error in the energies, measured on the strong SSGM-side plate
# case at cut-offs of 0.25-4 MHz: about TRUNCATION_ERROR (f_H / f_cut)^2 of the input
TRUNCATION_ERROR = 0.1


def load_scales(system: GranularSystem, state: GranularState, duration: float = 0.0) -> tuple[float, float]:
    """A run of `duration` seconds: its velocity and energy scales. The velocity: the largest speed
    a load can give its granule (peak impulse / mass), or the initial motion's. The energy: the
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
        if h.kind in ("harmonic", "chirp") and duration > 0:
            driving = max(0.0, min(h.params[3], duration - h.params[2]))
            energy = max(energy, 0.5 * abs(h.params[0]) * v * driving)
        scales.append((v, energy))
    for w in system.walls:  # a shaker: the speed it gives a granule, and that granule's energy then
        if w.drive is not None and system.n:
            sp = w.drive.peak_speed()
            scales.append((sp, 0.5 * float(system.mass.max()) * sp * sp))
    v = np.abs(state.vel)
    for g in (np.flatnonzero(v.max(axis=1) > 0) if v.size else []):
        sp = float(np.hypot(*state.vel[g]))
        scales.append((sp, 0.5 * system.mass[g] * sp * sp))
    if not scales:
        return 1.0, 1.0
    return max(s for s, _ in scales), max(e for _, e in scales)


def contact_frequency(system: GranularSystem, v_ref: float) -> float:
    """The highest Hertz contact frequency at the solid [Hz]: each solid contact's granule striking
    it at v_ref, sqrt(k/m) / 2 pi with k = 3/2 A sqrt(delta) at the impact's peak overlap (eq. 2)."""
    best = 0.0
    for c, sc in enumerate(system.solid_contacts):
        m, A = float(system.mass[sc.granule]), float(system.points.A[c])
        delta = impact_overlap(m, v_ref, A)
        best = max(best, float(np.sqrt(1.5 * A * np.sqrt(delta) / m)) / (2 * np.pi))
    return best


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
