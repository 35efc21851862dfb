"""Band measures of a transmissibility curve, from its values in dB on a frequency grid: a pass
band's level, its edge (the cut-off, EDGE below the level) and its 20 dB point (DROP below it),
and a second (optical) band beyond a gap, with the gap's mean attenuation. A crossing is
interpolated between grid points, or found on the curve itself when it is given as a function.
docs/narrowband.md ("Band measures") gives the definitions."""

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
    """The first pass band of the curve y_db [dB] on the grid f [Hz] (docs/narrowband.md, "Band
    measures")."""
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
    """The second pass band beyond `first`'s stop band, and the gap's attenuation
    (docs/narrowband.md, "Band measures")."""
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
