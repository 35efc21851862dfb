"""Materials and the contact coefficients they give: the effective properties of eq. (4), the
Hertz coefficient A and the damping prefactor G of eq. (3), for each kind of contact (two
granules, a granule on a rigid wall, a granule on the solid's massless layer). The functions take
numbers or numpy arrays alike."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..solid.base import Material  # noqa: F401  (the one material record, here for the granules)


STEEL = Material(E=200e9, rho=7850.0, nu=0.3)


def granule_volume(radius):
    """The volume of a spherical granule, 4/3 pi R^3 (the granules are spheres in a plane)."""
    return 4.0 / 3.0 * math.pi * radius**3


def sphere_mass(radius, rho):
    return granule_volume(radius) * rho


def sphere_inertia(mass: float, radius: float) -> float:
    """Moment of inertia of a solid sphere about a diameter."""
    return 0.4 * mass * radius**2


def effective_modulus(E1: float, nu1: float, E2: float | None = None, nu2: float | None = None) -> float:
    """E* of eq. (4); a rigid partner (E2 = None) gives E1 / (1 - nu1^2)."""
    inv = (1.0 - nu1**2) / E1
    if E2 is not None:
        inv += (1.0 - nu2**2) / E2
    return 1.0 / inv


def effective_radius(R1: float, R2: float | None = None) -> float:
    """R* of eq. (4); a flat partner (R2 = None) gives R1."""
    return R1 if R2 is None else R1 * R2 / (R1 + R2)


def effective_mass(m1, m2):
    """m* of eq. (4). m2 = None is an immovable wall (m* = m1); m2 = 0 a massless layer (m* = 0)."""
    if m2 is None:
        return m1
    if np.ndim(m2) == 0 and m2 == 0.0:
        return 0.0
    return m1 * m2 / (m1 + m2)


def hertz_coefficient(E_star, R_star):
    """A = 4/3 E* sqrt(R*), eq. (3)."""
    return 4.0 / 3.0 * E_star * np.sqrt(R_star)


def damping_coefficient(alpha_n, m_star, A):
    """alpha_n sqrt(m* A): gamma = this * delta^(1/4), eq. (3)."""
    return alpha_n * np.sqrt(m_star * A)


class Body(NamedTuple):
    """A granule as a contact sees it: Young's modulus E [Pa], Poisson's ratio nu, radius R [m]
    and mass m [kg]; numbers, or arrays of one per contact (`GranularSystem.bodies`)."""

    E: object
    nu: object
    R: object
    m: object


def pair_coefficients(a: Body, b: Body, alpha_n):
    """(A, G) of eq. (3) for two granules, with E*, R* and m* of eq. (4)."""
    A = hertz_coefficient(effective_modulus(a.E, a.nu, b.E, b.nu), effective_radius(a.R, b.R))
    return A, damping_coefficient(alpha_n, effective_mass(a.m, b.m), A)


def wall_coefficients(g: Body, alpha_n, damped=True):
    """(A, G) of eq. (3) for a granule on a rigid, immovable wall: E* = E / (1 - nu^2), R* = R,
    and in the dashpot m* = m for a damped wall, m* = 0 (G = 0, Hertz alone) for an undamped
    (elastic) one; `damped` is a bool or an array of them, one per granule."""
    A = hertz_coefficient(effective_modulus(g.E, g.nu), effective_radius(g.R))
    m_star = effective_mass(g.m, None) if np.all(damped) else np.where(damped, effective_mass(g.m, None), 0.0)
    return A, damping_coefficient(alpha_n, m_star, A)


def point_coefficient(g: Body):
    """A of eq. (3) for a granule on the solid's massless rigid layer: E* = E / (1 - nu^2), R* =
    R, and m* = 0, so no damping (G = 0)."""
    return hertz_coefficient(effective_modulus(g.E, g.nu), effective_radius(g.R))
