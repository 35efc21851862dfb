"""Time-signal measures used to check the paper's statements from data: when a curve peaks,
and how fast a velocity trace oscillates (Fig. 3's "lower frequency content").

All functions take sampled signals (t, s) on a uniform or near-uniform grid; `window` = (t0, t1)
restricts a measure to t0 <= t <= t1.
"""

from __future__ import annotations

import numpy as np


def _windowed(t, s, window):
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    if window is None:
        return t, s
    sel = (t >= window[0]) & (t <= window[1])
    return t[sel], s[sel]


def peak_time(t, s) -> tuple[float, float]:
    """(time, value) of the maximum of s, refined by the parabola through the largest sample
    and its two neighbours (exact for a locally quadratic peak)."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    k = int(np.argmax(s))
    if k == 0 or k == len(s) - 1:
        return float(t[k]), float(s[k])
    y0, y1, y2 = s[k - 1], s[k], s[k + 1]
    den = y0 - 2.0 * y1 + y2
    if den >= 0.0:  # flat top: no refinement
        return float(t[k]), float(y1)
    x = 0.5 * (y0 - y2) / den  # vertex offset in samples, in [-1/2, 1/2]
    h = 0.5 * (t[k + 1] - t[k - 1])
    return float(t[k] + x * h), float(y1 - 0.25 * (y0 - y2) * x)


def zero_crossing_frequency(t, s, window=None) -> float:
    """Mean oscillation frequency from the crossings of the signal's mean [Hz]: 1 / the mean of
    the full periods between every other crossing, so that a mean that differs from the
    oscillation's centre does not bias it (exact for a finely sampled sine). With only two
    crossings, from the half period between them; NaN with fewer."""
    t, s = _windowed(t, s, window)
    x = s - s.mean() if len(s) else s
    k = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:]))
    if len(k) < 2:
        return float("nan")
    tc = t[k] - x[k] * (t[k + 1] - t[k]) / (x[k + 1] - x[k])  # crossing instants, linear interpolation
    if len(tc) == 2:
        return float(0.5 / (tc[1] - tc[0]))
    return float(1.0 / np.mean(tc[2:] - tc[:-2]))


def amplitude_spectrum(t, s, window=None, pad: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies [Hz], |S(f)|) of the mean-removed, Hann-windowed signal, zero-padded `pad`
    times for a finely sampled spectrum. Normalised so that a sine of amplitude a peaks at a."""
    t, s = _windowed(t, s, window)
    n = len(s)
    if n < 4:
        return np.zeros(0), np.zeros(0)
    dt = (t[-1] - t[0]) / (n - 1)
    w = np.hanning(n)
    x = (s - s.mean()) * w
    nfft = int(2 ** np.ceil(np.log2(pad * n)))
    S = np.abs(np.fft.rfft(x, nfft)) * 2.0 / w.sum()
    return np.fft.rfftfreq(nfft, dt), S


def dominant_frequency(t, s, window=None, pad: int = 8) -> float:
    """Frequency of the largest peak of `amplitude_spectrum` (0 excluded), interpolated between
    bins [Hz]."""
    return spectrum_peak(*amplitude_spectrum(t, s, window, pad))


def spectrum_peak(f, S) -> float:
    """Frequency of the largest peak of a spectrum (f, |S|) from `amplitude_spectrum` (0
    excluded), interpolated between bins [Hz]."""
    if len(S) < 2 or S[1:].max() <= 0:
        return float("nan")
    k = 1 + int(np.argmax(S[1:]))
    if k + 1 >= len(S):
        return float(f[k])
    # vertex of the parabola through the log-magnitudes around the peak bin
    fk, _ = peak_time(f[k - 1 : k + 2], np.log(np.maximum(S[k - 1 : k + 2], 1e-300)))
    return fk


def spectral_centroid(f, S) -> float:
    """Power-weighted mean frequency sum f |S|^2 / sum |S|^2 [Hz]."""
    p = np.asarray(S, float) ** 2
    return float(np.sum(np.asarray(f) * p) / p.sum()) if p.sum() > 0 else float("nan")


def peak_width(t, s) -> float:
    """Full width at half maximum of the largest peak of s (crossings interpolated linearly);
    a side that never falls to half is cut at the end of the record."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    k = int(np.argmax(s))
    half = 0.5 * s[k]
    a = k
    while a > 0 and s[a] > half:
        a -= 1
    b = k
    while b < len(s) - 1 and s[b] > half:
        b += 1
    ta = t[a] if s[a] > half or a == k else t[a] + (half - s[a]) * (t[a + 1] - t[a]) / (s[a + 1] - s[a])
    tb = t[b] if s[b] > half or b == k else t[b - 1] + (s[b - 1] - half) * (t[b] - t[b - 1]) / (s[b - 1] - s[b])
    return float(tb - ta)
