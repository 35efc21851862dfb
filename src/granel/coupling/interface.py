"""The granular-solid interface seen from the solid: per step size, the Newmark response of the
contact points to interface forces, and the friction stability eigenvalues (10)/(A9).

With S(dt) = M + K dt^2/4, Newmark (A2) gives a_{s+1} = a_pred + S^-1 B' F_{s+1}, where B picks
the contact points' (x, y) displacements from the reduced DOFs. We precompute, once per step
size, Z = S^-1 B' (ndof x 2nc) and C = B Z (2nc x 2nc): each fixed-point iteration of the paper's
algorithm then costs a 2nc-vector product instead of a sparse solve, with identical iterates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solid.base import SolidModel
from ..solid.newmark import Newmark


@dataclass
class StepOperators:
    dt: float
    Z: np.ndarray  # (ndof, 2nc): S^-1 B'
    C: np.ndarray  # (2nc, 2nc): B S^-1 B'
    c_tangent: np.ndarray  # (nc,): t' C_kk t, the tangential compliance of (A8) without dt/2


class Interface:
    def __init__(self, model: SolidModel, newmark: Newmark, tangents: np.ndarray):
        self.model = model
        self.newmark = newmark
        self.B = model.contact_map()
        self.Bt = self.B.T.tocsc()
        self.tangents = np.asarray(tangents, float)  # (nc, 2): t_k = k x n_k
        self.nc = len(model.contacts)
        self.has_tangent = np.array([c.dof_y >= 0 for c in model.contacts], bool)
        self._ops: dict[float, StepOperators] = {}

    def operators(self, dt: float) -> StepOperators:
        key = float(dt)
        ops = self._ops.get(key)
        if ops is None:
            nc = self.nc
            if self.model.ndof == 0:
                Z = np.zeros((0, 2 * nc))
            else:
                lu = self.newmark.factor(dt)
                Z = lu.solve(self.Bt.toarray())
            C = np.asarray(self.B @ Z) if self.model.ndof else np.zeros((2 * nc, 2 * nc))
            ct = np.zeros(nc)
            for k in range(nc):
                t = self.tangents[k]
                blk = C[2 * k : 2 * k + 2, 2 * k : 2 * k + 2]
                ct[k] = t @ blk @ t if self.has_tangent[k] else 0.0
            ops = StepOperators(dt, Z, C, ct)
            self._ops[key] = ops
        return ops

    def friction_eigenvalues(self, dt: float, mu: float, k_s: float, normal: np.ndarray, vrel: np.ndarray) -> np.ndarray:
        """|lambda_k| of (A9): 1/2 mu k_s |N_k| dt T (M + K dt^2/4)^-1 T' / cosh^2(k_s v_t,k)."""
        ct = self.operators(dt).c_tangent
        return 0.5 * mu * k_s * np.abs(normal) * dt * ct / np.cosh(np.minimum(np.abs(k_s * vrel), 350.0)) ** 2
