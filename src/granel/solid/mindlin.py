"""The thick (Mindlin-Reissner) plate standing across the granular plane: the plate in bending's
option `plate_theory = "mindlin"`. Its deflection w (along x) and the rotations beta = (beta_y,
beta_z) of its normals are independent fields, so that shear deformation and rotary inertia
count (Mindlin, J. Appl. Mech. 18, 31, 1951):

    U = 1/2 int D ((1 - nu) kappa : kappa + nu tr(kappa)^2) + k G h |grad w - beta|^2,
    T = 1/2 int rho h w_t^2 + rho h^3 / 12 |beta_t|^2,     kappa = sym grad beta,

k = 5/6 the shear coefficient. Quadratic Lagrange triangles (scikit-fem's ElementTriP2) for w and
for each rotation, on the same meshes as the thin plate (`surface.standing_surface`);
docs/solids.md ("Thick plates")."""

from __future__ import annotations

import numpy as np

from .base import Material, Slab, SolidModel
from .surface import check_held, flexural_rigidity, standing_surface, surface_model

SHEAR_COEFFICIENT = 5.0 / 6.0  # Reissner's k of the shear force k G h (grad w - beta)


def mindlin_forms(D: float, nu: float, shear: float, rho_h: float, rho_i: float, foundation: float = 0.0):
    """(stiffness, mass, strain energy density, kinetic energy density) of the Mindlin plate with
    bending stiffness D, shear stiffness k G h, mass per area rho h and rotary inertia rho h^3/12,
    on a foundation of stiffness k_f per area (acting on w); the fields are (w, beta)."""
    from skfem import BilinearForm, Functional
    from skfem.helpers import ddot, dot, grad, sym_grad, trace

    def bending(ka, kb):
        return D * ((1.0 - nu) * ddot(ka, kb) + nu * trace(ka) * trace(kb))

    @BilinearForm
    def stiffness(w, beta, v, psi, _):
        return bending(sym_grad(beta), sym_grad(psi)) + shear * dot(grad(w) - beta, grad(v) - psi) + foundation * w * v

    @BilinearForm
    def mass(w, beta, v, psi, _):
        return rho_h * w * v + rho_i * dot(beta, psi)

    @Functional
    def strain(f):
        w, beta = f["u"]
        gap = grad(w) - beta
        return 0.5 * (bending(sym_grad(beta), sym_grad(beta)) + shear * dot(gap, gap) + foundation * w**2)

    @Functional
    def kinetic(f):
        w, beta = f["speed"]
        return 0.5 * (rho_h * w**2 + rho_i * dot(beta, beta))

    return stiffness, mass, strain, kinetic


def build_mindlin_plate(slab: Slab, material: Material, contacts, n_along: int = 24, edges=("clamped",) * 4,
                        shape: str = "rectangle", refine: int = 0, foundation: float = 0.0) -> SolidModel:
    """The Mindlin plate of `slab` (as `bending_plate.build_bending_plate`'s: h = width along x, the
    length along y, its depth along z; a disc's diameter the length) on P2 triangles for w and
    beta. edges: a rectangle's (bottom, top, front, back), a disc's (rim,), each 'clamped' (w and
    beta held), 'simple' (w and the rotation about the edge's normal, beta along the edge, held:
    the hard simple support of Mindlin's exact solutions) or 'free'; `foundation` k_f [N/m^3] under
    its face. ValueError for edges that leave it a rigid motion on no foundation, or a contact off
    a vertex of z = 0 or on a held edge."""
    from skfem import ElementTriP2, ElementVector

    surface = standing_surface(slab, ElementTriP2() * ElementVector(ElementTriP2()), n_along, shape, refine,
                               [c[2] for c in contacts])
    basis, mesh = surface.basis, surface.mesh
    h = slab.width
    D = flexural_rigidity(material.E, material.nu, h)
    shear = SHEAR_COEFFICIENT * material.E / (2.0 * (1.0 + material.nu)) * h
    stiffness, mass, strain, kinetic = mindlin_forms(D, material.nu, shear, material.rho * h, material.rho * h**3 / 12,
                                                     foundation)
    K, M = stiffness.assemble(basis).tocsr(), mass.assemble(basis).tocsr()
    fixed = np.zeros(basis.N, bool)
    along = {"bottom": "u^2^2", "top": "u^2^2", "front": "u^1^2", "back": "u^1^2"}  # beta tangent to each edge
    for side, how in zip(surface.edge_facets, edges, strict=True):
        dofs = basis.get_dofs(surface.edge_facets[side])
        if how == "clamped":
            fixed[dofs.all()] = True
        elif how == "simple":
            fixed[dofs.all(["u^1", along[side]])] = True
    # the rigid motions: w = a + b y + c z with beta = (b, c)
    p, rigid = basis.doflocs, np.zeros((basis.N, 3))
    w_dofs = basis.get_dofs().all(["u^1"])
    by, bz = basis.get_dofs().all(["u^1^2"]), basis.get_dofs().all(["u^2^2"])
    rigid[w_dofs, 0], rigid[w_dofs, 1], rigid[w_dofs, 2] = 1.0, p[0, w_dofs], p[1, w_dofs]  # the mesh's frame
    rigid[by, 1], rigid[bz, 2] = 1.0, 1.0
    check_held(rigid, fixed, edges, foundation)
    model = surface_model("bending_plate", surface, K, M, fixed, rigid[:, 0], contacts, strain, kinetic,
                          {"D": D, "rhoh": material.rho * h, "thickness": h, "theory": "mindlin",
                           "shear": shear, "rhoI": material.rho * h**3 / 12, "foundation": float(foundation)})
    del mesh
    return model


def mindlin_rotation_stress(basis, x, E: float, nu: float, h: float) -> np.ndarray:
    """The largest surface bending stress (von Mises of 6 M / h^2, M from the curvature sym grad
    beta) of each triangle, averaged over it, for full DOFs x."""
    from skfem import Functional
    from skfem.helpers import sym_grad

    @Functional
    def surface_von_mises(f):
        _, beta = f["u"]
        k = sym_grad(beta)
        c = E * h / (2 * (1 - nu * nu))
        sy, sz, syz = c * (k[0, 0] + nu * k[1, 1]), c * (k[1, 1] + nu * k[0, 0]), c * (1 - nu) * k[0, 1]
        return np.sqrt(sy**2 - sy * sz + sz**2 + 3 * syz**2)

    return surface_von_mises.elemental(basis, u=basis.interpolate(np.asarray(x, float))) / basis.dx.sum(1)


def mindlin_frequencies(ky, kz, D: float, nu: float, shear: float, rho_h: float, rho_i: float,
                        foundation: float = 0.0) -> np.ndarray:
    """The three angular frequencies [rad/s] of the Mindlin plate's plane wave (or simply supported
    mode) with wavenumbers (ky, kz): w = W sin(ky y) sin(kz z), beta_y = B_y cos(ky y) sin(kz z),
    beta_z = B_z sin(ky y) cos(kz z) put in U and T give a 3 x 3 eigenproblem K q = w^2 M q, the
    lowest the flexural branch, the others the thickness-shear ones (a foundation k_f adds to the
    deflection's stiffness)."""
    from scipy.linalg import eigh

    s = shear
    K = np.array([
        [s * (ky * ky + kz * kz) + foundation, -s * ky, -s * kz],
        [-s * ky, D * (ky * ky + 0.5 * (1 - nu) * kz * kz) + s, 0.5 * D * (1 + nu) * ky * kz],
        [-s * kz, 0.5 * D * (1 + nu) * ky * kz, D * (kz * kz + 0.5 * (1 - nu) * ky * ky) + s],
    ])
    return np.sqrt(np.abs(eigh(K, np.diag([rho_h, rho_i, rho_i]), eigvals_only=True)))
