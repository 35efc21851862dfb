"""The one contact law of granel, eqs. (2), (3) and (5): force, potential and the derivatives
Newton needs, side by side. Every contact (granule-granule, granule-wall, granule-solid point)
and every solver calls these functions; tests check the derivatives against finite differences.

Variables of a contact: overlap delta > 0 (eq. 2), overlap rate ddelta = d(delta)/dt, relative
tangential velocity vt (eq. 6), Hertz coefficient A = 4/3 E* sqrt(R*) and damping prefactor
G = alpha_n sqrt(m* A) (eq. 3, so that gamma = G delta^(1/4)), friction mu and smoothness k_s.
Sign conventions: fn > 0 repels; ft is the tangential force along t = k x n on the body whose
relative velocity vt is, so ft opposes vt. The Hertz terms (`hertz_force`, `hertz_stiffness`,
`hertz_potential`, `tsuji_damping`) take arrays too, through their Python form `.py_func`, which
static equilibria and load checks call.
"""

from __future__ import annotations

import math

import numpy as np

from ..guard.jit import njit


@njit(cache=True, inline="always")
def hertz_force(A, delta):
    """Eq. (2): the elastic normal force A delta^(3/2) of an overlap delta >= 0."""
    return A * delta * np.sqrt(delta)


@njit(cache=True, inline="always")
def hertz_stiffness(A, delta):
    """d `hertz_force` / d delta = 3/2 A delta^(1/2)."""
    return 1.5 * A * np.sqrt(delta)


@njit(cache=True, inline="always")
def tsuji_damping(G, delta):
    """Eq. (3): the damping coefficient gamma = G delta^(1/4)."""
    return G * np.sqrt(np.sqrt(delta))


def hertz_overlap(force, A):
    """The overlap at which a Hertz contact carries `force` (the inverse of `hertz_force`)."""
    return (force / A) ** (2.0 / 3.0)


def impact_overlap(m_star, speed, A):
    """The largest overlap of an undamped Hertz impact at closing speed v: 1/2 m* v^2 =
    `hertz_potential`, so delta = (5 m* v^2 / (4 A))^(2/5)."""
    return (5.0 * m_star * speed * speed / (4.0 * A)) ** 0.4


@njit(cache=True, inline="always")
def hertz_tsuji_normal(A, G, delta, ddelta):
    """Eqs. (2)-(3): normal force magnitude fn = A delta^(3/2) + gamma ddelta (repulsive > 0) and
    the damping coefficient gamma = G delta^(1/4)."""
    gam = tsuji_damping(G, delta)
    return hertz_force(A, delta) + gam * ddelta, gam


# beyond this, tanh is 1 to the last bit (1 - tanh x = 2 e^(-2x) / (1 + e^(-2x)) < 2^-54)
TANH_SATURATED = 19.1


@njit(cache=True, inline="always")
def tanh(x):
    """tanh x within 2 ulp (tested against numpy), cheaper than the library's, for the friction
    law (eq. 5) at every contact and RK4 stage: +-1 beyond TANH_SATURATED; expm1(2x) /
    (expm1(2x) + 2) for |x| < 1/2 (no cancellation near 0); 1 - 2 / (e^(2|x|) + 1) with the sign
    of x between."""
    ax = abs(x)
    if ax > TANH_SATURATED:
        return 1.0 if x > 0.0 else -1.0
    if ax < 0.5:
        e = math.expm1(2.0 * x)
        return e / (e + 2.0)
    t = 1.0 - 2.0 / (math.exp(2.0 * ax) + 1.0)
    return t if x > 0.0 else -t


@njit(cache=True, inline="always")
def tanh_friction(fn, vt, mu, k_s):
    """Eq. (5): ft = -mu |N| tanh(k_s vt)."""
    return -mu * abs(fn) * tanh(k_s * vt)


@njit(cache=True, inline="always")
def contact_law(A, G, delta, ddelta, vt, mu, k_s):
    """Eqs. (2), (3), (5) for delta > 0: (fn, ft, gamma)."""
    fn, gam = hertz_tsuji_normal(A, G, delta, ddelta)
    return fn, tanh_friction(fn, vt, mu, k_s), gam


@njit(cache=True, inline="always")
def hertz_potential(A, delta):
    """The elastic energy of a contact, 2/5 A delta^(5/2) (eq. 11 shares it between the bodies);
    its derivative is the elastic part of fn."""
    return 0.4 * A * delta * delta * np.sqrt(delta)


@njit(cache=True, inline="always")
def contact_law_derivatives(A, G, delta, ddelta, vt, mu, k_s):
    """Partial derivatives of (fn, ft) of `contact_law` (eqs. (2), (3), (5)) with respect to
    (delta, ddelta, vt): (dfn/ddelta, dfn/dddelta, dft/ddelta, dft/dddelta, dft/dvt). The
    fn-derivatives of |fn| carry its sign (fn < 0 only under strong separation damping)."""
    fn, dfn_dd = hertz_tsuji_normal(A, G, delta, ddelta)  # d fn / d ddelta = gamma
    q = math.sqrt(math.sqrt(delta))  # delta^(1/4)
    dfn_d = hertz_stiffness(A, delta) + 0.25 * G * ddelta / (q * q * q)
    th = tanh(k_s * vt)
    s = -mu * th * (1.0 if fn >= 0.0 else -1.0)  # d ft / d fn
    return dfn_d, dfn_dd, s * dfn_d, s * dfn_dd, -mu * abs(fn) * k_s * (1.0 - th * th)


@njit(cache=True, inline="always")
def friction_map_slope(mu, k_s, normal, vt, beta):
    """The slope of a contact's friction force against itself over a step, mu k_s |N| beta /
    cosh^2(k_s vt) (eq. 5 differentiated), where beta is the relative tangential velocity's
    response to the contact's own tangential force: the map F_t -> F_t is a contraction where
    this is below 1."""
    th = tanh(k_s * vt)
    return mu * k_s * abs(normal) * beta * (1.0 - th * th)


@njit(cache=True, inline="always")
def friction_eigenvalue(mu, k_s, normal, vt, h, c_t):
    """(10)/(A9): |lambda| = 1/2 mu k_s |N| h c_t / cosh^2(k_s vt), with c_t = T (M + K h^2/4)^-1 T'
    the tangential compliance of the contact point over a step h (beta = h c_t / 2 under the
    constant average acceleration)."""
    return friction_map_slope(mu, k_s, normal, vt, 0.5 * h * c_t)
