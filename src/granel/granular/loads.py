"""Load histories applied to granules, one class per kind, each carrying its own law's
parameters, description and bounds: half-sine shocks, harmonic bursts, tabulated forces,
constant forces (preloads), and narrowband drives (harmonic forces with a smooth ramp, chirps
sweeping a band). A shaker wall's motion (`WallDrive`) is here too.

The compiled integrator evaluates a history from its kind's code and `params()` (the layout
`laws.load_force` unpacks by name), so that it never calls back into Python.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .load_codes import (KIND_BURST, KIND_CHIRP, KIND_CONSTANT, KIND_HALF_SINE, KIND_HARMONIC,  # noqa: F401
                         KIND_TABLE, LOAD_PARAMS)

# The paper's three shock levels (Sec. III): half-sine pulses of 0.01 ms.
SHOCK_LEVELS = {"weak": 63.67, "moderate": 318.3, "strong": 1591.6}
PAPER_TAU = 1.0e-5
_NO_TABLE = np.zeros(0)


@dataclass(frozen=True)
class LoadHistory:
    """A scalar force history F(t) [N] (the direction is the `Excitation`'s). A kind sets `kind`
    (its scenario name), `code` (the compiled law's), `fields` (the scenario fields it reads),
    `required` (those it cannot do without, each with a hint) and `noun` (for their errors),
    `size_field` and `length_field` (the fields that set its size and its duration), and what
    differs from these defaults."""

    kind: ClassVar[str]
    code: ClassVar[int]
    fields: ClassVar[tuple[str, ...]]
    required: ClassVar[tuple[tuple[str, str], ...]] = ()
    noun: ClassVar[str] = ""
    size_field: ClassVar[str] = "amplitude"
    length_field: ClassVar[str] = "duration"
    static: ClassVar[bool] = False  # a preload, which a static equilibrium balances
    tabulated: ClassVar[bool] = False  # its values come from a file

    @classmethod
    def lacks(cls, get) -> str | None:
        """What a scenario's load of this kind lacks (`get(field)` gives a field's value or None),
        as an error message; None when it has all it needs."""
        for name, hint in cls.required:
            if get(name) is None:
                return f"{cls.noun} needs '{name}'{hint}"
        return None

    @classmethod
    def from_fields(cls, get, read_table=None) -> "LoadHistory":
        """The history from a scenario's fields (`get(field)`; `read_table()` reads a table)."""
        raise NotImplementedError

    @property
    def params(self) -> tuple[float, ...]:
        """The parameters in the compiled law's layout (`laws.load_force`)."""
        raise NotImplementedError

    @classmethod
    def from_params(cls, params, times=(), values=()) -> "LoadHistory":
        """The history from `params` (the layout of `params`, zero-padded) and a table."""
        raise NotImplementedError

    @property
    def times(self) -> np.ndarray:
        return _NO_TABLE

    @property
    def values(self) -> np.ndarray:
        return _NO_TABLE

    def __call__(self, t: float) -> float:
        """F(t) [N], by the compiled law the integrator uses (`granular.laws.load_force`)."""
        from .laws import load_force  # lazy: numba only where a load is evaluated

        params = np.zeros(LOAD_PARAMS)
        params[: len(self.params)] = self.params
        return float(load_force(self.code, params, np.asarray(self.times, float), np.asarray(self.values, float),
                                float(t)))

    @property
    def end_time(self) -> float:
        """Time after which the force is identically zero (inf if it never stops)."""
        return math.inf

    def kinks(self) -> list[float]:
        """Times where the history is not smooth (a step of the adaptive integrator stops there)."""
        return []

    @property
    def top_frequency(self) -> float:
        """The highest frequency of a periodic history [Hz] (0 for the others)."""
        return 0.0

    def step_bound(self) -> float:
        """The largest RK4 step that resolves the history [s]: 1/20 of its shortest period (inf
        for a history without one)."""
        return 1.0 / (self.top_frequency * 20.0) if self.top_frequency > 0 else math.inf

    def impulse(self) -> float:
        """Time integral of F over its support (inf for a constant force or a drive)."""
        return math.inf

    def peak_impulse(self) -> float:
        """The largest |int_0^t F| over t: the most momentum the load can give a free body at any
        instant (inf for a constant force). Bounds the speed it imparts, for the safe step."""
        return math.inf

    def peak(self) -> float:
        """The largest |F| [N]: the size of the history (its `size_field`)."""
        return abs(float(getattr(self, self.size_field)))

    def driving_time(self, duration: float) -> float:
        """How long, within a run of `duration`, a sustained drive pushes (0 for a transient)."""
        return 0.0

    @property
    def preload(self) -> float:
        """The force a static equilibrium balances (a static load's; 0 for the others) [N]."""
        return 0.0

    @property
    def shock_level(self) -> str | None:
        """The paper's shock level this history is (`SHOCK_LEVELS`), or None."""
        return None


@dataclass(frozen=True)
class HalfSine(LoadHistory):
    """F(t) = fmax sin(pi (t - t0) / tau) for t0 <= t <= t0 + tau, else 0 (the paper's shock, Fig. 3a)."""

    fmax: float
    tau: float
    t0: float = 0.0
    kind: ClassVar[str] = "half_sine"
    code: ClassVar[int] = KIND_HALF_SINE
    fields: ClassVar[tuple[str, ...]] = ("shock", "fmax", "tau", "t0")
    size_field: ClassVar[str] = "fmax"
    length_field: ClassVar[str] = "tau"

    @classmethod
    def lacks(cls, get):
        if get("fmax") is None and get("shock") is None:
            return "a half_sine needs 'fmax' [N] or 'shock' (weak | moderate | strong)"
        return None

    @classmethod
    def from_fields(cls, get, read_table=None):
        fmax = get("fmax") if get("fmax") is not None else SHOCK_LEVELS[get("shock")]
        return cls(float(fmax), float(get("tau")), float(get("t0")))

    @property
    def params(self):
        return (float(self.fmax), float(self.tau), float(self.t0))

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(*params[:3])

    @property
    def end_time(self):
        return self.tau + self.t0

    def kinks(self):
        return [self.t0, self.t0 + self.tau]

    def step_bound(self):
        return self.tau / 10.0

    @property
    def shock_level(self):
        return next((k for k, f in SHOCK_LEVELS.items() if f == self.fmax and self.tau == PAPER_TAU), None)

    def impulse(self):
        return 2.0 * self.fmax * self.tau / math.pi

    def peak_impulse(self):
        return abs(2.0 * self.fmax * self.tau / math.pi)


@dataclass(frozen=True)
class Burst(LoadHistory):
    """F(t) = amplitude sin(2 pi f (t - t0)) for `cycles` periods from t0."""

    amplitude: float
    frequency: float
    t0: float = 0.0
    cycles: float = 1.0
    kind: ClassVar[str] = "burst"
    code: ClassVar[int] = KIND_BURST
    fields: ClassVar[tuple[str, ...]] = ("amplitude", "frequency", "cycles", "t0")
    required: ClassVar[tuple[tuple[str, str], ...]] = (("amplitude", ""), ("frequency", ""), ("cycles", ""))
    noun: ClassVar[str] = "a burst"
    length_field: ClassVar[str] = "cycles"

    @classmethod
    def from_fields(cls, get, read_table=None):
        return cls(float(get("amplitude")), float(get("frequency")), float(get("t0")), float(get("cycles")))

    @property
    def params(self):
        return (float(self.amplitude), float(self.frequency), float(self.t0), float(self.cycles))

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(*params[:4])

    @property
    def end_time(self):
        return self.t0 + self.cycles / self.frequency

    def kinks(self):
        return [self.t0, self.t0 + self.cycles / self.frequency]

    @property
    def top_frequency(self):
        return self.frequency

    def impulse(self):  # int_0^(c/f) A sin(2 pi f s) ds
        return self.amplitude * (1.0 - math.cos(2.0 * math.pi * self.cycles)) / (2.0 * math.pi * self.frequency)

    def peak_impulse(self):  # half a period of push, or less for a shorter burst
        c = min(self.cycles, 0.5)
        return abs(self.amplitude) * (1.0 - math.cos(2.0 * math.pi * c)) / (2.0 * math.pi * self.frequency)


@dataclass(frozen=True, eq=False)
class Table(LoadHistory):
    """Piecewise-linear F(t) through (times, values); zero outside the table."""

    table_times: np.ndarray = field(default_factory=lambda: _NO_TABLE)
    table_values: np.ndarray = field(default_factory=lambda: _NO_TABLE)
    kind: ClassVar[str] = "table"
    code: ClassVar[int] = KIND_TABLE
    fields: ClassVar[tuple[str, ...]] = ("file",)
    required: ClassVar[tuple[tuple[str, str], ...]] = (("file", " (CSV of time,force)"),)
    noun: ClassVar[str] = "a table excitation"
    size_field: ClassVar[str] = "file"
    length_field: ClassVar[str] = "file"
    tabulated: ClassVar[bool] = True

    @classmethod
    def from_fields(cls, get, read_table=None):
        return read_table()

    @property
    def params(self):
        return ()

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(np.asarray(times, float), np.asarray(values, float))

    @property
    def times(self):
        return self.table_times

    @property
    def values(self):
        return self.table_values

    @property
    def end_time(self):
        return float(self.times[-1]) if self.values[-1] == 0 else math.inf

    def kinks(self):
        return list(np.asarray(self.times, float))

    def impulse(self):
        return float(np.trapezoid(self.values, self.times))

    def peak_impulse(self):
        if len(self.times) < 2:
            return 0.0
        steps = 0.5 * (self.values[1:] + self.values[:-1]) * np.diff(self.times)
        return float(np.max(np.abs(np.concatenate([[0.0], np.cumsum(steps)]))))

    def peak(self):
        return float(np.max(np.abs(self.values))) if len(self.values) else 0.0


@dataclass(frozen=True)
class Constant(LoadHistory):
    """A constant force F(t) = value: a preload."""

    value: float
    kind: ClassVar[str] = "constant"
    code: ClassVar[int] = KIND_CONSTANT
    fields: ClassVar[tuple[str, ...]] = ("value",)
    required: ClassVar[tuple[tuple[str, str], ...]] = (("value", " [N]"),)
    noun: ClassVar[str] = "a constant excitation"
    size_field: ClassVar[str] = "value"
    length_field: ClassVar[str] = "value"
    static: ClassVar[bool] = True

    @classmethod
    def from_fields(cls, get, read_table=None):
        return cls(float(get("value")))

    @property
    def params(self):
        return (float(self.value),)

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(params[0])

    @property
    def preload(self):
        return float(self.value)


def _drive_kinks(t0, duration, ramp) -> list[float]:
    """A drive's start and end and, with a ramp of `ramp` seconds, the ramps' ends (where the
    second derivative jumps)."""
    out = [t0, t0 + duration]
    if ramp > 0:
        out += [t0 + ramp, t0 + duration - ramp]
    return [t for t in out if math.isfinite(t)]


@dataclass(frozen=True)
class Harmonic(LoadHistory):
    """F(t) = amplitude r(s) sin(2 pi f s + phase), s = t - t0, for 0 <= s <= duration: a narrowband
    drive. The ramp r(s) = (1 - cos(pi s / T_r)) / 2 over the first T_r = ramp_cycles / f, and its
    mirror over the last T_r of a finite duration (1 between, or throughout when ramp_cycles = 0),
    starts and stops it without a jump in force or slope, which would excite every frequency."""

    amplitude: float
    frequency: float
    t0: float = 0.0
    duration: float = math.inf
    phase: float = 0.0
    ramp_cycles: float = 0.0
    kind: ClassVar[str] = "harmonic"
    code: ClassVar[int] = KIND_HARMONIC
    fields: ClassVar[tuple[str, ...]] = ("amplitude", "frequency", "phase", "ramp_cycles", "duration", "t0")
    required: ClassVar[tuple[tuple[str, str], ...]] = (("amplitude", ""), ("frequency", ""))
    noun: ClassVar[str] = "a harmonic excitation"

    @classmethod
    def from_fields(cls, get, read_table=None):
        return harmonic(get("amplitude"), get("frequency"), get("t0"), get("duration") or math.inf, get("phase"),
                        get("ramp_cycles"))

    @property
    def params(self):
        return (float(self.amplitude), float(self.frequency), float(self.t0), float(self.duration), float(self.phase),
                float(self.ramp_cycles))

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(*params[:6])

    @property
    def end_time(self):
        return self.t0 + self.duration

    def kinks(self):
        return _drive_kinks(self.t0, self.duration, self.ramp_cycles / self.frequency)

    @property
    def top_frequency(self):
        return self.frequency

    def peak_impulse(self):  # |int A r(s) sin(phase(s)) ds| over half a period, at most
        return abs(self.amplitude) / (math.pi * self.frequency)

    def driving_time(self, duration):
        return max(0.0, min(self.duration, duration - self.t0))


@dataclass(frozen=True)
class Chirp(LoadHistory):
    """F(t) = amplitude r(s) sin(phi(s)) for 0 <= s = t - t0 <= duration, its frequency phi' / 2 pi
    sweeping from f0 to f1 linearly, phi = 2 pi (f0 s + (f1 - f0) s^2 / 2 D), or geometrically
    (mode "log"), phi = 2 pi f0 D (k^(s / D) - 1) / ln k with k = f1 / f0; r as in `Harmonic` (up
    and down), its ramp_cycles counted at f0."""

    amplitude: float
    f0: float
    t0: float
    duration: float
    f1: float
    ramp_cycles: float = 0.0
    geometric: bool = False
    kind: ClassVar[str] = "chirp"
    code: ClassVar[int] = KIND_CHIRP
    fields: ClassVar[tuple[str, ...]] = ("amplitude", "f0", "f1", "duration", "mode", "ramp_cycles", "t0")
    required: ClassVar[tuple[tuple[str, str], ...]] = (("amplitude", ""), ("f0", ""), ("f1", ""), ("duration", ""))
    noun: ClassVar[str] = "a chirp"

    @classmethod
    def from_fields(cls, get, read_table=None):
        return chirp(get("amplitude"), get("f0"), get("f1"), get("duration"), get("t0"), get("mode"), get("ramp_cycles"))

    @property
    def params(self):
        return (float(self.amplitude), float(self.f0), float(self.t0), float(self.duration), float(self.f1),
                float(self.ramp_cycles), 1.0 if self.geometric else 0.0)

    @classmethod
    def from_params(cls, params, times=(), values=()):
        return cls(*params[:6], bool(params[6] > 0.5))

    @property
    def end_time(self):
        return self.t0 + self.duration

    def kinks(self):
        return _drive_kinks(self.t0, self.duration, self.ramp_cycles / self.f0)

    @property
    def top_frequency(self):
        return max(self.f0, self.f1)

    def peak_impulse(self):  # half a period of the lowest frequency, at most
        return abs(self.amplitude) / (math.pi * min(self.f0, self.f1))

    def driving_time(self, duration):
        return max(0.0, min(self.duration, duration - self.t0))


KINDS: dict[str, type[LoadHistory]] = {c.kind: c for c in (HalfSine, Burst, Table, Constant, Harmonic, Chirp)}


def load_history(kind: str, params=(), times=(), values=()) -> LoadHistory:
    """The history of `kind` from its compiled layout (a result's record); KeyError for an unknown kind."""
    return KINDS[kind].from_params(tuple(float(x) for x in params), times, values)


def half_sine(fmax: float, tau: float, t0: float = 0.0) -> HalfSine:
    return HalfSine(float(fmax), float(tau), float(t0))


def harmonic_burst(amplitude: float, frequency: float, cycles: float, t0: float = 0.0) -> Burst:
    return Burst(float(amplitude), float(frequency), float(t0), float(cycles))


def constant_force(value: float) -> Constant:
    return Constant(float(value))


def harmonic(amplitude: float, frequency: float, t0: float = 0.0, duration: float = math.inf, phase: float = 0.0,
             ramp_cycles: float = 0.0) -> Harmonic:
    return Harmonic(float(amplitude), float(frequency), float(t0), float(duration), float(phase), float(ramp_cycles))


def chirp(amplitude: float, f0: float, f1: float, duration: float, t0: float = 0.0, mode: str = "linear",
          ramp_cycles: float = 0.0) -> Chirp:
    return Chirp(amplitude=float(amplitude), f0=float(f0), t0=float(t0), duration=float(duration), f1=float(f1),
                 ramp_cycles=float(ramp_cycles), geometric={"linear": False, "log": True}[mode])


def tabulated(times, values) -> Table:
    return Table(np.asarray(times, float), np.asarray(values, float))


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
        return _drive_kinks(self.t0, self.duration, self.ramp_cycles / self.frequency if self.ramp_cycles > 0 else 0.0)

    def peak_speed(self) -> float:
        """An upper bound of |ds/dt| [m/s]: 2 pi f A (1 + 1 / (2 ramp_cycles) while ramping)."""
        extra = 0.5 / self.ramp_cycles if self.ramp_cycles > 0 else 0.0
        return 2.0 * math.pi * self.frequency * abs(self.amplitude) * (1.0 + extra)
