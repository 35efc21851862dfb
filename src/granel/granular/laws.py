"""The laws of the applied loads and of a shaker wall's motion, compiled once: the integrator
evaluates them at every RK4 stage, and `granular.loads` (`LoadHistory`, `WallDrive`) calls the
same functions from Python. The histories' parameters are laid out as `granular.loads` builds
them (the kind codes and LOAD_PARAMS below)."""

from __future__ import annotations

import math

from ..guard.jit import njit

# how a load history is handed to `load_force`: a kind code and up to LOAD_PARAMS parameters
KIND_HALF_SINE = 0
KIND_BURST = 1
KIND_TABLE = 2
KIND_CONSTANT = 3
KIND_HARMONIC = 4
KIND_CHIRP = 5
KIND_CODES = {"half_sine": KIND_HALF_SINE, "burst": KIND_BURST, "table": KIND_TABLE, "constant": KIND_CONSTANT,
              "harmonic": KIND_HARMONIC, "chirp": KIND_CHIRP}
LOAD_PARAMS = 8  # parameter slots per load


@njit(cache=True, inline="always")
def ramp(s, t_ramp, duration):
    """The drives' envelope at s into them: (1 - cos(pi s / t_ramp)) / 2 for s < t_ramp, the same
    mirrored over the last t_ramp of the duration, 1 between (and for t_ramp = 0)."""
    if t_ramp <= 0.0:
        return 1.0
    x = min(s, duration - s) / t_ramp
    return 1.0 if x >= 1.0 else 0.5 * (1.0 - math.cos(math.pi * x))


@njit(cache=True, inline="always")
def chirp_phase(s, f0, f1, duration, geometric):
    """phi(s) of a chirp from f0 to f1 over `duration` (phi' / 2 pi goes from f0 to f1): linear,
    2 pi (f0 s + (f1 - f0) s^2 / (2 D)), or geometric, 2 pi f0 D (k^(s/D) - 1) / ln k, k = f1/f0."""
    if geometric and f1 != f0:
        k = math.log(f1 / f0)
        return 2.0 * math.pi * f0 * duration * math.expm1(s / duration * k) / k
    return 2.0 * math.pi * (f0 * s + 0.5 * (f1 - f0) * s * s / duration)


@njit(cache=True, inline="always")
def load_force(kind, par, tab_t, tab_v, t):
    """F(t) [N] of one load history: half-sine (fmax, tau, t0), burst (amp, f, t0, cycles), table
    (linear through tab_t, tab_v, zero outside), constant (F), harmonic (amp, f, t0, duration,
    phase, ramp cycles) or chirp (amp, f0, t0, duration, f1, ramp cycles, geometric)."""
    if kind == KIND_HALF_SINE:
        s = t - par[2]
        if s < 0.0 or s > par[1]:
            return 0.0
        return par[0] * math.sin(math.pi * s / par[1])
    if kind == KIND_BURST:
        s = t - par[2]
        if s < 0.0 or s > par[3] / par[1]:
            return 0.0
        return par[0] * math.sin(2.0 * math.pi * par[1] * s)
    if kind == KIND_TABLE:
        lo = 0
        hi = tab_t.shape[0] - 1
        if hi < lo or t < tab_t[lo] or t > tab_t[hi]:
            return 0.0
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if tab_t[mid] <= t:
                lo = mid
            else:
                hi = mid
        if hi == lo:
            return tab_v[lo]
        w = (t - tab_t[lo]) / (tab_t[hi] - tab_t[lo])
        return tab_v[lo] * (1.0 - w) + tab_v[hi] * w
    if kind == KIND_HARMONIC or kind == KIND_CHIRP:
        s = t - par[2]
        if s < 0.0 or s > par[3]:
            return 0.0
        f = par[1]
        if kind == KIND_HARMONIC:
            phase = 2.0 * math.pi * f * s + par[4]
        else:
            phase = chirp_phase(s, f, par[4], par[3], par[6] > 0.5)
        return par[0] * ramp(s, par[5] / f, par[3]) * math.sin(phase)
    return par[0]


@njit(cache=True, inline="always")
def wall_motion(par, t):
    """(s, ds/dt) of a shaker wall along its normal at time t [m, m/s]: s = amplitude r(tau)
    sin(2 pi f tau + phase), tau = t - t0, for 0 <= tau <= duration, r the drives' ramp over
    ramp_cycles / f (up and down); par = (amplitude, f, t0, duration, phase, ramp cycles), and a
    wall at rest (f = 0) does not move."""
    f = par[1]
    tau = t - par[2]
    if f <= 0.0 or tau < 0.0 or tau > par[3]:
        return 0.0, 0.0
    om = 2.0 * math.pi * f
    t_ramp = par[5] / f
    r, dr = 1.0, 0.0
    if t_ramp > 0.0:
        up = tau <= par[3] - tau
        x = (tau if up else par[3] - tau) / t_ramp
        if x < 1.0:
            r = 0.5 * (1.0 - math.cos(math.pi * x))
            dr = 0.5 * math.pi / t_ramp * math.sin(math.pi * x) * (1.0 if up else -1.0)
    arg = om * tau + par[4]
    return par[0] * r * math.sin(arg), par[0] * (dr * math.sin(arg) + r * om * math.cos(arg))
