"""The interface shared by every solid model (plate, beam, rigid), and the protocol of a kind of
solid (`SolidKind`: what every layer above asks of one, implemented once per kind).

A solid is linear: M q'' + K q = B' F(t) in its reduced coordinates q (after clamping and the
rigid-layer constraints), where F stacks the 2D forces applied at its contact points and
B maps q to the contact points' displacements u = B q (2 rows per contact: x then y).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

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
    full_displacement: object = None  # callable(q) -> (n_nodes, 2); q (ndof, m) -> (n_nodes, 2, m)
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

    def element_energy_density(self, q, v) -> np.ndarray:
        """w of eq. (14) per element: (kinetic + strain energy) / volume [J/m^3]."""
        kin, pot = self.element_energies(q, v)
        return (np.asarray(kin) + np.asarray(pot)) / self.element_volume

    def energy(self, q, v) -> tuple[float, float]:
        """(kinetic 1/2 v'Mv, potential 1/2 q'Kq), eq. (11)."""
        return 0.5 * float(v @ (self.M @ v)), 0.5 * float(q @ (self.K @ q))


@dataclass(frozen=True)
class Shape:
    """A solid drawn in the granular plane [m]: its cells as polygons (P, k, 2), or its centre line
    (n, 2) when it is drawn as a line."""

    polygons: np.ndarray | None = None
    line: np.ndarray | None = None


@dataclass(frozen=True)
class Patches:
    """Cells of a solid (P, k, 2) [m] and a value on each (P,), e.g. the energy density (eq. 14)."""

    polygons: np.ndarray
    values: np.ndarray


# the relative frequency error of quadratic finite elements with consistent mass is (kl)^4 / 1440 at
# wavenumber k and element length l (docs/wavefield.md, "Which wavenumbers can be trusted"): the
# plate's Q8 sides, and an upper bound for the beam's Hermite cubics
QUADRATIC_DISPERSION = 1.0 / 1440.0


@dataclass(frozen=True)
class LineSampling:
    """How a solid's velocity is sampled along its length (the wavefield, docs/wavefield.md): lines
    at x (nl,) [m] standing for the mass per length `mass` (nl,) [kg/m], the velocity `components`
    sampled on each, `count` samples along the length, `element` the longest element along it [m],
    and `sampler(y)`: the sparse map from the full nodal DOFs (T q) to the samples at heights y,
    rows ordered (line, component, sample). `dispersion` (C, p): the elements' relative frequency
    error |C| (k l)^p at wavenumber k (l = element), as measured or derived for their kind.
    `whole`: the lines carry the solid's whole motion (a plate's columns across its width, a
    beam's axis), so their kinetic energy is the solid's; a surface standing across the granular
    plane is sampled on one line, z = 0, whose energy stands for a uniform motion across its depth."""

    x: np.ndarray
    mass: np.ndarray
    components: tuple[str, ...]
    count: int
    element: float
    sampler: Callable[[np.ndarray], sp.csr_matrix]
    dispersion: tuple[float, int] = (QUADRATIC_DISPERSION, 4)
    whole: bool = True


class SolidKind:
    """One kind of solid (plate, beam, rigid, ...): everything granel asks of a kind, so that no
    layer above the solids tests a kind's name. `name` is the scenario's solid.kind; `elastic`
    says whether it moves (has DOFs); `fields` are the [solid] fields it is built with;
    `stand_in` says it replaces any solid (the others' fields given with it are not refused).
    `section` arguments are the scenario's [solid] table, `material` its material record."""

    name = ""
    elastic = True
    stand_in = False
    fields: frozenset[str] = frozenset({"kind", "x0", "y0", "width", "length"})

    def check(self, section) -> None:
        """Refuse a [solid] table this kind cannot be built from: ValueError naming the field."""

    def layer(self, section) -> float:
        """The length of the rigid layer at a contact, as a fraction of the granule's radius."""
        return 0.0

    def recipe_fields(self, section, material) -> dict:
        """The `solid.recipe.SolidRecipe` fields (beyond kind and contacts) of this kind."""
        return dict(x0=section.x0, y0=section.y0, width=section.width, length=section.length)

    def build(self, recipe) -> SolidModel:
        """The solid of a `SolidRecipe` (ValueError for one that cannot be built)."""
        raise NotImplementedError

    def size(self, section, focus=()) -> tuple[int, int]:
        """(degrees of freedom, elements) the solid will have, at least, before it is built;
        `focus`: the contacts' heights y once the granules are placed (a mesh graded toward them
        counts them)."""
        return 0, 0

    def box(self, model: SolidModel) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1): the solid's extent in the granular plane [m]."""
        r = model.recipe
        if r is None:
            raise ValueError(f"a {self.name} solid built without a recipe has no known extent")
        return float(r.x0), float(r.y0), float(r.x0 + r.width), float(r.y0 + r.length)

    def shape(self, model: SolidModel, u: np.ndarray | None = None, scale: float = 0.0) -> Shape:
        """The solid drawn with its nodes moved by scale * u (u: (n_nodes, 2), as full_displacement)."""
        raise ValueError(f"a {self.name} solid has no elements to draw")

    def energy_cells(self, model: SolidModel, q, v) -> Patches:
        """The energy density w of eq. (14) on the cells that pictures colour."""
        raise ValueError(f"a {self.name} solid stores no energy")

    def export_cells(self, model: SolidModel) -> list[tuple[str, np.ndarray]]:
        """The solid's cells for meshio: (cell type, connectivity) pairs."""
        return []

    def stress(self, model: SolidModel, x: np.ndarray, E: float, nu: float) -> dict[str, np.ndarray]:
        """Stress cell data [Pa] of the full nodal DOF vector x = T q, by name."""
        return {}

    def mode_kinds(self, model: SolidModel, shapes, which) -> list[str]:
        """The kind of each mode `which` (columns of shapes): bending, axial or bulk."""
        return ["rigid" for _ in which]

    def wave_lines(self, model: SolidModel, samples: int | None = None) -> LineSampling:
        """How its wavefield is sampled (ValueError for a kind without one)."""
        raise ValueError(f"a {self.name} solid has no wavefield (a plate or a beam built from its recipe has)")

    def branches(self, model: SolidModel, k: np.ndarray, count: int = 3) -> dict[str, np.ndarray]:
        """Its analytic dispersion branches over wavenumbers k [rad/m]: frequency [Hz] by name."""
        raise ValueError(f"a {self.name} solid has no dispersion branches")


class RigidKind(SolidKind):
    """A rigid, immovable solid: no DOFs; its contact points never move."""

    name = "rigid"
    elastic = False
    stand_in = True  # `--solid rigid` replaces any solid of a scenario

    def build(self, recipe) -> SolidModel:
        return rigid_solid([(c.name, c.position, c.normal) for c in recipe.contacts])


def rigid_solid(contacts_positions: list[tuple[str, tuple[float, float], tuple[float, float]]]) -> SolidModel:
    """A rigid, immovable solid: no DOFs; its contact points never move."""
    z = sp.csr_matrix((0, 0))
    cps = [ContactPoint(n, p, nn, -1, -1, -1) for n, p, nn in contacts_positions]
    return SolidModel("rigid", z, z, cps, {"dofs": 0, "elements": 0})


ELEMENTS_LIMIT = 400  # the largest element count a hint proposes (the schema's bound on surface_elements)


def fitting_elements(y0: float, length: float, heights, at_least: int, even: bool = False) -> int | None:
    """The smallest element count n >= at_least (even for a disc, whose centre is a vertex) whose
    uniform grid y0 + i length / n holds every height (to the contact checks' 1e-9 of the length),
    or None up to ELEMENTS_LIMIT."""
    x = (np.asarray(heights, float) - y0) / length
    for n in range(max(2, at_least), ELEMENTS_LIMIT + 1):
        if even and n % 2:
            continue
        if np.all(np.abs(x * n - np.round(x * n)) <= 1e-9 * n):
            return n
    return None


def fitting_hint(y0: float, length: float, heights, at_least: int, even: bool = False) -> str:
    """What a refusal of a contact off the grid proposes: `fitting_elements`' count, or where to look."""
    n = fitting_elements(y0, length, heights, at_least, even)
    if n:
        return f"{n} is the first count from {at_least} that does"
    return f"no count up to {ELEMENTS_LIMIT} does: move the granules (center_y) or the solid (y0, length)"
