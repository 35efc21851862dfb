"""Static equilibrium of granules pressed by constant loads against each other, rigid walls and a
solid (`simulation.equilibrate`): the state a precompressed medium starts its dynamics from.

At rest the Tsuji damping (eq. 3) and the tanh friction (eq. 5) exert nothing, so equilibrium is
the balance of the Hertz forces (eq. 2) with the constant loads, the solid's contact points
displaced by its static compliance, u = C F_s (C = B K^-1 B'). Newton on the granules' positions
and the contact points' displacements, with the Hertz stiffness 3/2 A delta^(1/2) and the turn of
a pair's normal (f / d); Levenberg-Marquardt damping carries it from the initial, untouched
contacts (zero stiffness) into the loaded ones. A granule that a load pushes but nothing holds has
no equilibrium: that is an error naming it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu


class NoEquilibrium(ValueError):
    """The loads cannot be balanced (a granule pushed but not held)."""


@dataclass
class Equilibrium:
    pos: np.ndarray  # (n, 2) granule centres at equilibrium
    u: np.ndarray  # (nc, 2) the solid contact points' static displacement
    solid_forces: np.ndarray  # (nc, 2) force on the solid at each contact
    pair_forces: np.ndarray  # (m,) normal force of each loaded granule pair
    pair_overlaps: np.ndarray  # (m,) their overlaps [m]
    pairs: np.ndarray  # (m, 2) the loaded pairs
    wall_forces: np.ndarray  # (k,) normal force of each loaded granule-wall contact
    wall_overlaps: np.ndarray
    walls: np.ndarray  # (k, 2): granule, wall
    iterations: int
    residual: float  # the largest force imbalance on a granule [N]

    @property
    def max_overlap(self) -> float:
        return float(max(self.pair_overlaps.max(initial=0.0), self.wall_overlaps.max(initial=0.0)))

    def contacts(self, labels: list[str], wall_names: list[str]) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Every loaded contact: its name ('C:1-C:2', a granule and a wall 'C:20|far', a solid
        contact 'C:3|solid'), its normal force [N] and its overlap [m] (the solid's: its force only,
        overlap NaN)."""
        names = [f"{labels[i]}-{labels[j]}" for i, j in self.pairs] + \
            [f"{labels[g]}|{wall_names[w]}" for g, w in self.walls]
        force = np.concatenate([self.pair_forces, self.wall_forces])
        overlap = np.concatenate([self.pair_overlaps, self.wall_overlaps])
        return names, force, overlap

    def summary(self) -> dict:
        """Numbers for the run's attributes and summary."""
        fs = np.hypot(*self.solid_forces.T) if len(self.solid_forces) else np.zeros(0)
        return {"equilibrium_iterations": int(self.iterations), "equilibrium_residual_N": float(self.residual),
                "equilibrium_loaded_pairs": int(len(self.pairs)), "equilibrium_loaded_walls": int(len(self.walls)),
                "equilibrium_max_overlap_m": self.max_overlap,
                "equilibrium_max_pair_force_N": float(self.pair_forces.max(initial=0.0)),
                "equilibrium_max_wall_force_N": float(self.wall_forces.max(initial=0.0)),
                "equilibrium_max_solid_force_N": float(fs.max(initial=0.0))}


def constant_loads(system) -> np.ndarray:
    """(n, 2): the constant excitations (preloads) on each granule."""
    F = np.zeros((system.n, 2))
    for e in system.excitations:
        if e.history.kind == "constant":
            d = np.asarray(e.direction, float)
            F[e.granule] += e.history.params[0] * d / np.hypot(*d)
    return F


def hertz_force_stiffness(A, delta):
    """Force A delta^(3/2) and stiffness 3/2 A delta^(1/2) of loaded contacts (delta > 0), eq. (2)."""
    r = np.sqrt(np.maximum(delta, 0.0))
    return A * np.maximum(delta, 0.0) * r, 1.5 * A * r


def _outer(n):
    """n n' for rows of unit vectors n (m, 2): (m, 2, 2)."""
    return n[:, :, None] * n[:, None, :]


def _blocks(rows, cols, blocks, shape):
    """A sparse matrix from 2x2 blocks at block rows / columns (granule or contact indices)."""
    r = (2 * rows[:, None, None] + np.arange(2)[None, :, None]).repeat(2, axis=2)
    c = (2 * cols[:, None, None] + np.arange(2)[None, None, :]).repeat(2, axis=1)
    return sp.coo_matrix((blocks.ravel(), (r.ravel(), c.ravel())), shape=shape)


class _Balance:
    """The net forces on the granules and on the solid's contact points, and their derivatives, at
    positions x (n, 2) and contact displacements u (nc, 2)."""

    def __init__(self, system, model, loads):
        self.system, self.model, self.loads = system, model, loads
        self.n, self.nc = system.n, len(system.solid_contacts)

    def __call__(self, x, u):
        n, nc, m = self.n, self.nc, self.model
        R = self.system.radius
        F = self.loads.copy()
        Fs = np.zeros((nc, 2))
        Kxx, Kxu, Ksx, Ksu = [], [], [], []  # -dF/dx, -dF/du, dFs/dx, dFs/du as 2x2 blocks
        # granule pairs: the force on j is +f n, n from i to j
        i, j, A = m.pairs.i, m.pairs.j, m.pairs.A
        d = x[j] - x[i]
        dist = np.hypot(*d.T)
        on = R[i] + R[j] - dist > 0
        i, j, A, d, dist = i[on], j[on], A[on], d[on], dist[on]
        nrm = d / dist[:, None]
        f, k = hertz_force_stiffness(A, R[i] + R[j] - dist)
        np.add.at(F, j, f[:, None] * nrm)
        np.add.at(F, i, -f[:, None] * nrm)
        eye = np.eye(2)[None]
        S = k[:, None, None] * _outer(nrm) - (f / dist)[:, None, None] * (eye - _outer(nrm))  # -dF_j/dx_j
        Kxx += [(j, j, S), (i, i, S), (j, i, -S), (i, j, -S)]
        pair_data = (np.stack([i, j], axis=1), f, R[i] + R[j] - dist)
        # walls: the force on the granule is +f n_w
        g, w, A = m.walls.g, m.walls.w, m.walls.A
        rel = x[g] - m.walls.p0[w]
        along = np.einsum("ki,ki->k", rel, m.walls.tangent[w])
        delta = R[g] - np.einsum("ki,ki->k", rel, m.walls.normal[w])
        on = (delta > 0) & (along >= 0) & (along <= m.walls.length[w])
        g, w, A, delta = g[on], w[on], A[on], delta[on]
        nw = m.walls.normal[w]
        f, k = hertz_force_stiffness(A, delta)
        np.add.at(F, g, f[:, None] * nw)
        Kxx.append((g, g, k[:, None, None] * _outer(nw)))
        wall_data = (np.stack([g, w], axis=1), f, delta)
        # solid points: the force on the granule is -f n_c, on the solid +f n_c
        g, A = m.points.g, m.points.A
        nc_ = m.points.n
        gap = np.einsum("ki,ki->k", m.points.p + u - x[g], nc_)
        delta = R[g] - gap
        on = delta > 0
        f, k = hertz_force_stiffness(A, np.where(on, delta, 0.0))
        np.add.at(F, g, -f[:, None] * nc_)
        Fs[:] = f[:, None] * nc_
        kk = k[:, None, None] * _outer(nc_)
        idx = np.arange(len(g))
        Kxx.append((g, g, kk))
        Kxu.append((g, idx, -kk))
        Ksx.append((idx, g, kk))
        Ksu.append((idx, idx, -kk))

        def assemble(parts, shape):
            if not parts:
                return sp.csr_matrix(shape)
            rows = np.concatenate([p[0] for p in parts])
            cols = np.concatenate([p[1] for p in parts])
            return _blocks(rows, cols, np.concatenate([p[2] for p in parts]), shape).tocsr()

        K = (assemble(Kxx, (2 * n, 2 * n)), assemble(Kxu, (2 * n, 2 * nc)), assemble(Ksx, (2 * nc, 2 * n)),
             assemble(Ksu, (2 * nc, 2 * nc)))
        return F, Fs, K, pair_data, wall_data


def equilibrium(system, model, compliance=None, rtol: float = 1e-10, max_iterations: int = 200) -> Equilibrium:
    """The positions where the constant loads balance the contacts (and the solid's static
    compliance `compliance` (2nc, 2nc) at its contact points, None for a rigid solid), from the
    system's initial positions; `model` is the kernels' bundle of candidate contacts there."""
    n, nc = system.n, len(system.solid_contacts)
    loads = constant_loads(system)
    balance = _Balance(system, model, loads)
    elastic = compliance is not None and nc > 0 and np.any(compliance)
    C = np.asarray(compliance, float) if elastic else None
    x, u = system.pos0.astype(float).copy(), np.zeros((nc, 2))
    scale = max(np.abs(loads).max(initial=0.0), 1e-300)
    # the stiffness of a contact under the largest load: the Levenberg-Marquardt damping starts
    # there, and it turns the contact points' displacement residual into a force
    A_ref = np.concatenate([model.pairs.A, model.walls.A, model.points.A]).max(initial=1.0)
    k_ref = 1.5 * A_ref * np.sqrt((scale / A_ref) ** (2 / 3))
    tol = rtol * scale

    def residual(x, u):
        F, Fs, K, pairs, walls = balance(x, u)
        Ru = u.ravel() - C @ Fs.ravel() if elastic else np.zeros(0)
        merit = np.sqrt(np.sum(F * F) + k_ref**2 * np.sum(Ru * Ru))
        return F.ravel(), Ru, K, pairs, walls, Fs, merit

    F, Ru, K, pairs, walls, Fs, merit = residual(x, u)
    lam, it = k_ref, 0
    while np.abs(F).max(initial=0.0) > tol or k_ref * np.abs(Ru).max(initial=0.0) > tol:
        if it >= max_iterations:
            worst = int(np.argmax(np.abs(F).reshape(n, 2).max(axis=1)))
            raise NoEquilibrium(f"no equilibrium after {it} Newton iterations: granule {system.labels[worst]} is still "
                                f"off balance by {np.abs(F.reshape(n, 2)[worst]).max():.3e} N (is it held by a wall, a "
                                "neighbour or the solid against its load?)")
        it += 1
        Kxx, Kxu, Ksx, Ksu = K
        # Newton on [x, u]: K_xx dx + K_xu du = F, (I - C dFs/du) du - C dFs/dx dx = -Ru
        if elastic:
            Cs = sp.csr_matrix(C)
            J = sp.bmat([[Kxx + lam * sp.eye(2 * n), Kxu], [-Cs @ Ksx, sp.eye(2 * nc) - Cs @ Ksu]])
            rhs = np.concatenate([F, -Ru])
        else:
            J, rhs = Kxx + lam * sp.eye(2 * n), F
        try:
            step = splu(sp.csc_matrix(J)).solve(rhs)
        except RuntimeError:  # singular: lam vanished where nothing is held
            lam = max(4.0 * lam, k_ref)
            continue
        xt = x + step[: 2 * n].reshape(n, 2)
        ut = u + step[2 * n:].reshape(nc, 2) if elastic else u
        trial = residual(xt, ut)
        if trial[-1] < merit:
            x, u = xt, ut
            F, Ru, K, pairs, walls, Fs, merit = trial
            lam = max(lam / 10.0, 1e-12 * k_ref)
        else:
            lam *= 4.0
    return Equilibrium(x, u, Fs, pairs[1], pairs[2], pairs[0], walls[1], walls[2], walls[0], it,
                       float(np.abs(F).max(initial=0.0)))
