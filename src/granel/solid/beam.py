"""Euler-Bernoulli beam (eq. 9): Hermite cubic elements, deflection u_x along y.

Contact forces act on the neutral axis at the contact heights (mesh nodes); tangential forces
load nothing (the beam is axially rigid), so the contact points have no y DOF.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .base import ContactPoint, Material, Slab, SolidModel


def hermite_stiffness(EI: float, l: float) -> np.ndarray:
    return EI / l**3 * np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
                                 [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]])


def hermite_mass(rhoA: float, l: float) -> np.ndarray:
    return rhoA * l / 420 * np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                                      [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]])


def build_beam(slab: Slab, material: Material, contacts, n_elements=40, clamped=(True, True)) -> SolidModel:
    """The Euler-Bernoulli beam model (eq. 9) of the solid `slab`: Hermite cubic elements,
    consistent mass, the ends clamped where `clamped` says. contacts: list of (name, edge
    'left'/'right', y). Cross-section: depth = width (x), thickness (z); A = width * thickness,
    I = thickness * width^3 / 12 (Poisson's ratio unused)."""
    x0, y0, width, length, thickness = slab.x0, slab.y0, slab.width, slab.length, slab.thickness
    E, rho = material.E, material.rho
    A = width * thickness
    I = thickness * width**3 / 12.0
    l = length / n_elements
    nn = n_elements + 1
    ys = y0 + l * np.arange(nn)
    ke = hermite_stiffness(E * I, l)
    me = hermite_mass(rho * A, l)
    rows, cols, kv, mv = [], [], [], []
    for e in range(n_elements):
        d = np.arange(2 * e, 2 * e + 4)
        rows += list(np.repeat(d, 4))
        cols += list(np.tile(d, 4))
        kv += list(ke.ravel())
        mv += list(me.ravel())
    N = 2 * nn
    K = sp.csr_matrix((kv, (rows, cols)), shape=(N, N))
    M = sp.csr_matrix((mv, (rows, cols)), shape=(N, N))
    fixed = np.zeros(N, bool)
    if clamped[0]:
        fixed[[0, 1]] = True
    if clamped[1]:
        fixed[[N - 2, N - 1]] = True
    keep = np.flatnonzero(~fixed)
    red = -np.ones(N, dtype=np.int64)
    red[keep] = np.arange(len(keep))
    T = sp.csr_matrix((np.ones(len(keep)), (keep, np.arange(len(keep)))), shape=(N, len(keep)))
    Mr = (T.T @ M @ T).tocsr()
    Kr = (T.T @ K @ T).tocsr()
    cps = []
    for name, edge, y in contacts:
        node = int(round((y - y0) / l))
        if abs(ys[node] - y) > 1e-9 * length:
            raise ValueError(f"beam contact {name} at y = {y}: not on a node (element length {l:g} m); "
                             "choose beam_elements so that every contact height is a node")
        if red[2 * node] < 0:
            raise ValueError(f"beam contact {name} at y = {y}: on a clamped node")
        xe = x0 if edge == "left" else x0 + width
        nrm = (1.0, 0.0) if edge == "left" else (-1.0, 0.0)
        cps.append(ContactPoint(name, (xe, y), nrm, int(red[2 * node]), -1, int(red[2 * node + 1])))
    nodes = np.column_stack([np.full(nn, x0 + width / 2), ys])
    elems = np.column_stack([np.arange(n_elements), np.arange(1, nn)])

    def full(q):
        x = T @ q
        return np.column_stack([x[0::2], np.zeros(nn)])

    def energies(q, v):
        xq, xv = T @ q, T @ v
        kin = np.empty(n_elements)
        pot = np.empty(n_elements)
        for e in range(n_elements):
            d = slice(2 * e, 2 * e + 4)
            kin[e] = 0.5 * xv[d] @ me @ xv[d]
            pot[e] = 0.5 * xq[d] @ ke @ xq[d]
        return kin, pot

    info = {"dofs": int(len(keep)), "elements": int(n_elements), "nodes": int(nn), "EI": E * I, "rhoA": rho * A,
            "width": width, "thickness": thickness}
    model = SolidModel("beam", Mr, Kr, cps, info, T, nodes, elems, energies, np.full(n_elements, A * l), full)
    across = np.zeros(N)
    across[0::2] = 1.0  # a unit translation across the beam (x); along its axis it is held rigidly
    model.unit_weight = np.column_stack([T.T @ (M @ across), np.zeros(len(keep))])
    return model


def clamped_clamped_periods(E, rho, width, thickness, length, count=5) -> np.ndarray:
    """Exact Euler-Bernoulli periods: cos(bL) cosh(bL) = 1, w = (bL)^2 sqrt(EI / (rho A L^4))."""
    from scipy.optimize import brentq

    f = lambda x: np.cos(x) * np.cosh(x) - 1.0  # noqa: E731
    roots = [brentq(f, (n + 0.5) * np.pi - 0.5, (n + 0.5) * np.pi + 0.5) for n in range(1, count + 1)]
    A = width * thickness
    I = thickness * width**3 / 12.0
    w = np.array(roots) ** 2 * np.sqrt(E * I / (rho * A * length**4))
    return 2 * np.pi / w
