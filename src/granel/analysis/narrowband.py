"""Measures of a narrowband (harmonic) response: when it is steady, its amplitudes at the drive
frequency, its harmonics and subharmonics, the period it locks to, and transmissibility and
nonreciprocity.

Signals are sampled on the outputs (t, s). Amplitudes come from a least-squares fit of
c0 + sum_k (a_k cos 2 pi f_k t + b_k sin 2 pi f_k t) over a whole number of the longest period
fitted (a lock-in amplifier's measure: exact for a signal made of those frequencies, and blind to
the others when the window holds whole periods of them). A response is steady when successive
drive periods repeat; it locks to m drive periods when s(t + m T) = s(t) there.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from fractions import Fraction

import numpy as np


@dataclass(frozen=True)
class Drive:
    """A harmonic drive of a run: granule label, frequency [Hz], force amplitude [N], start t0."""

    granule: str
    frequency: float
    amplitude: float
    t0: float


def drive_of(ds) -> Drive:
    """The (first) harmonic excitation of a result Dataset, from its scenario."""
    sc = tomllib.loads(ds.attrs["scenario"])
    for e in sc.get("excitations", []):
        if e.get("kind") == "harmonic":
            return Drive(e["granule"], float(e["frequency"]), float(e["amplitude"]), float(e.get("t0", 0.0)))
    raise ValueError("the run has no harmonic excitation")


def lock_in(t, s, frequencies, window=None) -> np.ndarray:
    """Complex amplitudes A_k (s ~ c0 + sum Re(A_k e^(2 pi i f_k t))) at `frequencies` by least
    squares over `window` = (t0, t1) (all samples by default); |A_k| is the amplitude."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    if window is not None:
        sel = (t >= window[0] - 1e-12 * abs(window[0])) & (t <= window[1] + 1e-12 * abs(window[1]))
        t, s = t[sel], s[sel]
    f = np.atleast_1d(np.asarray(frequencies, float))
    w = 2 * np.pi * f[None, :] * t[:, None]
    M = np.column_stack([np.ones_like(t), np.cos(w), np.sin(w)])
    c, *_ = np.linalg.lstsq(M, s, rcond=None)
    return c[1: 1 + len(f)] - 1j * c[1 + len(f):]


def steady_window(t, s, period: float, rtol: float = 1e-2, periods: int = 3) -> tuple[float, float] | None:
    """The latest stretch of whole periods at the end of the record over which the response is
    steady: from the first time after which each period's waveform differs from the one before
    by less than `rtol` (RMS of the difference over the RMS of the period) for the rest of the
    record. None if the last `periods` periods are not steady or the record is too short."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    n = int(math.floor((t[-1] - t[0]) / period + 1e-9))
    if n < periods + 1:
        return None
    ends = t[-1] - period * np.arange(n + 1)[::-1]  # period boundaries counted back from the end
    grid = np.linspace(0.0, period, 64, endpoint=False)
    waves = np.array([np.interp(a + grid, t, s) for a in ends[:-1]])
    diff = np.sqrt(np.mean(np.diff(waves, axis=0) ** 2, axis=1))
    size = np.sqrt(np.mean(waves[1:] ** 2, axis=1))
    ok = diff <= rtol * np.maximum(size, 1e-300)
    if not ok[-periods:].all():
        return None
    first = len(ok) - int(np.argmin(ok[::-1])) if not ok.all() else 0
    return float(ends[first]), float(t[-1])


def response_period(t, s, period: float, max_multiple: int = 8, rtol: float = 1e-2, window=None) -> int:
    """The smallest m <= max_multiple with s(t + m T) = s(t) within `rtol` (RMS over the RMS of
    s) over `window` (by default the record after its first 2 max_multiple periods): the response
    locks to m drive periods (1: at the drive period; 2: a period-doubled response). 0 when none
    does (quasi-periodic or chaotic)."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    lo, hi = window if window is not None else (t[0] + 2 * max_multiple * period, t[-1])
    for m in range(1, max_multiple + 1):
        a = max(lo, t[0])
        b = hi - m * period
        if b - a < m * period:
            break
        grid = np.linspace(a, b, 400)
        x, y = np.interp(grid, t, s), np.interp(grid + m * period, t, s)
        if np.sqrt(np.mean((y - x) ** 2)) <= rtol * max(np.sqrt(np.mean(x * x)), 1e-300):
            return m
    return 0


def harmonic_amplitudes(t, s, frequency: float, orders=(1, 2, 3), subharmonics=(2, 3), window=None) -> dict:
    """Amplitudes of s at k f (k in `orders`) and at f / m (m in `subharmonics`), fitted together
    over a whole number of periods of the slowest of them ending at the window's end (`window`
    defaults to the whole record). Keys: 'f', '2f', ..., 'f/2', ..."""
    t = np.asarray(t, float)
    lo, hi = window if window is not None else (t[0], t[-1])
    ks = [Fraction(k) for k in orders] + [Fraction(1, m) for m in subharmonics]
    longest = max(1 / (float(k) * frequency) for k in ks)
    span = math.floor((hi - lo) / longest + 1e-9) * longest
    if span <= 0:
        raise ValueError(f"the window ({hi - lo:.3e} s) is shorter than the longest period fitted ({longest:.3e} s)")
    A = lock_in(t, s, [float(k) * frequency for k in ks], (hi - span, hi))
    names = [("f" if k == 1 else f"{k}f") if k.denominator == 1 else f"f/{k.denominator}" for k in ks]
    return {n: float(abs(a)) for n, a in zip(names, A)}


def transmissibility(measured_amplitude: float, driven_amplitude: float) -> float:
    """The measured response's amplitude at the drive frequency over the driven one's (e.g. the
    far wall's force over the drive's force, or a far granule's velocity over the driven one's)."""
    return float(measured_amplitude / driven_amplitude) if driven_amplitude else float("nan")


def nonreciprocity_db(forward, backward):
    """20 log10 of forward over backward transmissibility [dB] (0: reciprocal)."""
    return 20.0 * np.log10(np.asarray(forward, float) / np.asarray(backward, float))
