"""The laws of the applied loads and of a shaker wall's motion, compiled once: the integrator
evaluates them at every RK4 stage, and `granular.loads` (its history classes, `WallDrive`) calls
the same functions from Python. `load_force` unpacks each kind's parameters by name, in the
layout of its class's `params` (`granular.loads`)."""

from __future__ import annotations

import math

from ..guard.jit import njit
from .load_codes import KIND_BURST, KIND_CHIRP, KIND_HALF_SINE, KIND_HARMONIC, KIND_TABLE, LOAD_PARAMS  # noqa: F401


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
def half_sine_force(t, fmax, tau, t0):
    """`loads.HalfSine`: fmax sin(pi (t - t0) / tau) over [t0, t0 + tau], else 0."""
    s = t - t0
    if s < 0.0 or s > tau:
        return 0.0
    return fmax * math.sin(math.pi * s / tau)


@njit(cache=True, inline="always")
def burst_force(t, amplitude, frequency, t0, cycles):
    """`loads.Burst`: amplitude sin(2 pi f (t - t0)) for `cycles` periods from t0."""
    s = t - t0
    if s < 0.0 or s > cycles / frequency:
        return 0.0
    return amplitude * math.sin(2.0 * math.pi * frequency * s)


@njit(cache=True, inline="always")
def table_force(t, tab_t, tab_v):
    """`loads.Table`: linear through (tab_t, tab_v), zero outside."""
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


@njit(cache=True, inline="always")
def drive_force(t, amplitude, frequency, t0, duration, ramp_cycles, phase_of_s):
    """`loads.Harmonic` and `loads.Chirp`: amplitude r(s) sin(phase(s)), s = t - t0, over
    [0, duration], r the ramp of `ramp_cycles` periods at `frequency` (the start frequency)."""
    s = t - t0
    if s < 0.0 or s > duration:
        return 0.0
    return amplitude * ramp(s, ramp_cycles / frequency, duration) * math.sin(phase_of_s)


@njit(cache=True, inline="always")
def load_force(kind, par, tab_t, tab_v, t):
    """F(t) [N] of one load history from its kind code and parameters (`granular.loads`)."""
    if kind == KIND_HALF_SINE:
        return half_sine_force(t, par[0], par[1], par[2])
    if kind == KIND_BURST:
        return burst_force(t, par[0], par[1], par[2], par[3])
    if kind == KIND_TABLE:
        return table_force(t, tab_t, tab_v)
    if kind == KIND_HARMONIC:
        amplitude, frequency, t0, duration, phase, ramp_cycles = par[0], par[1], par[2], par[3], par[4], par[5]
        return drive_force(t, amplitude, frequency, t0, duration, ramp_cycles, 2.0 * math.pi * frequency * (t - t0) + phase)
    if kind == KIND_CHIRP:
        amplitude, f0, t0, duration, f1, ramp_cycles, geometric = par[0], par[1], par[2], par[3], par[4], par[5], par[6]
        return drive_force(t, amplitude, f0, t0, duration, ramp_cycles, chirp_phase(t - t0, f0, f1, duration, geometric > 0.5))
    return par[0]  # KIND_CONSTANT: the value


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
