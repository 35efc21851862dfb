"""The quantities recorded at every output, computed in one compiled pass over a batch of outputs:
each medium's energy (11), the solid's energy, the deepest overlap (eq. 2) and the force on each
wall."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..granular.kernels import granule_energies, overlaps, wall_forces
from ..guard.jit import njit


class OutputQuantities(NamedTuple):
    """Filled by `output_quantities` for a batch of K outputs."""

    media: np.ndarray  # (K, n_media)
    solid: np.ndarray  # (K, 2): kinetic, potential
    su: np.ndarray  # (K, nc, 2)
    overlap: np.ndarray  # (K,)
    where: np.ndarray  # (K, 2) int: kind, index
    walls: np.ndarray  # (K, n_walls, 2): the force each wall takes


@njit(cache=True)
def output_quantities(oy, oeta, oetad, model, solid, medium, n_media, q, times):
    """Per output o of a batch: each medium's energy (11) in q.media[o], the solid's kinetic and
    potential energy, the contacts' displacement, the deepest overlap (eq. 2) over the smaller
    radius with its kind (0 pair, 1 wall, 2 solid) and index, and the force on each wall (at the
    outputs' `times`, for moving walls)."""
    nc = solid.P.shape[0] // 2
    radius = model.granules.radius
    pairs, walls, points = model.pairs, model.walls, model.points
    for o in range(oy.shape[0]):
        su = np.dot(solid.P, oeta[o]) if solid.P.shape[1] else np.zeros(2 * nc)
        ep = 0.0
        for i in range(oeta.shape[1]):
            ep += 0.5 * solid.omega[i] ** 2 * oeta[o, i] ** 2
        q.solid[o, 0] = 0.5 * np.dot(oetad[o], oetad[o])
        q.solid[o, 1] = ep
        sup = su.reshape(nc, 2)
        q.su[o, :, :] = sup
        kin, rot, pot = granule_energies(oy[o], model, sup)
        for m in range(n_media):
            q.media[o, m] = 0.0
        for i in range(kin.shape[0]):
            q.media[o, medium[i]] += kin[i] + rot[i] + pot[i]
        dp, dw, ds = overlaps(oy[o], model, sup)
        best, kind, idx = 0.0, -1, -1
        for c in range(dp.shape[0]):
            r = dp[c] / min(radius[pairs.i[c]], radius[pairs.j[c]])
            if r > best:
                best, kind, idx = r, 0, c
        for c in range(dw.shape[0]):
            r = dw[c] / radius[walls.g[c]]
            if r > best:
                best, kind, idx = r, 1, c
        for c in range(ds.shape[0]):
            r = ds[c] / radius[points.g[c]]
            if r > best:
                best, kind, idx = r, 2, c
        q.overlap[o] = best
        q.where[o, 0] = kind
        q.where[o, 1] = idx
        wall_forces(oy[o], model, q.walls[o], times[o])
