"""Band measures of a transmissibility curve: where a pass band ends, its 20 dB point, and a
second (optical) band beyond a gap, read from the curve's values in dB on a frequency grid.

Definitions (docs/narrowband.md, "Band measures"), for y_k = 20 log10 T(f_k), f ascending:
- the stop band starts at the first f_s whose y lies more than DROP (20 dB) below the mean of
  the y before it and falls on to the next frequency (a dip between two resonances rises again);
  the pass band is the frequencies below f_s, and its level L the mean of their y [dB];
- its edge (the cut-off) is where y last falls through L - EDGE (3 dB: half the power of the
  pass band's level) at or before f_s;
- its 20 dB point is where y last falls through L - DROP at or before f_s;
- a second band above it: the highest y beyond f_s, if it rises at least DROP out of the gap's
  floor (the lowest y between); the band is the run of frequencies around that peak above the
  half-way level (in dB) between the floor and the peak; its level L2 is their mean; its bottom
  is where y first rises through L2 - EDGE above f_s, its top where y last falls through it;
- the gap's mean attenuation: L less the mean of y over the grid frequencies strictly between
  the first band's edge and the second band's bottom.
A crossing between two grid points is placed by linear interpolation of y in f, or, given the
curve as a function (`curve`), by the last root of y(f) - level in that interval, found on a
fine grid of REFINE points and then by Brent's method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

DROP = 20.0  # [dB]
EDGE = 3.0  # [dB] a band's edge lies this far below its level
REFINE = 200  # fine points per grid interval when the curve is given


@dataclass(frozen=True)
class PassBand:
    """The first pass band of a curve: its level L [dB], its edge (cut-off) and 20 dB point [Hz],
    the grid interval each lies in [Hz], and the index of the first grid point of its stop band.
    NaN edges when the curve never falls DROP below the mean of the frequencies before."""

    level_db: float
    edge_hz: float
    db20_hz: float
    edge_interval: tuple[float, float]
    db20_interval: tuple[float, float]
    stop: int


@dataclass(frozen=True)
class SecondBand:
    """A second pass band beyond the first one's stop band: its level [dB], bottom and top [Hz]
    with their grid intervals, and the gap's mean attenuation below the first band's level [dB].
    NaN where the curve does not show it (no rise of DROP out of the gap, no fall at its top, no
    grid point inside the gap)."""

    level_db: float
    bottom_hz: float
    top_hz: float
    bottom_interval: tuple[float, float]
    top_interval: tuple[float, float]
    gap_attenuation_db: float


NAN_INTERVAL = (math.nan, math.nan)


def to_db(values) -> np.ndarray:
    """20 log10 of magnitudes (NaN for zero or NaN)."""
    v = np.asarray(values, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 20.0 * np.log10(np.where(v > 0, v, np.nan))


def _crossing(f, y, j: int, level: float, curve=None) -> float:
    """Where the curve crosses `level` between grid points j - 1 and j (y on either side of it):
    linear interpolation of y, or the last root of curve(f) - level there (`curve` in dB)."""
    a, b = float(f[j - 1]), float(f[j])
    if curve is None:
        return a + (level - y[j - 1]) * (b - a) / (y[j] - y[j - 1])
    fine = np.linspace(a, b, REFINE + 1)
    g = np.array([curve(x) for x in fine]) - level
    flips = np.flatnonzero(np.sign(g[:-1]) * np.sign(g[1:]) <= 0)
    k = int(flips[-1])
    if g[k] == 0.0:
        return float(fine[k])
    return float(brentq(lambda x: curve(x) - level, fine[k], fine[k + 1], xtol=1e-12 * b, rtol=1e-15))


def _last_fall(y, level: float, upto: int) -> int:
    """The largest j <= upto with y[j - 1] >= level > y[j] (the last fall through `level`)."""
    return max(j for j in range(1, upto + 1) if y[j - 1] >= level > y[j])


def pass_band(f, y_db, curve=None) -> PassBand:
    """The first pass band of the curve y_db [dB] on the grid f [Hz] (module docstring)."""
    f, y = np.asarray(f, float), np.asarray(y_db, float)
    s = next((k for k in range(1, len(y)) if y[k] < np.mean(y[:k]) - DROP and (k == len(y) - 1 or y[k + 1] < y[k])),
             None)
    if s is None or not np.isfinite(y[:s + 1]).all():
        level = float(np.mean(y)) if np.isfinite(y).all() else math.nan
        return PassBand(level, math.nan, math.nan, NAN_INTERVAL, NAN_INTERVAL, len(y))
    level = float(np.mean(y[:s]))
    j, k = _last_fall(y, level - EDGE, s), _last_fall(y, level - DROP, s)
    return PassBand(level, _crossing(f, y, j, level - EDGE, curve), _crossing(f, y, k, level - DROP, curve),
                    (float(f[j - 1]), float(f[j])), (float(f[k - 1]), float(f[k])), s)


def second_band(f, y_db, first: PassBand, curve=None) -> SecondBand:
    """The second pass band beyond `first`'s stop band, and the gap's attenuation (module
    docstring)."""
    f, y = np.asarray(f, float), np.asarray(y_db, float)
    none = SecondBand(math.nan, math.nan, math.nan, NAN_INTERVAL, NAN_INTERVAL, math.nan)
    s = first.stop
    if s >= len(y) - 1 or not np.isfinite(y[s:]).all():
        return none
    p = s + int(np.argmax(y[s:]))
    floor = float(np.min(y[s:p + 1]))
    if y[p] - floor < DROP:
        return none
    half = 0.5 * (y[p] + floor)
    lo = p
    while lo > s and y[lo - 1] > half:
        lo -= 1
    hi = p
    while hi < len(y) - 1 and y[hi + 1] > half:
        hi += 1
    level = float(np.mean(y[lo:hi + 1]))
    edge = level - EDGE
    up = min(k for k in range(s + 1, p + 1) if y[k - 1] < edge <= y[k])
    bottom = _crossing(f, y, up, edge, curve)
    downs = [k for k in range(p + 1, len(y)) if y[k - 1] >= edge > y[k]]
    top, top_iv = (_crossing(f, y, downs[-1], edge, curve), (float(f[downs[-1] - 1]), float(f[downs[-1]]))) \
        if downs else (math.nan, NAN_INTERVAL)
    inside = (f > first.edge_hz) & (f < bottom)
    gap = first.level_db - float(np.mean(y[inside])) if inside.any() else math.nan
    return SecondBand(level, bottom, top, (float(f[up - 1]), float(f[up])), top_iv, gap)
