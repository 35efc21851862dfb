"""A tensioned membrane standing across the granular plane, optionally on an elastic foundation
(the "elastically supported membrane" of Zhang, Potekin, Li & Vakakis, Int. J. Solids Struct.
182, 46, 2020): rho h w_tt - N lap w + k_f w = p, with N the tension per length [N/m] and k_f the
foundation's stiffness per area [N/m^3]. Quadratic Lagrange triangles (scikit-fem's ElementTriP2)
on the grid of `surface.standing_surface`; docs/solids.md ("Membrane")."""

from __future__ import annotations

import numpy as np

from .base import Material, Slab, SolidModel
from .bending_plate import BendingPlateKind
from .surface import standing_surface, surface_model
from .dispersion import string_frequency


def membrane_forms(tension: float, foundation: float, rho_h: float):
    """(stiffness, mass, strain energy density, kinetic energy density): a(w, v) = int N grad w .
    grad v + k_f w v, m(w, v) = int rho h w v."""
    from skfem import BilinearForm, Functional
    from skfem.helpers import dot, grad

    @BilinearForm
    def stiffness(u, v, _):
        return tension * dot(grad(u), grad(v)) + foundation * u * v

    @BilinearForm
    def mass(u, v, _):
        return rho_h * u * v

    @Functional
    def strain(w):
        return 0.5 * (tension * dot(grad(w["u"]), grad(w["u"])) + foundation * w["u"] ** 2)

    @Functional
    def kinetic(w):
        return 0.5 * rho_h * w["speed"] ** 2

    return stiffness, mass, strain, kinetic


def build_membrane(slab: Slab, material: Material, contacts, n_along: int = 24, edges=("fixed",) * 4,
                   tension: float = 0.0, foundation: float = 0.0, shape: str = "rectangle", refine: int = 0) -> SolidModel:
    """The membrane of `slab` (h = width, its thickness along x; the length along y; its depth
    along z = thickness, centred on the granular plane), `tension` N [N/m] and `foundation` k_f
    [N/m^3], on `standing_surface`'s P2 triangles (a disc's diameter the length). edges: a
    rectangle's (bottom, top, front, back), a disc's (rim,), each 'fixed' (w = 0) or 'free'. ValueError if it is free to move as a rigid body (no edge fixed, no
    foundation), or for a contact off a vertex of z = 0 or on a fixed edge. `refine`: the mesh
    graded toward the contacts (`surface.refined_toward`)."""
    from skfem import ElementTriP2

    if foundation == 0 and all(e == "free" for e in edges):
        raise ValueError(f"solid.edges = {list(edges)}: a membrane with every edge free and no foundation moves as a "
                         "rigid body; fix an edge or give it a foundation (solid.foundation)")
    surface = standing_surface(slab, ElementTriP2(), n_along, shape, refine, [c[2] for c in contacts])
    basis = surface.basis
    rho_h = material.rho * slab.width
    stiffness, mass, strain, kinetic = membrane_forms(tension, foundation, rho_h)
    K, M = stiffness.assemble(basis).tocsr(), mass.assemble(basis).tocsr()
    fixed = np.zeros(basis.N, bool)
    for side, how in zip(surface.edge_facets, edges, strict=True):
        if how == "fixed":
            fixed[basis.get_dofs(surface.edge_facets[side]).all()] = True
    return surface_model("membrane", surface, K, M, fixed, np.ones(basis.N), contacts, strain, kinetic,
                         {"tension": float(tension), "foundation": float(foundation), "rhoh": rho_h,
                          "thickness": slab.width})


class MembraneKind(BendingPlateKind):
    """The tensioned membrane (`build_membrane`), seen edge-on as the plate in bending is."""

    name = "membrane"
    fields = BendingPlateKind.fields - {"plate_theory"} | {"tension", "foundation"}

    edge_kinds = ("fixed", "free")
    # P2's frequency error at wavenumber K and element l: +0.0012 (K l)^4 at most, measured against the
    # fixed rectangle's exact modes (tests/test_membrane.py; docs/solids.md)
    dispersion = (0.0012, 4)
    disc_edge_kinds = ("fixed",)  # free only on a foundation

    def check(self, section) -> None:
        if not section.tension > 0:
            raise ValueError("solid.tension: a membrane needs a tension > 0 [N/m] (its tension per length)")
        super().check(section)  # edges fixed or free; all free only on a foundation

    def recipe_fields(self, section, material) -> dict:
        return super().recipe_fields(section, material) | dict(tension=section.tension, foundation=section.foundation)

    def build(self, recipe) -> SolidModel:
        r = recipe
        return build_membrane(r.slab, r.material, [(c.name, c.edge, c.position[1]) for c in r.contacts],
                              r.beam_elements, r.edges, r.tension, r.foundation, r.shape, r.refinement)

    def size(self, section, focus=()) -> tuple[int, int]:
        """P2: a DOF per vertex and per edge of the grid, as Morley has."""
        return super().size(section, focus)

    def stress(self, model, x, E, nu):
        """The membrane stress N / h in every segment (its prestress)."""
        return {"tension_stress": np.full(model.nelements, model.info["tension"] / model.info["width"])}

    def branches(self, model, k, count=3):
        """w^2 = (N k^2 + k_f) / rho h for waves along y: cut on at sqrt(k_f / rho h) / 2 pi."""
        i = model.info
        return {"membrane": string_frequency(k, i["tension"], i["rhoh"], 0.0, i["foundation"])}


MEMBRANE = MembraneKind()
