"""Materials and effective contact properties, eq. (4) of the paper."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """An isotropic linear elastic material."""

    E: float  # Young's modulus [Pa]
    rho: float  # density [kg/m^3]
    nu: float  # Poisson's ratio [-]


STEEL = Material(E=200e9, rho=7850.0, nu=0.3)


def sphere_mass(radius: float, rho: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * rho


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


def effective_mass(m1: float, m2: float | None) -> float:
    """m* of eq. (4). m2 = None is an immovable wall (m* = m1); m2 = 0 a massless layer (m* = 0)."""
    if m2 is None:
        return m1
    if m2 == 0.0:
        return 0.0
    return m1 * m2 / (m1 + m2)


def hertz_coefficient(E_star: float, R_star: float) -> float:
    """A = 4/3 E* sqrt(R*), eq. (3)."""
    return 4.0 / 3.0 * E_star * math.sqrt(R_star)


def static_overlap(force: float, A: float) -> float:
    """The overlap at which a Hertz contact carries `force` (eq. 2): A delta^(3/2) = F."""
    return (force / A) ** (2.0 / 3.0)


def impact_overlap(m_star: float, speed: float, A: float) -> float:
    """The largest overlap of an undamped Hertz impact (eq. 2) at closing speed v:
    1/2 m* v^2 = 2/5 A delta^(5/2), so delta = (5 m* v^2 / (4 A))^(2/5)."""
    return (5.0 * m_star * speed * speed / (4.0 * A)) ** 0.4


def damping_coefficient(alpha_n: float, m_star: float, A: float) -> float:
    """alpha_n sqrt(m* A): gamma = this * delta^(1/4), eq. (3)."""
    return alpha_n * math.sqrt(m_star * A)
