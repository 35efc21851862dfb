"""The interface shared by every solid model (plate, beam, rigid).

A solid is linear: M q'' + K q = B' F(t) in its reduced coordinates q (after clamping and the
rigid-layer constraints), where F stacks the 2D forces applied at its contact points and
B maps q to the contact points' displacements u = B q (2 rows per contact: x then y).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Slab:
    """Where an elastic solid lies: the rectangle x0 <= x <= x0 + width, y0 <= y <= y0 + length in
    the granular plane [m], and its thickness out of that plane [m]."""

    x0: float
    y0: float
    width: float
    length: float
    thickness: float


@dataclass(frozen=True)
class Material:
    """An isotropic linear elastic material (of a solid or of the granules)."""

    E: float  # Young's modulus [Pa]
    rho: float  # density [kg/m^3]
    nu: float  # Poisson's ratio [-]


@dataclass(frozen=True)
class ContactPoint:
    """Where a granule touches the solid: position, unit normal n_ik (granule -> solid), and
    the reduced DOFs of the driven motion (-1 where the model has none)."""

    name: str
    position: tuple[float, float]
    normal: tuple[float, float]
    dof_x: int
    dof_y: int
    dof_rotation: int = -1


# the largest |K q - W g| / |W g| of a solid's sag: far above a factorisation's round-off for a
# held solid (its condition number times eps), far below a singular one's
SAG_RESIDUAL = 1e-6


@dataclass
class SolidModel:
    kind: str
    M: sp.csr_matrix
    K: sp.csr_matrix
    contacts: list[ContactPoint]
    info: dict = field(default_factory=dict)
    # full-field recovery and plotting (None for the rigid solid)
    T: sp.csr_matrix | None = None  # full nodal DOFs = T q
    nodes: np.ndarray | None = None  # (n_nodes, 2) coordinates
    elements: np.ndarray | None = None  # (n_elements, k) node indices
    element_energies: object = None  # callable(q, v) -> (kinetic (ne,), strain (ne,))
    element_volume: np.ndarray | None = None
    full_displacement: object = None  # callable(q) -> (n_nodes, 2)
    recipe: object = None  # what it was built from (`solid.recipe.SolidRecipe`), if known
    unit_weight: np.ndarray | None = None  # (ndof, 2) T' M_full e_x, T' M_full e_y: the weight per m/s^2

    def unit_weights(self) -> np.ndarray:
        """(ndof, 2): the generalised forces of the solid's own mass under a unit acceleration along x
        and along y (T' M e with M its unreduced consistent mass), so that its weight is this @ g."""
        if self.unit_weight is None:
            return np.zeros((self.ndof, 2))
        return self.unit_weight

    def sag(self, gravity) -> np.ndarray:
        """(nc, 2) how far the solid's own weight moves its contact points [m]: u = B K^-1 W g (the
        static deflection, about which a linear solid's motion is the same as without its weight).
        ValueError if its supports leave it free to move under its weight."""
        nc, g = len(self.contacts), np.asarray(gravity, float)
        if self.ndof == 0 or not g.any():
            return np.zeros((nc, 2))
        f = self.unit_weights() @ g
        if not f.any():  # its weight acts only along directions it is held rigidly (a beam's axis)
            return np.zeros((nc, 2))
        from scipy.sparse.linalg import splu

        free = ValueError(f"the {self.kind} is free to move under its own weight: nothing holds it (clamp an end, "
                          "solid.clamped)")
        try:
            q = splu(self.K.tocsc()).solve(f)
        except RuntimeError:  # an exactly singular stiffness
            raise free from None
        residual = np.linalg.norm(self.K @ q - f)
        if not (np.isfinite(q).all() and residual <= SAG_RESIDUAL * np.linalg.norm(f)):
            raise free
        return (self.contact_map() @ q).reshape(nc, 2)

    @property
    def ndof(self) -> int:
        return self.M.shape[0]

    @property
    def nelements(self) -> int:
        return 0 if self.elements is None else len(self.elements)

    def contact_map(self) -> sp.csr_matrix:
        """B: (2 nc, ndof), u_contacts.ravel() = B q."""
        rows, cols = [], []
        for k, c in enumerate(self.contacts):
            if c.dof_x >= 0:
                rows.append(2 * k)
                cols.append(c.dof_x)
            if c.dof_y >= 0:
                rows.append(2 * k + 1)
                cols.append(c.dof_y)
        return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * len(self.contacts), self.ndof))

    def energy(self, q, v) -> tuple[float, float]:
        """(kinetic 1/2 v'Mv, potential 1/2 q'Kq), eq. (11)."""
        return 0.5 * float(v @ (self.M @ v)), 0.5 * float(q @ (self.K @ q))


def rigid_solid(contacts_positions: list[tuple[str, tuple[float, float], tuple[float, float]]]) -> SolidModel:
    """A rigid, immovable solid: no DOFs; its contact points never move."""
    z = sp.csr_matrix((0, 0))
    cps = [ContactPoint(n, p, nn, -1, -1, -1) for n, p, nn in contacts_positions]
    return SolidModel("rigid", z, z, cps, {"dofs": 0, "elements": 0})
