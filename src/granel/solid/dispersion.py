"""Analytic dispersion of the solids' waves, independent of their finite-element models: the
Rayleigh-Lamb branches of the plate as a plane-stress strip (`rayleigh_lamb`, `lamb_frequencies`;
the bulk speeds from eq. 7, `plane_stress_speeds`) and the beam's Euler-Bernoulli branch of
eq. (9) (`euler_bernoulli_frequency`). docs/wavefield.md ("Analytic branches") gives the
equations and how their roots are found."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FAMILIES = ("symmetric", "antisymmetric")
# points per pi of q h/2 and of p h/2 in the scan for sign changes (`_scan_grid`)
SCAN_PER_PI = 64
# relative accuracy of the roots in frequency (the bisection's final width)
ROOT_RTOL = 1e-12


@dataclass(frozen=True)
class WaveSpeeds:
    """The bulk speeds [m/s] of a 2-D elastic medium: dilatational c_p and shear c_s."""

    c_p: float
    c_s: float

    def __iter__(self):
        return iter((self.c_p, self.c_s))


def plane_stress_speeds(E: float, nu: float, rho: float) -> WaveSpeeds:
    """The in-plane bulk speeds of a plane-stress sheet: c_p = sqrt(E / (rho (1 - nu^2))), from
    lam' + 2 mu with the plane-stress lam' = E nu / (1 - nu^2) (eq. 7), and c_s = sqrt(E / (2 rho
    (1 + nu)))."""
    if not (E > 0 and rho > 0 and -1 < nu < 0.5):
        raise ValueError(f"plane_stress_speeds: need E > 0, rho > 0 and -1 < nu < 1/2 (got {E}, {rho}, {nu})")
    return WaveSpeeds(math.sqrt(E / (rho * (1 - nu**2))), math.sqrt(E / (2 * rho * (1 + nu))))


def _cos_even(s):
    """cos(x) for x^2 = s, scaled by exp(-|x|) where x is imaginary (cosh)."""
    s = np.asarray(s, float)
    r = np.sqrt(np.abs(s))
    return np.where(s >= 0, np.cos(r), 0.5 * (1 + np.exp(-2 * r)))


def _sinc_even(s):
    """sin(x) / x for x^2 = s, scaled by exp(-|x|) where x is imaginary (sinh(y) / y)."""
    s = np.asarray(s, float)
    r = np.sqrt(np.abs(s))
    safe = np.where(r > 0, r, 1.0)
    return np.where(r == 0, 1.0, np.where(s > 0, np.sin(r), -0.5 * np.expm1(-2 * r)) / safe)


def _shc_difference(d, s):
    """exp(-s) (sinh(d)/d - sinh(s)/s) for 0 <= d <= s, without the cancellation of small
    arguments: below s = 1/2 the series sum_n (d^2n - s^2n) / (2n+1)! with d^2n - s^2n =
    (d^2 - s^2) sum_j d^2j s^2(n-1-j)."""
    d, s = np.broadcast_arrays(np.asarray(d, float), np.asarray(s, float))
    safe_d = np.where(d > 0, d, 1.0)
    small = np.minimum(d, 1.0)  # sinh(d) / d, accurate as d -> 0, or (e^(d-s) - e^(-d-s)) / 2d, finite for large d
    shc_d = np.where(d < 1, np.where(d > 0, np.sinh(small) / np.where(d > 0, small, 1.0), 1.0) * np.exp(-s),
                     0.5 * (np.exp(d - s) - np.exp(-d - s)) / safe_d)
    direct = shc_d + 0.5 * np.expm1(-2 * s) / s
    d2, s2 = d * d, s * s
    total, inner, fact = np.zeros_like(s), np.ones_like(s), 6.0  # inner: sum_j d^2j s^2(n-1-j), n = 1
    for n in range(1, 12):
        total = total + inner / fact
        inner = inner * s2 + d2**n
        fact *= (2 * n + 2) * (2 * n + 3)
    return np.where(s > 0.5, direct, (d2 - s2) * total * np.exp(-s))


def _cross(K2, P2, S2):
    """D = sin(X)/X cos(Y) - cos(X) sin(Y)/Y for X^2 = P2 - K2, Y^2 = S2 - K2, scaled as
    `rayleigh_lamb`. It vanishes at X = Y (w = 0); where both are imaginary, X = i x, Y = i y
    (the lowest branches' region), D = [s sinh(d) - d sinh(s)] / (2 x y) with s = x + y and
    d = x - y = (S2 - P2) / s, which keeps its accuracy as w -> 0."""
    X2, Y2 = P2 - K2, S2 - K2
    both = (X2 < 0) & (Y2 < 0)
    x, y = np.sqrt(np.where(both, -X2, 1.0)), np.sqrt(np.where(both, -Y2, 1.0))
    s = x + y
    d = np.where(both, (S2 - P2) / s, 0.0)
    stable = 0.5 * s * d * _shc_difference(np.abs(d), s) / (x * y)
    return np.where(both, stable, _sinc_even(X2) * _cos_even(Y2) - _cos_even(X2) * _sinc_even(Y2))


def _terms(omega, k, h: float, speeds: WaveSpeeds, family: str) -> tuple[np.ndarray, np.ndarray]:
    """The two terms of `rayleigh_lamb`, whose sum it is (arrays that broadcast)."""
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    c_p, c_s = speeds
    half = 0.5 * h
    K2 = (np.asarray(k, float) * half) ** 2
    P2, S2 = (np.asarray(omega, float) * half / c_p) ** 2, (np.asarray(omega, float) * half / c_s) ** 2
    X2, Y2 = P2 - K2, S2 - K2
    D = _cross(K2, P2, S2)
    if family == "symmetric":
        return -4 * K2 * K2 * D, (S2 * S2 - 4 * K2 * S2) * _cos_even(X2) * _sinc_even(Y2) + \
            4 * K2 * P2 * _sinc_even(X2) * _cos_even(Y2)
    return 4 * K2 * (K2 - S2) * D, S2 * S2 * _sinc_even(X2) * _cos_even(Y2)


def rayleigh_lamb(omega, k, h: float, speeds: WaveSpeeds, family: str):
    """The Rayleigh-Lamb function of a layer of thickness h, zero on its `family`'s branches
    (angular frequencies `omega` and wavenumbers `k` broadcast): the family's equation multiplied
    out without poles, real and finite for real or imaginary p and q, each term scaled by
    exp(-|Im p| h/2 - |Im q| h/2) and arranged so that no two terms cancel near w = 0
    (docs/wavefield.md, "Analytic branches"). w = 0 is a root of both families for k > 0 (the
    rigid translation)."""
    a, b = _terms(omega, k, h, speeds, family)
    return a + b


# a value of `rayleigh_lamb` within this many roundings of its terms' size is taken for zero
# (too close to a root for its sign to be known)
NOISE = 64 * np.finfo(float).eps


def _scan_grid(k: float, h: float, speeds: WaveSpeeds, omega_max: float) -> np.ndarray:
    """Angular frequencies (0, omega_max] to scan at wavenumber k for sign changes: SCAN_PER_PI
    points per pi of q h/2 above the shear line w = c_s k and of p h/2 above w = c_p k (the
    functions' arguments advance by about pi/2 between roots), and phase speeds from 1e-9 c_s to
    c_p (geometric to c_s / 100, then even): only the lowest branch of each family has a phase
    speed below c_s, and S0 one between c_s and its plate speed."""
    c_p, c_s = speeds
    step = math.pi / SCAN_PER_PI * 2 / h
    parts = []
    for c in (c_s, c_p):
        if omega_max > c * k:
            n = int(math.ceil(math.sqrt((omega_max / c) ** 2 - k * k) / step)) + 1
            parts.append(c * np.sqrt(k * k + (step * np.arange(1, n + 1)) ** 2))
    if k > 0:
        phase = np.concatenate([c_s * np.geomspace(1e-9, 1e-2, 200), np.linspace(1e-2 * c_s, c_p, 8 * SCAN_PER_PI)])
        parts.append(k * phase)
    grid = np.unique(np.concatenate(parts))
    return grid[(grid > 0) & (grid <= omega_max)]


def _brackets(k: float, h: float, speeds: WaveSpeeds, family: str, count: int) -> np.ndarray:
    """(count, 2) intervals of angular frequency, each holding one of the `count` lowest positive
    roots of `family` at wavenumber k (fewer rows if there are fewer): sign changes on
    `_scan_grid` of the values whose sign is sure (`NOISE`); the window grows until it holds
    `count` of them."""
    c_p = speeds.c_p
    omega_max = c_p * math.hypot(k, (count + 1) * math.pi / h)
    for _ in range(30):
        grid = _scan_grid(k, h, speeds, omega_max)
        a, b = _terms(grid, k, h, speeds, family)
        values = a + b
        sure = np.abs(values) > NOISE * (np.abs(a) + np.abs(b))
        grid, values = grid[sure], values[sure]
        change = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
        if len(change) >= count:
            break
        omega_max *= 2
    change = change[:count]
    return np.column_stack([grid[change], grid[change + 1]])


def _bisect(lo, hi, k, h: float, speeds: WaveSpeeds, family: str) -> np.ndarray:
    """The roots of `rayleigh_lamb` in the intervals [lo, hi] (one sign change each), at their
    wavenumbers k, by bisection of all at once to the relative width ROOT_RTOL."""
    lo, hi = np.array(lo, float), np.array(hi, float)
    f_lo = np.sign(rayleigh_lamb(lo, k, h, speeds, family))
    for _ in range(200):
        if not np.any(hi - lo > ROOT_RTOL * hi):
            break
        mid = 0.5 * (lo + hi)
        same = np.sign(rayleigh_lamb(mid, k, h, speeds, family)) == f_lo
        lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
    return 0.5 * (lo + hi)


def lamb_frequencies(k, h: float, speeds: WaveSpeeds, family: str, count: int = 3) -> np.ndarray:
    """Frequencies f_n(k) [Hz] of the `count` lowest Rayleigh-Lamb branches of `family`
    ("symmetric": S0, S1, ...; "antisymmetric": A0, A1, ...), shape (count, len(k)), at
    wavenumbers k [rad/m] >= 0, of a layer of thickness h [m] with bulk speeds `speeds`: the
    roots of `rayleigh_lamb` in frequency, to relative accuracy ROOT_RTOL. At k = 0, row 0 is 0
    (A0 and S0 start there) and row n >= 1 the family's n-th cut-off frequency."""
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    k = np.atleast_1d(np.asarray(k, float))
    if not (h > 0 and np.all(np.isfinite(k)) and np.all(k >= 0) and count >= 1):
        raise ValueError("lamb_frequencies: need h > 0, finite wavenumbers k >= 0 and count >= 1")
    out = np.full((count, len(k)), np.nan)
    rows, cols, brackets = [], [], []
    for j, kj in enumerate(k):
        b = _brackets(float(kj), h, speeds, family, count)
        rows += range(len(b))
        cols += [j] * len(b)
        brackets.append(b)
    b = np.vstack(brackets)
    out[rows, cols] = _bisect(b[:, 0], b[:, 1], k[cols], h, speeds, family) / (2 * math.pi)
    if np.any(k == 0):  # the scan finds only the cut-offs at k = 0: the lowest branch's 0 goes first
        j = np.flatnonzero(k == 0)
        out[:, j] = np.vstack([np.full((1, len(j)), 0.0), out[:-1, j]])
    return out


@dataclass(frozen=True)
class LambBranches:
    """Rayleigh-Lamb branches of a layer: wavenumbers k [rad/m] and frequencies [Hz] of the
    symmetric (S0, S1, ...) and antisymmetric (A0, A1, ...) families, (count, len(k)) each."""

    k: np.ndarray
    symmetric: np.ndarray
    antisymmetric: np.ndarray
    thickness: float
    speeds: WaveSpeeds


def lamb_branches(k, h: float, speeds: WaveSpeeds, count: int = 3) -> LambBranches:
    """Both families' `count` lowest branches at wavenumbers k (`lamb_frequencies`)."""
    k = np.atleast_1d(np.asarray(k, float))
    return LambBranches(k, lamb_frequencies(k, h, speeds, "symmetric", count),
                        lamb_frequencies(k, h, speeds, "antisymmetric", count), float(h), speeds)


def string_frequency(k, tension: float, rho_A: float, EI: float = 0.0, foundation: float = 0.0) -> np.ndarray:
    """The transverse branch of a string under tension T (a tensioned beam if EI > 0) on a
    foundation of stiffness k_f per length: rho A w^2 = T k^2 + EI k^4 + k_f, f = w / (2 pi) [Hz];
    k_f cuts it on at f = sqrt(k_f / (rho A)) / (2 pi)."""
    k = np.asarray(k, float)
    return np.sqrt((tension * k**2 + EI * k**4 + foundation) / rho_A) / (2 * math.pi)


def euler_bernoulli_frequency(k, EI: float, rho_A: float) -> np.ndarray:
    """The Euler-Bernoulli beam's flexural branch, eq. (9): f = k^2 sqrt(EI / (rho A)) / (2 pi) [Hz]."""
    return np.asarray(k, float) ** 2 * math.sqrt(EI / rho_A) / (2 * math.pi)
