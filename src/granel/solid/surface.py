"""The surfaces standing across the granular plane that the plates in bending and the membrane
are built on: their meshes (a rectangle's grid, a disc whose diameter is made of element edges,
either graded toward the contacts) and the solid model of such a surface (its contacts on the line
z = 0 where the two planes meet, that line drawn and sampled), with the thin plate's flexural
rigidity the thick one shares; docs/solids.md ("Plate in bending")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .base import ContactPoint, Slab, SolidModel, fitting_hint

EDGES = ("bottom", "top", "front", "back")  # y = y0, y = y0 + length, z = -depth/2, z = +depth/2
RIM = ("rim",)  # a disc's one edge
SHAPES = ("rectangle", "disc")


def flexural_rigidity(E: float, nu: float, h: float) -> float:
    """D = E h^3 / 12 (1 - nu^2), the Kirchhoff plate's bending stiffness [N m]."""
    return E * h**3 / (12.0 * (1.0 - nu * nu))


def _axis(lo: float, length: float, n: int) -> np.ndarray:
    return lo + length * np.arange(n + 1) / n


@dataclass
class Surface:
    """A surface standing across the granular plane, meshed: its mesh (coordinates y, z), the
    scikit-fem basis of its element, the facets of each edge (a rectangle's bottom, top, front,
    back; a disc's rim), the elements along its line z = 0."""

    slab: Slab
    mesh: object
    basis: object
    edge_facets: dict
    n_along: int

    @property
    def disc(self) -> bool:
        return set(self.edge_facets) == set(RIM)


def disc_mesh(center_y: float, radius: float, rings: int):
    """A disc of `radius` centred on (center_y, 0) in triangles whose diameter z = 0 is made of
    their edges: a centre vertex and `rings` circles of radii i radius / rings holding 6 i vertices
    each at angles 2 pi k / 6 i (k = 0 and k = 3 i lie on z = 0), each of the six sectors between
    circles i - 1 and i split into 2 i - 1 triangles: 6 rings^2 triangles of nearly equal size. The
    rim is the polygon through the outer circle's vertices (its area falls short of pi radius^2 by
    O(rings^-2))."""
    from skfem import MeshTri

    points, first = [(0.0, 0.0)], [0]
    for i in range(1, rings + 1):
        first.append(len(points))
        angles = 2 * np.pi * np.arange(6 * i) / (6 * i)
        points += list(zip(radius * i / rings * np.cos(angles), radius * i / rings * np.sin(angles)))

    def vertex(i, j):
        return 0 if i == 0 else first[i] + j % (6 * i)

    triangles = []
    for i in range(1, rings + 1):
        for s in range(6):
            for j in range(i):
                outer, inner = s * i + j, s * (i - 1) + j
                triangles.append((vertex(i, outer), vertex(i, outer + 1), vertex(i - 1, inner)))
                if j < i - 1:
                    triangles.append((vertex(i - 1, inner), vertex(i, outer + 1), vertex(i - 1, inner + 1)))
    p = np.ascontiguousarray(np.array(points).T + np.array([[center_y], [0.0]]))
    return MeshTri(p, np.ascontiguousarray(np.array(triangles, dtype=np.int64).T))


# a graded mesh's zone at each level: the triangles within this many of that level's elements of a contact
REFINE_ZONE = 4.0


def refined_toward(mesh, points, levels: int, size: float):
    """`mesh` refined `levels` times toward `points` (y, z): at level k the triangles whose
    centroid lies within REFINE_ZONE elements of size / 2^(k-1) of a point are split (scikit-fem's
    red-green-blue refinement, which keeps the mesh conforming and its angles bounded), so the
    elements shrink by half at each level toward the points and the mesh's vertices and edges stay
    vertices and (split) edges."""
    pts = np.asarray(points, float).reshape(-1, 2)
    for k in range(levels):
        if not len(pts):
            break
        centroids = mesh.p[:, mesh.t].mean(axis=1)
        reach = REFINE_ZONE * size / 2**k
        near = np.min(np.hypot(centroids[0][:, None] - pts[:, 0], centroids[1][:, None] - pts[:, 1]), axis=1) < reach
        if not near.any():
            break
        mesh = mesh.refined(np.flatnonzero(near))
    return mesh


def surface_mesh(y0: float, length: float, depth: float, n_along: int, shape: str = "rectangle", refine: int = 0,
                 focus=()):
    """The triangles of a surface standing across the granular plane (coordinates y, z). A rectangle
    (y over [y0, y0 + length], z over depth centred on the granular plane): the uniform grid of
    n_along cells along y and as many of the same size along z (an even count: z = 0 is a grid
    line), two triangles a cell. A disc (its diameter the length, centred on y0 + length / 2,
    z = 0): `disc_mesh` with n_along / 2 rings, so n_along elements along its diameter. With
    `refine` > 0, graded toward the heights `focus` on z = 0 (the contacts) by `refined_toward`."""
    from skfem import MeshTri

    points = [(y, 0.0) for y in focus]
    if shape == "disc":
        rings = max(1, n_along // 2)
        return refined_toward(disc_mesh(y0 + length / 2, length / 2, rings), points, refine, length / (2 * rings))
    nz = max(2, 2 * int(round(0.5 * n_along * depth / length)))
    mesh = MeshTri.init_tensor(_axis(y0, length, n_along), _axis(-depth / 2, depth, nz))
    return refined_toward(mesh, points, refine, length / n_along)


def standing_surface(slab: Slab, element, n_along: int, shape: str = "rectangle", refine: int = 0,
                     focus=()) -> Surface:
    """The mesh of `slab`'s surface standing across the granular plane (`surface_mesh`, in the
    surface's frame: y from slab.y0), with `element`'s basis and the facets of its edges (a
    rectangle's bottom, top, front, back; a disc's rim)."""
    from skfem import Basis

    # the mesh in the surface's own frame, y measured from slab.y0 (the elements' bases, Morley's
    # global polynomials, lose digits to a large offset): `surface_model` adds y0 back
    L, depth = slab.length, slab.thickness
    mesh = surface_mesh(0.0, L, depth, n_along, shape, refine, [y - slab.y0 for y in focus])
    if shape == "disc":
        rings = max(1, n_along // 2)
        return Surface(slab, mesh, Basis(mesh, element, intorder=4), {"rim": mesh.boundary_facets()}, 2 * rings)
    tol = 1e-9 * max(L, depth)
    where = {"bottom": lambda p: np.abs(p[0]) < tol, "top": lambda p: np.abs(p[0] - L) < tol,
             "front": lambda p: np.abs(p[1] + depth / 2) < tol, "back": lambda p: np.abs(p[1] - depth / 2) < tol}
    return Surface(slab, mesh, Basis(mesh, element, intorder=4), {e: mesh.facets_satisfying(where[e]) for e in EDGES},
                   n_along)


def segments_of(line: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The segment of the sorted line vertices `line` each height in `ys` falls in (the ends'
    segments take what lies beyond them)."""
    return np.clip(np.searchsorted(line, ys) - 1, 0, len(line) - 2)


def check_held(rigid: np.ndarray, fixed: np.ndarray, edges, foundation: float) -> None:
    """ValueError naming solid.edges when the held DOFs `fixed` leave a plate on no foundation one
    of its rigid motions (the columns of `rigid`: w = 1, y, z at every DOF)."""
    if foundation == 0 and np.linalg.matrix_rank(rigid[fixed], tol=1e-9) < 3:
        raise ValueError(f"solid.edges = {list(edges)}: the plate is free to move as a rigid body (it needs an edge "
                         "clamped, or three of its corners' lines held: two opposite edges simply supported, or "
                         "one clamped; or a foundation under it, solid.foundation)")



def surface_model(kind: str, surface: Surface, K, M, fixed: np.ndarray, translation: np.ndarray, contacts, strain,
                  kinetic, info: dict) -> SolidModel:
    """The solid of a standing surface with stiffness K, mass M (full DOFs) and the DOFs `fixed`
    held: reduced by T, its contacts on the vertices of its line z = 0 (the vertex value DOF, no
    y DOF), that line drawn in the granular plane at x0 + h/2 (its segments are the model's
    elements; each triangle's energies go to the segment its centroid's y falls in), its weight
    across it (M times `translation`, the full DOFs of w = 1 everywhere). ValueError for a contact
    off a vertex of z = 0 or on a held one."""
    slab, mesh, basis = surface.slab, surface.mesh, surface.basis
    h, L, p = slab.width, slab.length, mesh.p
    u_dofs = basis.nodal_dofs[0]
    keep = np.flatnonzero(~fixed)
    red = -np.ones(basis.N, dtype=np.int64)
    red[keep] = np.arange(len(keep))
    T = sp.csr_matrix((np.ones(len(keep)), (keep, np.arange(len(keep)))), shape=(basis.N, len(keep)))
    on_line = np.flatnonzero(np.abs(p[1]) < 1e-9 * max(L, slab.thickness))
    on_line = on_line[np.argsort(p[0, on_line])]
    line_local = p[0, on_line]  # the mesh's frame: y from slab.y0
    line_y = slab.y0 + line_local
    cps = []
    for name, edge, y in contacts:
        i = int(np.argmin(np.abs(line_y - y)))
        if abs(line_y[i] - y) > 1e-9 * L:
            hint = fitting_hint(slab.y0, L, [c[2] for c in contacts], surface.n_along, even=surface.disc)
            raise ValueError(f"{kind} contact {name} at y = {y}: not on a node of z = 0 (element length "
                             f"{L / surface.n_along:g} m); choose surface_elements so that every contact height is a "
                             f"node ({hint})")
        dof = int(red[u_dofs[on_line[i]]])
        if dof < 0:
            raise ValueError(f"{kind} contact {name} at y = {y}: on a held edge (solid.edges)")
        xe = slab.x0 if edge == "left" else slab.x0 + h
        cps.append(ContactPoint(name, (xe, y), (1.0, 0.0) if edge == "left" else (-1.0, 0.0), dof, -1, -1))
    nodes = np.column_stack([np.full(len(on_line), slab.x0 + h / 2), line_y])
    segments = np.column_stack([np.arange(len(on_line) - 1), np.arange(1, len(on_line))])
    segment_of = segments_of(line_local, p[0, mesh.t].mean(axis=0))
    volumes = h * np.bincount(segment_of, basis.dx.sum(axis=1), len(segments))  # the triangles' areas

    T_line = T.tocsr()[u_dofs[on_line]]  # the rows of the line's deflections

    def full(q):  # (ndof,) -> (n_line, 2); (ndof, m) -> (n_line, 2, m)
        w = T_line @ q
        return np.stack([w, np.zeros_like(w)], axis=1)

    def energies(q, v):
        kin = kinetic.elemental(basis, speed=basis.interpolate(T @ v))
        pot = strain.elemental(basis, u=basis.interpolate(T @ q))
        return np.bincount(segment_of, kin, len(segments)), np.bincount(segment_of, pot, len(segments))

    info = {"dofs": int(len(keep)), "elements": int(mesh.t.shape[1]), "nodes": int(p.shape[1]), "width": h,
            "depth": float(np.ptp(p[1])), "full_dofs": int(basis.N), "along": int(surface.n_along)} | info
    model = SolidModel(kind, (T.T @ M @ T).tocsr(), (T.T @ K @ T).tocsr(), cps, info, T, nodes, segments, energies,
                       volumes, full)
    model.basis = basis
    model.segment_of = segment_of  # each triangle's segment of the line z = 0
    model.line_dofs = u_dofs[on_line]
    model.unit_weight = np.column_stack([T.T @ (M @ translation), np.zeros(len(keep))])
    return model
