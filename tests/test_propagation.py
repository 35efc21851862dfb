"""Exact modal propagation (solid.propagation) against arbitrary-precision references and the
orders of the modal integrators."""

import math

import mpmath as mp
import numpy as np
import pytest

from granel.solid.propagation import SERIES_LIMIT, hermite_taylor, hermite_weights, modal_step_cubic, oscillator_functions

mp.mp.dps = 90
EPS = np.finfo(float).eps


def S_ref(p, x):
    """S_p(x) = sum_m (-x^2)^m / (2m + p)! in 90-digit arithmetic (the defining series)."""
    x = mp.mpf(x)
    total, m = mp.mpf(0), 0
    while True:
        term = (-x * x) ** m / mp.factorial(2 * m + p)
        total += term
        if m > 5 and abs(term) < mp.mpf(10) ** -45 * (abs(total) + mp.mpf(10) ** -60):
            return total
        m += 1


def S_exact(x):
    """S_0..S_5 at x in 90 digits: the series, or beyond x = 50 (too many terms) the closed forms."""
    if x < 50:
        return [S_ref(p, x) for p in range(6)]
    xs = mp.mpf(x)
    closed = [mp.cos(xs), mp.sin(xs) / xs]
    for q in range(4):
        closed.append((mp.mpf(1) / mp.factorial(q) - closed[q]) / xs**2)
    return closed


def S_rounding(x):
    """Bounds on the relative rounding error of `oscillator_functions`' S_0..S_5, from the exact
    values: below SERIES_LIMIT, S4 and S5 by Horner over 13 terms (2 x 13 eps of their absolute
    series over their value), then S_p = 1/p! - x^2 S_(p+2) (its terms' errors over its value);
    above, cos, sin to an ulp and the recurrence S_(p+2) = (1/p! - S_p) / x^2, whose cancellation
    (1/p! + |S_p|) / |1/p! - S_p| multiplies S_p's error."""
    S = [abs(v) for v in S_exact(x)]
    x2 = mp.mpf(x) ** 2
    inv = [1 / mp.factorial(p) for p in range(6)]
    rel = [mp.mpf(0)] * 6
    if x < SERIES_LIMIT:
        for p in (4, 5):
            absolute = mp.nsum(lambda m: x2**m / mp.factorial(2 * m + p), [0, mp.inf])
            rel[p] = 26 * EPS * absolute / S[p]
        for p in (3, 2, 1):
            rel[p] = (x2 * S[p + 2] * (rel[p + 2] + 2 * EPS) + S[p] * EPS) / S[p]
        rel[0] = EPS
    else:
        rel[0], rel[1], rel[2] = EPS, 2 * EPS, 5 * EPS
        for p in (1, 2, 3):
            rel[p + 2] = ((inv[p] + S[p]) * EPS + S[p] * rel[p]) / abs(inv[p] - S_exact(x)[p]) + 2 * EPS
    return [float(r) for r in rel]


def step_bound(w, h, eta0, etad0, T, data):
    """Bounds on the rounding of one propagated step (displacement, velocity), `weights_at`'s sums
    eta = S0 eta0 + h S1 eta0' + sum_b g_b sum_k T_bk h^(k+2) S_(k+2) (velocity: one power of h
    less): each term its S's error and a few roundings, the sum (its terms' count) eps of the
    terms' absolute sum; T's own rows to 4 eps."""
    x = w * h
    S, rel = [abs(float(v)) for v in S_exact(x)], S_rounding(x)
    out = []
    for shift, free in ((2, [(S[0] * abs(eta0), rel[0]), (h * S[1] * abs(etad0), rel[1])]),
                        (1, [(w * w * h * S[1] * abs(eta0), rel[1]), (S[0] * abs(etad0), rel[0])])):
        terms = free + [(abs(T[b][k] * data[b]) * h ** (k + shift) * S[k + shift], rel[k + shift] + 4 * EPS)
                        for b in range(len(data)) for k in range(4)]
        out.append(sum(t * (r + (len(terms) + 3) * EPS) for t, r in terms))
    return out


@pytest.mark.parametrize("x", [0.0, 1e-6, 1e-3, 0.3, 1.0, 1.9999, 2.0, 2.5, 7.0, 31.4, 1e2, 1e3])
def test_oscillator_functions_to_full_precision(x):
    """S_0..S_5 from the series (x < 2) and the recurrence (x >= 2) within their rounding bounds
    (`S_rounding`: at most 9e-15, near x = 2) of the 90-digit value (measured at most 0.32 of them)."""
    S = np.empty(6)
    oscillator_functions(x, S)
    rel = S_rounding(x)
    for p, ref in enumerate(S_exact(x)):
        assert S[p] == pytest.approx(float(ref), rel=rel[p], abs=1e-300), p


def test_cubic_forcing_is_propagated_exactly():
    """A mode under a cubic force: the end state against the closed-form solution of
    eta'' + w^2 eta = a + b t + c t^2 + d t^3 evaluated in 90 digits, over w h from 1e-6 to 1e3,
    within the step's rounding bound (`step_bound`; measured at most 2.8 eps)."""
    T = np.empty((4, 4))
    hermite_taylor(1.0, T)
    a, b, c, d = 0.7, -3.0, 5.0, 11.0
    eta0, etad0 = 0.3, -0.8
    for w in (1e-6, 1e-2, 1.0, 3.0, 40.0, 1e3):
        h = 1.0
        g = lambda t: a + b * t + c * t * t + d * t**3  # noqa: E731
        dg = lambda t: b + 2 * c * t + 3 * d * t * t  # noqa: E731
        data = [g(0), dg(0), g(h), dg(h)]
        eta, etad = modal_step_cubic([w], h, eta0, etad0, [[v] for v in data])
        bd, bv = step_bound(w, h, eta0, etad0, T, data)
        W, h, A4 = mp.mpf(w), mp.mpf(h), [mp.mpf(v) for v in (a, b, c, d)]
        a_, b_, c_, d_ = A4
        # particular solution of a polynomial force: p = g/w^2 - g''/w^4 (+ g''''/w^6 = 0)
        gp = lambda t: (a_ + b_ * t + c_ * t**2 + d_ * t**3) / W**2 - (2 * c_ + 6 * d_ * t) / W**4  # noqa: E731
        dgp = lambda t: (b_ + 2 * c_ * t + 3 * d_ * t**2) / W**2 - 6 * d_ / W**4  # noqa: E731
        A, B = eta0 - gp(0), (etad0 - dgp(0)) / W
        ref = A * mp.cos(W * h) + B * mp.sin(W * h) + gp(h)
        refd = -A * W * mp.sin(W * h) + B * W * mp.cos(W * h) + dgp(h)
        assert eta[0] == pytest.approx(float(ref), rel=0, abs=bd), w
        assert etad[0] == pytest.approx(float(refd), rel=0, abs=bv), w


def _order(errors, steps):
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def test_modal_orders_linear_force_2_cubic_force_4():
    """A mode driven by a smooth force g(t) = cos(3 t) + t^2, stepped with the force taken as the
    linear interpolant of its end values (order 2) or the cubic Hermite through values and slopes
    (order 4), against the exact solution."""
    w, T = 5.0, 2.0
    g = lambda t: np.cos(3 * t) + t * t  # noqa: E731
    dg = lambda t: -3 * np.sin(3 * t) + 2 * t  # noqa: E731

    def exact(t):  # eta'' + w^2 eta = g, eta(0) = eta'(0) = 0, by quadrature of the Duhamel integral
        return float(mp.quad(lambda s: mp.sin(w * (t - s)) / w * (mp.cos(3 * s) + s * s), [0, t]))

    ref = exact(T)
    errs = {"linear": [], "cubic": []}
    ns = [8, 16, 32, 64, 128]
    for n in ns:
        h = T / n
        for kind in errs:
            eta, etad = 0.0, 0.0
            for k in range(n):
                t0, t1 = k * h, (k + 1) * h
                slope = (g(t1) - g(t0)) / h
                data = [[g(t0)], [slope], [g(t1)], [slope]] if kind == "linear" else [[g(t0)], [dg(t0)], [g(t1)], [dg(t1)]]
                e, ed = modal_step_cubic([w], h, eta, etad, data)
                eta, etad = e[0], ed[0]
            errs[kind].append(abs(eta - ref))
    hs = [T / n for n in ns]
    # the fitted orders against the theoretical 2 and 4 (measured 2.00 and 4.00; the smallest
    # error, 7.5e-10, is still far above round-off)
    assert 1.9 < _order(errs["linear"], hs) < 2.1
    assert 3.8 < _order(errs["cubic"], hs) < 4.3


def test_hermite_weights_of_a_static_mode():
    """w -> 0 limit and w h >> 1: the weights stay finite and reproduce simple cases: a constant
    force F on a free mass (w = 0) moves it F h^2 / 2; on a stiff mode (w h = 1e3) the end
    displacement under a constant force is F (1 - cos w h) / w^2."""
    hom, wd, wv = np.empty((2, 3)), np.empty((2, 4)), np.empty((2, 4))
    hermite_weights(np.array([0.0, 1e3]), 1.0, hom, wd, wv)
    T = np.empty((4, 4))
    hermite_taylor(1.0, T)
    # a unit constant force: data (1, 0, 1, 0); measured exact at w = 0, 1 eps at w h = 1e3
    bounds = [step_bound(w, 1.0, 0.0, 0.0, T, [1.0, 0.0, 1.0, 0.0]) for w in (0.0, 1e3)]
    assert wd[0, 0] + wd[0, 2] == pytest.approx(0.5, abs=bounds[0][0]) and wv[0, 0] + wv[0, 2] == pytest.approx(1.0, abs=bounds[0][1])
    assert wd[1, 0] + wd[1, 2] == pytest.approx((1 - math.cos(1e3)) / 1e6, abs=bounds[1][0] + EPS * 2e-6)


def test_lagrange_basis_interpolates_its_nodes():
    """The force models' bases (`interpolation_taylor`): each basis polynomial is 1 at its own node
    and 0 at the others, on a step of any size, and the propagation under a quadratic force is
    exact (against the 90-digit closed form of the forced oscillator)."""
    from granel.solid.propagation import basis_values, interpolation_taylor, modal_step_interpolated

    for nodes in ((0.0, 1.0), (0.0, 0.5, 1.0)):
        for h in (1e-9, 1e-6, 1.0):
            nb = len(nodes)
            T = np.empty((nb, 4))
            interpolation_taylor(np.array(nodes), np.zeros(nb, np.int64), h, T)
            H, dH = np.empty(nb), np.empty(nb)
            for i, s in enumerate(nodes):
                basis_values(T, s * h, H, dH)
                # sum_k T_bk (s h)^k / k!: 7 roundings of its absolute sum, T's rows to 4 eps (measured 4 eps)
                absolute = np.abs(T) @ np.array([(s * h) ** k / math.factorial(k) for k in range(4)])
                assert np.all(np.abs(H - np.eye(nb)[i]) <= 11 * EPS * absolute), (nodes, h, s)
    a, b, c = 0.4, -2.0, 3.0  # g(t) = a + b t + c t^2
    eta0, etad0, h = 0.2, -0.5, 1.0
    for w in (1e-6, 0.5, 3.0, 40.0, 1e3):
        g = lambda t: a + b * t + c * t * t  # noqa: E731
        data = [g(0), g(0.5), g(1.0)]
        eta, etad = modal_step_interpolated([w], h, eta0, etad0, (0.0, 0.5, 1.0), (0, 0, 0), [[v] for v in data])
        T = np.empty((3, 4))
        interpolation_taylor(np.array((0.0, 0.5, 1.0)), np.zeros(3, np.int64), h, T)
        bd, bv = step_bound(w, h, eta0, etad0, T, data)  # measured at most 3.5 eps
        W, a_, b_, c_ = mp.mpf(w), mp.mpf(a), mp.mpf(b), mp.mpf(c)
        gp = lambda t: (a_ + b_ * t + c_ * t**2) / W**2 - 2 * c_ / W**4  # noqa: E731
        dgp = lambda t: (b_ + 2 * c_ * t) / W**2  # noqa: E731
        A, B = eta0 - gp(0), (etad0 - dgp(0)) / W
        ref = A * mp.cos(W) + B * mp.sin(W) + gp(1)
        refd = -A * W * mp.sin(W) + B * W * mp.cos(W) + dgp(1)
        assert eta[0] == pytest.approx(float(ref), rel=0, abs=bd), w
        assert etad[0] == pytest.approx(float(refd), rel=0, abs=bv), w


def test_modal_orders_linear_force_2_quadratic_force_4():
    """A mode driven by the smooth force g(t) = cos(3 t) + t^2, stepped with the force taken as
    the polynomial through its values at (0, h) or at (0, h/2, h), the coupled solver's two force
    models: orders 2 and 4 (the quadratic through the Simpson nodes gains an order by symmetry)."""
    from granel.solid.propagation import modal_step_interpolated

    w, T = 5.0, 2.0
    g = lambda t: np.cos(3 * t) + t * t  # noqa: E731
    ref = float(mp.quad(lambda s: mp.sin(w * (T - s)) / w * (mp.cos(3 * s) + s * s), [0, T]))
    ns = [8, 16, 32, 64, 128]
    errs = {"linear": [], "quadratic": []}
    for n in ns:
        h = T / n
        for kind, nodes in (("linear", (0.0, 1.0)), ("quadratic", (0.0, 0.5, 1.0))):
            eta, etad = 0.0, 0.0
            for k in range(n):
                vals = [[g(k * h + s * h)] for s in nodes]
                e, ed = modal_step_interpolated([w], h, eta, etad, nodes, (0,) * len(nodes), vals)
                eta, etad = e[0], ed[0]
            errs[kind].append(abs(eta - ref))
    hs = [T / n for n in ns]
    assert 1.9 < _order(errs["linear"], hs) < 2.1  # the theoretical orders, fitted over five steps
    assert 3.8 < _order(errs["quadratic"], hs) < 4.3
