"""Exact propagation of an undamped modal oscillator eta'' + w^2 eta = g(t) over a step [0, h]
under a cubic force g, in closed form through S_p(x) = sum_m (-x^2)^m / (2m + p)!, x = w h
(`oscillator_functions`: S0..S5, x >= 0). The force is given in a basis by its Taylor rows at the
step's start (`interpolation_taylor`, `hermite_taylor`); `weights_at` gives each mode's
displacement and velocity per unit datum. docs/performance.md ("Propagation") gives the formulas."""

from __future__ import annotations

import math

import numpy as np

from ..guard.jit import njit

SERIES_LIMIT = 2.0


def _series_coefficients(p: int, terms: int) -> np.ndarray:
    """(-1)^m / (2m + p)!, m = 0 .. terms - 1: S_p as a polynomial in x^2."""
    return np.array([(-1.0) ** m / math.factorial(2 * m + p) for m in range(terms)])


# below SERIES_LIMIT, 13 terms of S4 and S5 reach round-off: (x^2)^13 / 30! < 1e-24 for x < 2
_S4 = _series_coefficients(4, 13)
_S5 = _series_coefficients(5, 13)


@njit(cache=True)
def oscillator_functions(x, S):
    """S[p] = S_p(x) = sum_m (-x^2)^m / (2m + p)!, p = 0..5, for x >= 0."""
    x2 = x * x
    if x < SERIES_LIMIT:
        # S4, S5 by their series in x^2 (Horner), then down: S_p = 1/p! - x^2 S_(p+2), which
        # loses nothing here (x^2 S_(p+2) < 0.7 / p! for p >= 1); S0 = cos x directly (near
        # pi / 2 it is the difference of two numbers close to 1)
        s4 = _S4[12]
        s5 = _S5[12]
        for m in range(11, -1, -1):
            s4 = s4 * x2 + _S4[m]
            s5 = s5 * x2 + _S5[m]
        S[5] = s5
        S[4] = s4
        S[3] = 1.0 / 6.0 - x2 * s5
        S[2] = 0.5 - x2 * s4
        S[1] = 1.0 - x2 * S[3]
        S[0] = math.cos(x)
        return
    S[0] = math.cos(x)
    S[1] = math.sin(x) / x
    half = math.sin(0.5 * x)
    S[2] = 2.0 * half * half / x2  # (1 - cos x) / x^2 without cancellation near x = 2 pi k
    S[3] = (1.0 - S[1]) / x2
    S[4] = (0.5 - S[2]) / x2  # S_(p+2) = (1/p! - S_p) / x^2
    S[5] = (1.0 / 6.0 - S[3]) / x2


@njit(cache=True)
def hermite_taylor(h, out):
    """Taylor coefficients at tau = 0 (the derivatives g_0..g_3) of the four cubic Hermite basis
    functions on [0, h]: rows H00 (F0), H10 (F0'), H01 (F1), H11 (F1')."""
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = 1.0, 0.0, -6.0 / h**2, 12.0 / h**3
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = 0.0, 1.0, -4.0 / h, 6.0 / h**2
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = 0.0, 0.0, 6.0 / h**2, -12.0 / h**3
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, -2.0 / h, 6.0 / h**2


@njit(cache=True)
def interpolation_taylor(nodes, orders, h, out):
    """Taylor coefficients at tau = 0 (derivatives 0..3) of the interpolation basis on [0, h] for
    the data "derivative orders[b] at tau = nodes[b] h" (at most four data): row b is the
    polynomial whose datum b is 1 and whose other data are 0. Values at (0, 1) give the linear
    force, at (0, 1/2, 1) the quadratic; value and slope at 0 with values at 1/2 and 1 the C1
    cubic."""
    nb = nodes.shape[0]
    V = np.zeros((nb, nb))
    for i in range(nb):
        tau = nodes[i] * h
        for k in range(orders[i], nb):
            c = 1.0
            for m in range(k - orders[i] + 1, k + 1):
                c *= m
            V[i, k] = c * tau ** (k - orders[i])
    C = np.linalg.inv(V)  # column b: the monomial coefficients (in tau) of basis b
    out[:, :] = 0.0
    fact = 1.0
    for k in range(nb):
        if k > 1:
            fact *= k
        for b in range(nb):
            out[b, k] = fact * C[k, b]


@njit(cache=True)
def basis_values(T, tau, H, dH):
    """The basis functions H_b(tau) and their slopes H_b'(tau) from their Taylor rows T
    (`hermite_taylor`, `interpolation_taylor`)."""
    for b in range(T.shape[0]):
        H[b] = T[b, 0] + T[b, 1] * tau + 0.5 * T[b, 2] * tau * tau + T[b, 3] * tau**3 / 6.0
        dH[b] = T[b, 1] + T[b, 2] * tau + 0.5 * T[b, 3] * tau * tau


@njit(cache=True)
def weights_at(omega, tau, T, hom, wd, wv):
    """Modal weights at tau into a step under a force sum_b F_b H_b(tau), the basis given by its
    Taylor rows T (nb, 4): the free response hom (S0, tau S1, -w^2 tau S1) at w tau and, per basis
    datum b, the displacement wd and velocity wv of the mode at tau per unit modal datum."""
    S = np.empty(6)
    tp = np.empty(6)
    tp[0] = 1.0
    for p in range(1, 6):
        tp[p] = tp[p - 1] * tau
    nb = T.shape[0]
    for i in range(omega.shape[0]):
        w = omega[i]
        oscillator_functions(w * tau, S)
        hom[i, 0] = S[0]
        hom[i, 1] = tau * S[1]
        hom[i, 2] = -w * w * tau * S[1]
        for b in range(nb):
            d = 0.0
            v = 0.0
            for k in range(4):
                d += T[b, k] * tp[k + 2] * S[k + 2]
                v += T[b, k] * tp[k + 1] * S[k + 1]
            wd[i, b] = d
            wv[i, b] = v


@njit(cache=True)
def hermite_weights(omega, h, hom, wd, wv):
    """Per mode i (omega[i]) over a step h: hom[i] = (S0, h S1, -w^2 h S1) for the free response,
    and wd[i, b], wv[i, b]: the end displacement and velocity per unit modal force of Hermite
    datum b (0: F0, 1: F0', 2: F1, 3: F1')."""
    T = np.empty((4, 4))
    hermite_taylor(h, T)
    weights_at(omega, h, T, hom, wd, wv)


def modal_step_cubic(omega, h, eta0, etad0, g):
    """End displacement and velocity of each mode after a step h under the cubic force with
    Hermite data g (4, nm): rows g(0), g'(0), g(h), g'(h). Reference implementation (tests)."""
    omega = np.asarray(omega, float)
    n = len(omega)
    hom, wd, wv = np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4))
    hermite_weights(omega, float(h), hom, wd, wv)
    g = np.asarray(g, float).reshape(4, n)
    eta = hom[:, 0] * eta0 + hom[:, 1] * etad0 + np.einsum("ib,bi->i", wd, g)
    etad = hom[:, 2] * eta0 + hom[:, 0] * etad0 + np.einsum("ib,bi->i", wv, g)
    return eta, etad


def modal_step_interpolated(omega, h, eta0, etad0, nodes, orders, data):
    """End displacement and velocity of each mode after a step h under the force polynomial with
    `data` (nb, nm): derivative orders[b] at nodes[b] h (`interpolation_taylor`). Reference
    implementation (tests)."""
    omega = np.asarray(omega, float)
    nodes, orders = np.asarray(nodes, float), np.asarray(orders, np.int64)
    n, nb = len(omega), len(nodes)
    T = np.empty((nb, 4))
    interpolation_taylor(nodes, orders, float(h), T)
    hom, wd, wv = np.empty((n, 3)), np.empty((n, nb)), np.empty((n, nb))
    weights_at(omega, float(h), T, hom, wd, wv)
    g = np.asarray(data, float).reshape(nb, n)
    eta = hom[:, 0] * eta0 + hom[:, 1] * etad0 + np.einsum("ib,bi->i", wd, g)
    etad = hom[:, 2] * eta0 + hom[:, 0] * etad0 + np.einsum("ib,bi->i", wv, g)
    return eta, etad
