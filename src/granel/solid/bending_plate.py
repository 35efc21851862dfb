"""A thin (Kirchhoff) plate standing across the granular plane: its mid-surface is the plane
x = x0 + h/2 spanning y (the granular plane's `length`) and z (out of it, the `thickness` field),
h = `width` its own thickness; granules touch its faces x0, x0 + h on the line z = 0 and it bends
along x: rho h w_tt + D lap^2 w = p, D = E h^3 / 12 (1 - nu^2). Morley elements (scikit-fem's
ElementTriMorley: vertex values and edge normal slopes, P2, non-conforming); docs/solids.md
("Plate in bending")."""

from __future__ import annotations

import numpy as np

from .base import Material, Slab, SolidModel
from .beam import BeamKind
from .dispersion import string_frequency
from .surface import REFINE_ZONE, disc_mesh, refined_toward  # noqa: F401 (the surfaces' meshes, re-exported)
from .surface import check_held, flexural_rigidity, standing_surface, surface_model


def kirchhoff_forms(D: float, nu: float, rho_h: float, foundation: float = 0.0):
    """(stiffness, mass, strain energy density, kinetic energy density) of the Kirchhoff plate on
    a foundation of stiffness k_f per area: a(w, v) = int D ((1 - nu) w_,ij v_,ij + nu lap w lap v)
    + k_f w v, m(w, v) = int rho h w v."""
    from skfem import BilinearForm, Functional
    from skfem.helpers import dd, ddot, eye, trace

    def moments(T):
        return D * ((1.0 - nu) * T + nu * eye(trace(T), 2))

    @BilinearForm
    def stiffness(u, v, _):
        return ddot(moments(dd(u)), dd(v)) + foundation * u * v

    @BilinearForm
    def mass(u, v, _):
        return rho_h * u * v

    @Functional
    def strain(w):
        return 0.5 * (ddot(moments(dd(w["u"])), dd(w["u"])) + foundation * w["u"] ** 2)

    @Functional
    def kinetic(w):
        return 0.5 * rho_h * w["speed"] ** 2

    return stiffness, mass, strain, kinetic


def build_bending_plate(slab: Slab, material: Material, contacts, n_along: int = 24, edges=("clamped",) * 4,
                        shape: str = "rectangle", refine: int = 0, foundation: float = 0.0) -> SolidModel:
    """The Kirchhoff plate of `slab` (h = width, along x; the length along y; its depth along z =
    thickness, centred on the granular plane; a disc's diameter the length) on
    `standing_surface`'s Morley triangles. edges: a rectangle's (bottom, top, front, back), a
    disc's (rim,), each 'clamped' (w and its normal slope held), 'simple' (w held) or 'free'.
    contacts: (name, edge 'left'/'right', y), each on a vertex of z = 0. `foundation`: a Winkler
    foundation's stiffness per area k_f [N/m^3] under its whole face (0: none). ValueError for edges
    that leave it free to move as a rigid body on no foundation, or a contact off a vertex or on a
    held edge. `refine`: the mesh graded toward the contacts (`refined_toward`)."""
    from skfem import ElementTriMorley

    surface = standing_surface(slab, ElementTriMorley(), n_along, shape, refine, [c[2] for c in contacts])
    mesh, basis = surface.mesh, surface.basis
    D, rho_h = flexural_rigidity(material.E, material.nu, slab.width), material.rho * slab.width
    stiffness, mass, strain, kinetic = kirchhoff_forms(D, material.nu, rho_h, foundation)
    K, M = stiffness.assemble(basis).tocsr(), mass.assemble(basis).tocsr()
    fixed = np.zeros(basis.N, bool)
    for side, how in zip(surface.edge_facets, edges, strict=True):
        dofs = basis.get_dofs(surface.edge_facets[side])
        if how == "clamped":
            fixed[dofs.all()] = True
        elif how == "simple":
            fixed[dofs.nodal["u"]] = True
    # the rigid motions w = a + b y + c z (exact in Morley: vertex values, edge normal slopes)
    u_dofs, p = basis.nodal_dofs[0], mesh.p
    rigid = np.zeros((basis.N, 3))
    rigid[u_dofs, 0], rigid[u_dofs, 1], rigid[u_dofs, 2] = 1.0, p[0], p[1]  # the mesh's frame
    slopes = _facet_normals(mesh)
    rigid[basis.facet_dofs[0], 1], rigid[basis.facet_dofs[0], 2] = slopes[0], slopes[1]
    check_held(rigid, fixed, edges, foundation)
    return surface_model("bending_plate", surface, K, M, fixed, rigid[:, 0], contacts, strain, kinetic,
                         {"D": D, "rhoh": rho_h, "thickness": slab.width, "foundation": float(foundation)})



def _facet_normals(mesh) -> np.ndarray:
    """(2, n_facets) a unit normal of each facet of a triangle mesh, in skfem's orientation for
    ElementTriMorley's normal-slope DOF (the facet's tangent turned by -90 degrees)."""
    a, b = mesh.p[:, mesh.facets[0]], mesh.p[:, mesh.facets[1]]
    t = (b - a) / np.linalg.norm(b - a, axis=0)
    return np.vstack([t[1], -t[0]])


class BendingPlateKind(BeamKind):
    """The Kirchhoff plate standing across the granular plane (`build_bending_plate`), seen edge-on:
    drawn, exported and sampled along its line z = 0 as a beam is along its axis."""

    name = "bending_plate"
    line_is_whole = False  # sampled on its line z = 0 alone (`LineSampling.whole`)
    fields = BeamKind.fields - {"beam_elements", "clamped"} | {"edges", "surface_elements", "shape", "contact_refinement",
                                                              "plate_theory", "foundation"}

    edge_kinds = ("clamped", "simple", "free")  # the first is the default
    # Morley's frequency error at wavenumber K and element l: -0.18 (K l)^2 as K l -> 0 for waves along
    # the grid's lines, less across them (-0.14 diagonally), measured against simply supported
    # strips' exact modes (tests/test_bending_plate.py; docs/solids.md); 0.185 bounds it
    dispersion = (0.185, 2)
    disc_edge_kinds = ("clamped",)  # a disc's rim: simply supported is refused (Babuska's paradox), free moves

    def edges(self, section) -> tuple[str, ...]:
        """Its edges as the [solid] table gives them (a rectangle's four, a disc's rim), or the
        default for each."""
        count = 1 if section.shape == "disc" else 4
        return tuple(section.edges) if section.edges is not None else (self.edge_kinds[0],) * count

    def check(self, section) -> None:
        edges = self.edges(section)
        if any(e not in self.edge_kinds for e in edges):
            raise ValueError(f"solid.edges = {list(edges)}: a {self.name}'s edges are each one of "
                             f"{', '.join(self.edge_kinds)}")
        if section.shape == "disc":
            self._check_disc(section, edges)
        elif len(edges) != 4:
            raise ValueError(f"solid.edges = {list(edges)}: a rectangular {self.name} has four edges (bottom, top, "
                             "front, back)")
        if all(e == "free" for e in edges) and not section.foundation:
            raise ValueError(f"solid.edges: a {self.name} with every edge free moves as a rigid body; hold an edge")

    def _check_disc(self, section, edges) -> None:
        """A disc: one edge (its rim) of `disc_edge_kinds`, an even count of elements along its
        diameter (its centre a node), and its depth its diameter (`thickness` is not read: left at
        its default or equal to the length)."""
        if len(edges) != 1:
            raise ValueError(f"solid.edges = {list(edges)}: a disc has one edge, its rim: give one value")
        if edges[0] not in self.disc_edge_kinds and not (edges[0] == "free" and section.foundation):
            why = ("on the polygon that meshes the rim the solution tends to a different plate's (Babuska's paradox)"
                   if edges[0] == "simple" else "a free rim leaves it free to move as a rigid body")
            raise ValueError(f"solid.edges = {list(edges)}: a {self.name} disc's rim is "
                             f"{' or '.join(self.disc_edge_kinds)} ({why})")
        if section.surface_elements % 2:
            raise ValueError(f"solid.surface_elements = {section.surface_elements}: a disc's diameter holds an even "
                             "count of elements (its centre is a node)")
        if section.thickness not in (section.length, type(section).model_fields["thickness"].default):
            raise ValueError(f"solid.thickness = {section.thickness:g}: a disc's depth across the granular plane is its "
                             f"diameter, solid.length = {section.length:g}; leave thickness out")

    def recipe_fields(self, section, material) -> dict:
        edges = self.edges(section)
        depth = section.length if section.shape == "disc" else section.thickness
        return dict(x0=section.x0, y0=section.y0, width=section.width, length=section.length,
                    thickness=depth, E=material.E, rho=material.rho, nu=material.nu,
                    beam_elements=section.surface_elements, edges=edges, shape=section.shape,
                    refinement=section.contact_refinement, theory=section.plate_theory, foundation=section.foundation,
                    clamped=(edges[0] != "free", edges[min(1, len(edges) - 1)] != "free"))

    def build(self, recipe) -> SolidModel:
        """Kirchhoff's thin plate on Morley triangles, or with `plate_theory = "mindlin"` the thick
        plate of `mindlin.build_mindlin_plate`."""
        r = recipe
        if r.theory == "mindlin":
            from .mindlin import build_mindlin_plate

            builder = build_mindlin_plate
        else:
            builder = build_bending_plate
        return builder(r.slab, r.material, [(c.name, c.edge, c.position[1]) for c in r.contacts], r.beam_elements,
                       r.edges, r.shape, r.refinement, r.foundation)

    def size(self, section, focus=()) -> tuple[int, int]:
        """A DOF per vertex and per edge of its triangles (Morley's and P2's count alike; three
        P2 fields for Mindlin's); its elements as drawn and exported: the segments of its line
        z = 0. The rectangle's grid of n_along x n_across cells of two triangles; the disc's
        1 + 3 n (n + 1) vertices and 6 n^2 triangles of n rings (its edges: vertices + triangles - 1,
        by Euler). A mesh graded toward the contacts is counted as built once their heights `focus`
        are known (the mesh alone, `surface.surface_mesh`); before that, as if ungraded."""
        ny = section.surface_elements
        fields = 3 if getattr(section, "plate_theory", "kirchhoff") == "mindlin" else 1  # (w, beta) per node
        if section.contact_refinement and len(focus):
            from .surface import surface_mesh

            mesh = surface_mesh(section.y0, section.length, section.thickness, ny, section.shape,
                                section.contact_refinement, focus)
            return fields * (mesh.p.shape[1] + mesh.facets.shape[1]), ny
        if section.shape == "disc":
            n = ny // 2
            vertices, triangles = 1 + 3 * n * (n + 1), 6 * n * n
            return fields * (2 * vertices + triangles - 1), 2 * n
        nz = max(2, 2 * int(round(0.5 * ny * section.thickness / section.length)))
        vertices, cells = (ny + 1) * (nz + 1), ny * nz
        return fields * (vertices + (ny * (nz + 1) + nz * (ny + 1) + cells)), ny

    def export_cells(self, model):
        return [("line", np.asarray(model.elements, dtype=np.int64))]

    def stress(self, model, x, E, nu):
        """The largest surface bending stress (von Mises of 6 M / h^2) over the triangles of each
        segment of the line z = 0."""
        from skfem import Functional
        from skfem.helpers import dd

        h = model.info["width"]
        basis = model.basis
        if model.info.get("theory") == "mindlin":
            from .mindlin import mindlin_rotation_stress

            return self._per_segment(model, mindlin_rotation_stress(basis, x, E, nu, h))

        @Functional
        def surface_von_mises(w):
            k = dd(w["u"])
            c = E * h / (2 * (1 - nu * nu))
            sy, sz, syz = c * (k[0, 0] + nu * k[1, 1]), c * (k[1, 1] + nu * k[0, 0]), c * (1 - nu) * k[0, 1]
            return np.sqrt(sy**2 - sy * sz + sz**2 + 3 * syz**2)

        per_triangle = surface_von_mises.elemental(basis, u=basis.interpolate(np.asarray(x, float))) / basis.dx.sum(1)
        return self._per_segment(model, per_triangle)

    @staticmethod
    def _per_segment(model, per_triangle) -> dict:
        """The largest of a per-triangle stress over the triangles of each segment of the line z = 0."""
        out = np.zeros(len(model.elements))
        np.maximum.at(out, model.segment_of, per_triangle)
        return {"surface_von_mises": out}

    def mode_kinds(self, model, shapes, which):
        return ["transverse" for _ in which]

    def deflection_dofs(self, model) -> np.ndarray:
        """The Morley vertex value of each vertex of its line z = 0 (its wavefield samples them)."""
        return np.asarray(model.line_dofs)

    def sampled_elements(self, model) -> int:
        """The coarse grid's elements along the line z = 0 (`surface_elements`): a mesh graded
        toward the contacts keeps the coarse vertices, whose spacing sets what the wavefield
        resolves; the extra vertices near the contacts are not sampled."""
        return int(model.recipe.beam_elements)

    def branches(self, model, k, count=3):
        """The Kirchhoff plate's flexural branch w^2 = (D k^4 + k_f) / rho h (plane waves along y; on a
        foundation k_f, cut on at sqrt(k_f / rho h)); a Mindlin plate's lowest branch of
        `mindlin.mindlin_frequencies` (shear and rotary inertia bend it below Kirchhoff's as k h
        grows)."""
        info = model.info
        kf = info.get("foundation", 0.0)
        if info.get("theory") == "mindlin":
            from .mindlin import mindlin_frequencies

            f = [mindlin_frequencies(q, 0.0, info["D"], model.recipe.nu, info["shear"], info["rhoh"], info["rhoI"], kf)[0]
                 for q in np.atleast_1d(np.asarray(k, float))]
            return {"flexural": np.asarray(f) / (2 * np.pi)}
        return {"flexural": string_frequency(k, 0.0, info["rhoh"], info["D"], kf)}


BENDING_PLATE = BendingPlateKind()
