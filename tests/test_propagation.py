"""Exact modal propagation (solid.propagation) against arbitrary-precision references and the
orders of the modal integrators."""

import math

import mpmath as mp
import numpy as np
import pytest

from granel.solid.propagation import hermite_weights, modal_step_cubic, oscillator_functions

mp.mp.dps = 90


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


@pytest.mark.parametrize("x", [0.0, 1e-6, 1e-3, 0.3, 1.0, 1.9999, 2.0, 2.5, 7.0, 31.4, 1e2, 1e3])
def test_oscillator_functions_to_full_precision(x):
    """S_0..S_5 from the series (x < 2) and the recurrence (x >= 2) to 1e-13 of the 90-digit value."""
    S = np.empty(6)
    oscillator_functions(x, S)
    for p in range(6):
        ref = float(S_ref(p, x)) if x < 50 else None
        if ref is None:  # the series needs too many terms: use the closed forms
            xs = mp.mpf(x)
            closed = [mp.cos(xs), mp.sin(xs) / xs]
            fact = 1
            for q in range(4):
                fact = fact * q if q > 1 else 1
                closed.append((mp.mpf(1) / mp.factorial(q) - closed[q]) / xs**2)
            ref = float(closed[p])
        assert S[p] == pytest.approx(ref, rel=1e-13, abs=1e-300), p


def test_cubic_forcing_is_propagated_exactly():
    """A mode under a cubic force: the end state against the closed-form solution of
    eta'' + w^2 eta = a + b t + c t^2 + d t^3 evaluated in 90 digits, over w h from 1e-6 to 1e3."""
    a, b, c, d = 0.7, -3.0, 5.0, 11.0
    eta0, etad0 = 0.3, -0.8
    for w in (1e-6, 1e-2, 1.0, 3.0, 40.0, 1e3):
        h = 1.0
        g = lambda t: a + b * t + c * t * t + d * t**3  # noqa: E731
        dg = lambda t: b + 2 * c * t + 3 * d * t * t  # noqa: E731
        eta, etad = modal_step_cubic([w], h, eta0, etad0, [[g(0)], [dg(0)], [g(h)], [dg(h)]])
        W, h, A4 = mp.mpf(w), mp.mpf(h), [mp.mpf(v) for v in (a, b, c, d)]
        a_, b_, c_, d_ = A4
        # particular solution of a polynomial force: p = g/w^2 - g''/w^4 (+ g''''/w^6 = 0)
        gp = lambda t: (a_ + b_ * t + c_ * t**2 + d_ * t**3) / W**2 - (2 * c_ + 6 * d_ * t) / W**4  # noqa: E731
        dgp = lambda t: (b_ + 2 * c_ * t + 3 * d_ * t**2) / W**2 - 6 * d_ / W**4  # noqa: E731
        A, B = eta0 - gp(0), (etad0 - dgp(0)) / W
        ref = A * mp.cos(W * h) + B * mp.sin(W * h) + gp(h)
        refd = -A * W * mp.sin(W * h) + B * W * mp.cos(W * h) + dgp(h)
        scale = max(abs(float(ref)), 1e-12 * (abs(a) + abs(d)) / max(w, 1) ** 2, 1e-30)
        assert eta[0] == pytest.approx(float(ref), rel=1e-11, abs=1e-11 * scale), w
        assert etad[0] == pytest.approx(float(refd), rel=1e-11, abs=1e-11 * max(abs(float(refd)), 1e-12)), w


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
    assert 1.9 < _order(errs["linear"], hs) < 2.1
    assert 3.8 < _order(errs["cubic"], hs) < 4.3


def test_hermite_weights_of_a_static_mode():
    """w -> 0 limit and w h >> 1: the weights stay finite and reproduce simple cases: a constant
    force F on a free mass (w = 0) moves it F h^2 / 2; on a stiff mode (w h = 1e3) the end
    displacement under a constant force is F (1 - cos w h) / w^2."""
    hom, wd, wv = np.empty((2, 3)), np.empty((2, 4)), np.empty((2, 4))
    hermite_weights(np.array([0.0, 1e3]), 1.0, hom, wd, wv)
    assert wd[0, 0] + wd[0, 2] == pytest.approx(0.5, rel=1e-15) and wv[0, 0] + wv[0, 2] == pytest.approx(1.0, rel=1e-15)
    assert wd[1, 0] + wd[1, 2] == pytest.approx((1 - math.cos(1e3)) / 1e6, rel=1e-12)


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
                assert np.allclose(H, np.eye(nb)[i], atol=1e-12), (nodes, h, s)
    a, b, c = 0.4, -2.0, 3.0  # g(t) = a + b t + c t^2
    eta0, etad0, h = 0.2, -0.5, 1.0
    for w in (1e-6, 0.5, 3.0, 40.0, 1e3):
        g = lambda t: a + b * t + c * t * t  # noqa: E731
        eta, etad = modal_step_interpolated([w], h, eta0, etad0, (0.0, 0.5, 1.0), (0, 0, 0), [[g(0)], [g(0.5)], [g(1.0)]])
        W, a_, b_, c_ = mp.mpf(w), mp.mpf(a), mp.mpf(b), mp.mpf(c)
        gp = lambda t: (a_ + b_ * t + c_ * t**2) / W**2 - 2 * c_ / W**4  # noqa: E731
        dgp = lambda t: (b_ + 2 * c_ * t) / W**2  # noqa: E731
        A, B = eta0 - gp(0), (etad0 - dgp(0)) / W
        ref = A * mp.cos(W) + B * mp.sin(W) + gp(1)
        refd = -A * W * mp.sin(W) + B * W * mp.cos(W) + dgp(1)
        assert eta[0] == pytest.approx(float(ref), rel=1e-10, abs=1e-12 * max(1.0, abs(float(ref)))), w
        assert etad[0] == pytest.approx(float(refd), rel=1e-10, abs=1e-12 * max(1.0, abs(float(refd)))), w


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
    assert 1.9 < _order(errs["linear"], hs) < 2.1
    assert 3.8 < _order(errs["quadratic"], hs) < 4.3
