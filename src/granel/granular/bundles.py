"""Typed bundles of the arrays the compiled kernels read (numba accepts these NamedTuples as one
argument each, and caches the compiled code), and the granular state's layout.

The granular state y (n granules, float64) is laid out once, here, and read through the offsets
(compiled code) or `state_views` (Python):
    y[0:2n]     centre positions, interleaved (x0, y0, x1, y1, ...)
    y[2n:3n]    rotations theta                              (`theta_offset`)
    y[3n:5n]    velocities, interleaved                      (`velocity_offset`)
    y[5n:6n]    spins omega                                  (`spin_offset`)
    y[6n:6n+3]  accumulated viscous dissipation, friction dissipation and input work, so that RK4
                integrates the energy balance (13) at its own order (`ledger_offset` + ACC_*).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..guard.jit import njit

ACC_VISC, ACC_FRIC, ACC_WORK = 0, 1, 2
LEDGER_SIZE = 3  # the accumulators


def state_size(n: int) -> int:
    return 6 * n + LEDGER_SIZE


@njit(cache=True, inline="always")
def theta_offset(n):
    return 2 * n


@njit(cache=True, inline="always")
def velocity_offset(n):
    return 3 * n


@njit(cache=True, inline="always")
def spin_offset(n):
    return 5 * n


@njit(cache=True, inline="always")
def ledger_offset(n):
    return 6 * n


class StateViews(NamedTuple):
    """Named views of granular states y (..., 6n+3): positions and velocities (..., n, 2),
    rotations and spins (..., n), and the ledger's accumulators (...) of eq. (13)."""

    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    spin: np.ndarray
    dissipated_viscous: np.ndarray
    dissipated_friction: np.ndarray
    input_work: np.ndarray


def state_views(y: np.ndarray, n: int) -> StateViews:
    """`StateViews` of y (one state, or states along the leading axes); writing a view writes y."""
    lead = y.shape[:-1]
    acc = 6 * n
    return StateViews(y[..., : 2 * n].reshape(*lead, n, 2), y[..., 2 * n: 3 * n], y[..., 3 * n: 5 * n].reshape(*lead, n, 2),
                      y[..., 5 * n: 6 * n], y[..., acc + ACC_VISC], y[..., acc + ACC_FRIC], y[..., acc + ACC_WORK])


class Granules(NamedTuple):
    """Each granule's radius, mass and moment of inertia (n,), its weight m g (n, 2) and the
    centre its gravitational potential is measured from (n, 2; the centres as built)."""

    radius: np.ndarray  # (n,)
    mass: np.ndarray
    inertia: np.ndarray
    weight: np.ndarray  # (n, 2) [N]
    datum: np.ndarray  # (n, 2) [m]


class Law(NamedTuple):
    """Eq. (5)'s friction coefficient and tanh smoothness."""

    mu: float
    k_s: float


class Pairs(NamedTuple):
    """Granule-granule candidate contacts with their Hertz (A) and damping (G) coefficients, eq. (3)."""

    i: np.ndarray
    j: np.ndarray
    A: np.ndarray
    G: np.ndarray


class Walls(NamedTuple):
    """Granule-wall candidates (granule g, wall w, A, G) and the walls' geometry (per wall)."""

    g: np.ndarray
    w: np.ndarray
    A: np.ndarray
    G: np.ndarray
    p0: np.ndarray  # (nw, 2) start point
    tangent: np.ndarray  # (nw, 2) unit vector from p0 to p1
    length: np.ndarray  # (nw,)
    normal: np.ndarray  # (nw, 2) unit normal into the granular side
    drive: np.ndarray  # (nw, 6) a moving wall's `granular.loads.WallDrive.params` (frequency 0: at rest)


class Points(NamedTuple):
    """Granule-solid contact points: granule g, rest position p, unit normal n (granule -> solid)."""

    g: np.ndarray
    p: np.ndarray  # (nc, 2)
    n: np.ndarray  # (nc, 2)
    A: np.ndarray
    G: np.ndarray


class Loads(NamedTuple):
    """Applied forces: granule g, unit direction, history kind and parameters, tabulated values."""

    g: np.ndarray
    direction: np.ndarray  # (ne, 2)
    kind: np.ndarray
    params: np.ndarray  # (ne, laws.LOAD_PARAMS)
    offset: np.ndarray  # (ne + 1,) into tab_t / tab_v
    tab_t: np.ndarray
    tab_v: np.ndarray


class GranularModel(NamedTuple):
    """Everything the right-hand side of eq. (1) reads, besides the state and the solid's motion."""

    granules: Granules
    law: Law
    pairs: Pairs
    walls: Walls
    points: Points
    loads: Loads


class Motion(NamedTuple):
    """The solid contact points' motion inside a step, the quintic
    u(tau) = u0 + v0 tau + a tau^2/2 + j tau^3/6 + d4 tau^4/24 + d5 tau^5/120,
    (nc, 2) each: the constant-average-acceleration interpolation (A3) has j = d4 = d5 = 0; the
    exact modal integrator passes the polynomial through the points' exact displacements and
    velocities at the nodes of its force model (a cubic for two nodes, a quintic for three).
    Zero for a rigid solid."""

    u0: np.ndarray
    v0: np.ndarray
    a: np.ndarray
    j: np.ndarray
    d4: np.ndarray
    d5: np.ndarray


def still(nc: int) -> Motion:
    z = np.zeros((nc, 2))
    return Motion(z, z, z, z, z, z)


class InterfaceForces(NamedTuple):
    """Filled by `kernels.interface_forces`: forces on the solid at its contact points, |N|, the
    relative tangential velocity, and d(force)/d(displacement), d(force)/d(velocity) per point."""

    F: np.ndarray  # (nc, 2)
    normal: np.ndarray  # (nc,)
    vrel: np.ndarray  # (nc,)
    Du: np.ndarray  # (nc, 2, 2)
    Dw: np.ndarray  # (nc, 2, 2)


@njit(cache=True)
def interface_buffers(nc):
    """Zeroed `InterfaceForces` for nc contact points (callable from compiled code)."""
    return InterfaceForces(np.zeros((nc, 2)), np.zeros(nc), np.zeros(nc), np.zeros((nc, 2, 2)), np.zeros((nc, 2, 2)))


@njit(cache=True)
def motion_buffers(nc):
    """A zeroed `Motion` of nc contact points, each coefficient its own array (scratch)."""
    return Motion(np.zeros((nc, 2)), np.zeros((nc, 2)), np.zeros((nc, 2)), np.zeros((nc, 2)), np.zeros((nc, 2)),
                  np.zeros((nc, 2)))
