"""Newmark average acceleration (beta = 1/4, gamma = 1/2), eqs. (A1)-(A2), for M x'' + K x = F.

The factorisation of (M + K dt^2/4) is cached per step size: the paper's adaptive step takes
only a few distinct values (dtau0 / 2^n).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu


@dataclass
class NewmarkState:
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    t: float = 0.0

    def copy(self) -> "NewmarkState":
        return NewmarkState(self.x.copy(), self.v.copy(), self.a.copy(), self.t)


class Newmark:
    def __init__(self, M, K):
        self.M = sp.csc_matrix(M)
        self.K = sp.csc_matrix(K)
        self._lu = {}

    def factor(self, dt: float):
        key = float(dt)
        lu = self._lu.get(key)
        if lu is None:
            lu = splu((self.M + 0.25 * dt * dt * self.K).tocsc())
            self._lu[key] = lu
        return lu

    def initial(self, x0=None, v0=None, F0=None) -> NewmarkState:
        n = self.M.shape[0]
        x = np.zeros(n) if x0 is None else np.asarray(x0, float).copy()
        v = np.zeros(n) if v0 is None else np.asarray(v0, float).copy()
        rhs = -(self.K @ x) + (0.0 if F0 is None else F0)
        a = splu(self.M).solve(rhs) if n and np.any(rhs) else np.zeros(n)
        return NewmarkState(x, v, a, 0.0)

    def predictor(self, s: NewmarkState, dt: float) -> np.ndarray:
        """The force-independent part of a_{s+1}: -(M + K dt^2/4)^-1 K (x + v dt + a dt^2/4)."""
        return -self.factor(dt).solve(self.K @ (s.x + s.v * dt + 0.25 * dt * dt * s.a))

    def step(self, s: NewmarkState, F_next, dt: float, a_pred=None) -> NewmarkState:
        """One step (A2); F_next is the load at t + dt."""
        lu = self.factor(dt)
        a_new = (self.predictor(s, dt) if a_pred is None else a_pred) + (lu.solve(F_next) if F_next is not None else 0.0)
        return self.finish(s, a_new, dt)

    @staticmethod
    def finish(s: NewmarkState, a_new, dt: float) -> NewmarkState:
        aa = 0.5 * (s.a + a_new)
        return NewmarkState(s.x + s.v * dt + 0.5 * aa * dt * dt, s.v + aa * dt, np.asarray(a_new, float), s.t + dt)


def newmark_period_ratio(omega: float, dt: float) -> float:
    """T_numerical / T of the average-acceleration method: w dt / (2 arctan(w dt / 2))."""
    x = omega * dt
    return x / (2.0 * np.arctan(0.5 * x))
