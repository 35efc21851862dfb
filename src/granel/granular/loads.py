"""Load histories applied to granules: half-sine shocks, harmonic bursts, tabulated forces,
constant forces (preloads), and narrowband drives: harmonic forces with a smooth ramp-up and
chirps sweeping a frequency band.

Each history is encoded as (kind, params, table) so that the compiled integrator can
evaluate it at any RK4 stage time without calling back into Python.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# The paper's three shock levels (Sec. III): half-sine pulses of 0.01 ms.
SHOCK_LEVELS = {"weak": 63.67, "moderate": 318.3, "strong": 1591.6}
PAPER_TAU = 1.0e-5



@dataclass(frozen=True)
class LoadHistory:
    """A scalar force history F(t) [N]; the direction is carried by the `Excitation`."""

    kind: str
    params: tuple[float, ...] = ()
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    values: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __call__(self, t: float) -> float:
        """F(t) [N], by the compiled law the integrator uses (`granular.laws.load_force`)."""
        from .laws import KIND_CODES, LOAD_PARAMS, load_force  # lazy: numba only where a load is evaluated

        params = np.zeros(LOAD_PARAMS)
        params[: len(self.params)] = self.params
        return float(load_force(KIND_CODES[self.kind], params, np.asarray(self.times, float),
                                np.asarray(self.values, float), float(t)))

    @property
    def end_time(self) -> float:
        """Time after which the force is identically zero (inf if it never stops)."""
        p = self.params
        if self.kind == "half_sine":
            return p[1] + p[2]
        if self.kind == "burst":
            return p[2] + p[3] / p[1]
        if self.kind == "table":
            return float(self.times[-1]) if self.values[-1] == 0 else math.inf
        if self.kind in ("harmonic", "chirp"):
            return p[2] + p[3]
        return math.inf

    def kinks(self) -> list[float]:
        """Times where the history is not smooth (a step of the adaptive integrator stops there)."""
        p = self.params
        if self.kind == "half_sine":
            return [p[2], p[2] + p[1]]
        if self.kind == "burst":
            return [p[2], p[2] + p[3] / p[1]]
        if self.kind == "table":
            return list(np.asarray(self.times, float))
        if self.kind in ("harmonic", "chirp"):
            out = [p[2], p[2] + p[3]]
            if p[5] > 0:  # the ends of the ramps: the second derivative jumps
                out += [p[2] + p[5] / p[1], p[2] + p[3] - p[5] / p[1]]
            return [t for t in out if math.isfinite(t)]
        return []

    @property
    def top_frequency(self) -> float:
        """The highest frequency of a periodic history [Hz] (0 for the others)."""
        p = self.params
        if self.kind in ("burst", "harmonic"):
            return p[1]
        if self.kind == "chirp":
            return max(p[1], p[4])
        return 0.0

    def impulse(self) -> float:
        """Time integral of F over its support (inf for a constant force)."""
        p = self.params
        if self.kind == "half_sine":
            return 2.0 * p[0] * p[1] / math.pi
        if self.kind == "burst":  # int_0^(c/f) A sin(2 pi f s) ds
            return p[0] * (1.0 - math.cos(2.0 * math.pi * p[3])) / (2.0 * math.pi * p[1])
        if self.kind == "table":
            return float(np.trapezoid(self.values, self.times))
        return math.inf  # constant, or a drive without an analytic integral

    def peak_impulse(self) -> float:
        """The largest |int_0^t F| over t: the most momentum the load can give a free body at any
        instant (inf for a constant force). Bounds the speed it imparts, for the safe step."""
        p = self.params
        if self.kind == "half_sine":
            return abs(2.0 * p[0] * p[1] / math.pi)
        if self.kind == "burst":  # half a period of push, or less for a shorter burst
            c = min(p[3], 0.5)
            return abs(p[0]) * (1.0 - math.cos(2.0 * math.pi * c)) / (2.0 * math.pi * p[1])
        if self.kind == "table":
            if len(self.times) < 2:
                return 0.0
            steps = 0.5 * (self.values[1:] + self.values[:-1]) * np.diff(self.times)
            return float(np.max(np.abs(np.concatenate([[0.0], np.cumsum(steps)]))))
        if self.kind in ("harmonic", "chirp"):
            # |int A r(s) sin(phase(s)) ds| over half a period of the lowest frequency, at most
            f_low = p[1] if self.kind == "harmonic" else min(p[1], p[4])
            return abs(p[0]) / (math.pi * f_low)
        return math.inf

    def peak(self) -> float:
        if self.kind == "table":
            return float(np.max(np.abs(self.values))) if len(self.values) else 0.0
        return abs(self.params[0])


def half_sine(fmax: float, tau: float, t0: float = 0.0) -> LoadHistory:
    """F(t) = fmax sin(pi (t - t0) / tau) for t0 <= t <= t0 + tau, else 0 (paper Fig. 3a)."""
    return LoadHistory("half_sine", (float(fmax), float(tau), float(t0)))


def harmonic_burst(amplitude: float, frequency: float, cycles: float, t0: float = 0.0) -> LoadHistory:
    """F(t) = amplitude sin(2 pi f (t - t0)) for `cycles` periods starting at t0."""
    return LoadHistory("burst", (float(amplitude), float(frequency), float(t0), float(cycles)))


def constant_force(value: float) -> LoadHistory:
    return LoadHistory("constant", (float(value),))


def harmonic(amplitude: float, frequency: float, t0: float = 0.0, duration: float = math.inf, phase: float = 0.0,
             ramp_cycles: float = 0.0) -> LoadHistory:
    """F(t) = amplitude r(s) sin(2 pi f s + phase), s = t - t0, for 0 <= s <= duration: a
    narrowband drive. The ramp r(s) = (1 - cos(pi s / T_r)) / 2 over the first T_r = ramp_cycles
    / f, and its mirror over the last T_r of a finite duration (1 between, or throughout when
    ramp_cycles = 0), starts and stops it without a jump in force or slope, which would excite
    every frequency."""
    return LoadHistory("harmonic", (float(amplitude), float(frequency), float(t0), float(duration), float(phase),
                                    float(ramp_cycles)))


def chirp(amplitude: float, f0: float, f1: float, duration: float, t0: float = 0.0, mode: str = "linear",
          ramp_cycles: float = 0.0) -> LoadHistory:
    """F(t) = amplitude r(s) sin(phi(s)) for 0 <= s = t - t0 <= duration, its frequency phi' / 2 pi
    sweeping from f0 to f1 linearly, phi = 2 pi (f0 s + (f1 - f0) s^2 / 2 D), or geometrically
    (mode "log"), phi = 2 pi f0 D (k^(s / D) - 1) / ln k with k = f1 / f0; r as in `harmonic` (up
    and down), its ramp_cycles counted at f0."""
    return LoadHistory("chirp", (float(amplitude), float(f0), float(t0), float(duration), float(f1), float(ramp_cycles),
                                 {"linear": 0.0, "log": 1.0}[mode]))


def tabulated(times, values) -> LoadHistory:
    """Piecewise-linear F(t) through (times, values); zero outside the table."""
    t = np.asarray(times, float)
    v = np.asarray(values, float)
    return LoadHistory("table", (), t, v)


@dataclass(frozen=True)
class WallDrive:
    """A rigid wall moved along its normal (into the granular side positive) as a shaker would:
    s(t) = amplitude r(tau) sin(2 pi f tau + phase), tau = t - t0, for 0 <= tau <= duration (the
    wall at rest before and after), r the drives' ramp (`granular.laws.ramp`, up and down)."""

    amplitude: float
    frequency: float
    t0: float = 0.0
    duration: float = math.inf
    phase: float = 0.0
    ramp_cycles: float = 0.0

    def params(self) -> tuple[float, ...]:
        """The compiled law's layout (`granular.laws.wall_motion`)."""
        return (float(self.amplitude), float(self.frequency), float(self.t0), float(self.duration), float(self.phase),
                float(self.ramp_cycles))

    def __call__(self, t: float) -> tuple[float, float]:
        """(s, ds/dt) at time t [m, m/s], by the compiled law the integrator uses
        (`granular.laws.wall_motion`)."""
        from .laws import wall_motion  # lazy: numba only where a wall's motion is evaluated

        s, v = wall_motion(np.array(self.params()), float(t))
        return float(s), float(v)

    def kinks(self) -> list[float]:
        """Where the motion is not smooth: its start and end, and the ends of its ramps."""
        out = [self.t0, self.t0 + self.duration]
        if self.ramp_cycles > 0:
            out += [self.t0 + self.ramp_cycles / self.frequency, self.t0 + self.duration - self.ramp_cycles / self.frequency]
        return [t for t in out if math.isfinite(t)]

    def peak_speed(self) -> float:
        """An upper bound of |ds/dt| [m/s]: 2 pi f A (1 + 1 / (2 ramp_cycles) while ramping)."""
        extra = 0.5 / self.ramp_cycles if self.ramp_cycles > 0 else 0.0
        return 2.0 * math.pi * self.frequency * abs(self.amplitude) * (1.0 + extra)
