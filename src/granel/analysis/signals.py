"""Time-signal measures used to check the paper's statements from data: when a curve peaks,
and how fast a velocity trace oscillates (Fig. 3's "lower frequency content"); the transfer
spectrum of a transient, and the damped modes of a free response (a chain's cut-off).

All functions take sampled signals (t, s) on a uniform or near-uniform grid; `window` = (t0, t1)
restricts a measure to t0 <= t <= t1.
"""

from __future__ import annotations

from dataclasses import dataclass

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



def transfer_spectrum(t, out, inp, window=None, pad: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies [Hz], H(f)) with H = FFT(out) / FFT(inp): the transfer function of a system
    from a transient input (a force pulse) to a transient output (a velocity), both sampled on
    the same grid, zero-padded `pad` times. No taper: the record must hold the whole transient
    (start at rest, end decayed), else its cut end leaks into every bin. Where the input has no
    content (|FFT(inp)| below 1e-9 of its largest, e.g. at the zeros of a pulse's spectrum) H is
    NaN."""
    t_, y = _windowed(t, out, window)
    _, x = _windowed(t, inp, window)
    n = len(y)
    if n < 4:
        return np.zeros(0), np.zeros(0, complex)
    dt = (t_[-1] - t_[0]) / (n - 1)
    nfft = int(2 ** np.ceil(np.log2(pad * n)))
    Y, X = np.fft.rfft(y, nfft), np.fft.rfft(x, nfft)
    H = np.full(len(X), np.nan + 0j)
    ok = np.abs(X) > 1e-9 * np.abs(X).max(initial=0.0)
    H[ok] = Y[ok] / X[ok]
    return np.fft.rfftfreq(nfft, dt), H


@dataclass(frozen=True)
class DampedModes:
    """Damped oscillations found in a record by `damped_modes`, one per conjugate pair, in
    order of frequency. A mode is a e^(-zeta w t) cos(w sqrt(1 - zeta^2) t + phi) in each channel."""

    frequency: np.ndarray  # undamped natural frequency w / 2 pi = |s| / 2 pi [Hz]
    damped_frequency: np.ndarray  # Im(s) / 2 pi [Hz], the frequency of the oscillation itself
    damping_ratio: np.ndarray  # zeta = -Re(s) / |s|
    amplitude: np.ndarray  # (modes, channels): a at the window's start in each channel
    singular_values: np.ndarray  # of the stacked Hankel matrix, over the largest (the model order's
    # evidence; from the Gram matrix, so about 1e-8 is their floor of round-off)

    @property
    def strength(self) -> np.ndarray:
        """Each mode's amplitude over all channels (root of the sum of squares)."""
        return np.sqrt(np.sum(self.amplitude**2, axis=1))


def damped_modes(t, s, order: int, window=None, pencil: int | None = None) -> DampedModes:
    """The damped oscillations of a free response by the matrix pencil method (Hua & Sarkar,
    IEEE Trans. ASSP 38, 1990): s (samples, or samples x channels, on a uniform grid) is modelled
    as sum_k c_k z_k^n with `order` complex exponentials z_k = e^(s_k dt) shared by every channel;
    `pencil` is the Hankel matrices' column count (default a third of the samples). A real
    oscillation takes two exponentials, so N degrees of freedom need order >= 2N; a larger order
    absorbs a drift, an offset or weak harmonics.

    Returns the oscillating modes (Im s_k > 0) with their undamped natural frequency |s_k| / 2 pi,
    the undamped eigenfrequency exactly for damping proportional to the stiffness (a preloaded
    chain's linearised Tsuji damping). docs/analysis.md says why not a Fourier peak."""
    t = np.asarray(t, float)
    y = np.asarray(s, float)
    if y.ndim == 1:
        y = y[:, None]
    if y.ndim != 2 or y.shape[0] != len(t):
        raise ValueError(f"s must be samples or samples x channels with {len(t)} samples, got shape {np.shape(s)}")
    if window is not None:
        sel = (t >= window[0]) & (t <= window[1])
        t, y = t[sel], y[sel]
    n = len(t)
    order = int(order)
    if order < 1:
        raise ValueError(f"order must be at least 1, got {order}")
    if n < 3 * order + 2:
        raise ValueError(f"{n} samples cannot resolve {order} exponentials: give at least {3 * order + 2}")
    dt = (t[-1] - t[0]) / (n - 1)
    if not np.allclose(np.diff(t), dt, rtol=1e-6, atol=0.0):
        raise ValueError("damped_modes needs uniformly sampled data")
    L = int(pencil) if pencil is not None else n // 3
    L = min(max(L, order), n - order - 1)
    H = np.vstack([np.lib.stride_tricks.sliding_window_view(y[:, c], L + 1) for c in range(y.shape[1])])
    # the right singular vectors from the Gram matrix H'H (L + 1 square: much cheaper than the SVD
    # of the tall H; squaring the singular values costs nothing at the 1e-5 depth the modes span)
    ev, vecs = np.linalg.eigh(H.T @ H)
    ev, vecs = ev[::-1], vecs[:, ::-1]
    sv = np.sqrt(np.clip(ev, 0.0, None))
    if sv[0] == 0:
        raise ValueError("the signal is zero: no mode to find")
    V = vecs[:, :order]  # (L + 1, order): the signal space
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
    z = z[np.abs(z) > 0]
    sk = np.log(z) / dt
    # amplitudes at the window's start by least squares; exponents clipped against overflow
    expo = np.clip(np.outer(np.arange(n), np.log(z)).real, -700.0, 700.0) + 1j * np.outer(np.arange(n), np.angle(z))
    c, *_ = np.linalg.lstsq(np.exp(expo), y.astype(complex), rcond=None)
    keep = sk.imag > 0
    sk, c = sk[keep], c[keep]
    w = np.abs(sk)
    k = np.argsort(w)
    return DampedModes(frequency=w[k] / (2 * np.pi), damped_frequency=sk.imag[k] / (2 * np.pi),
                       damping_ratio=-sk.real[k] / w[k], amplitude=2.0 * np.abs(c[k]), singular_values=sv / sv[0])
