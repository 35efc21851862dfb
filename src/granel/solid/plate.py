"""Plane-stress plate (eq. 7) with 8-node serendipity quadrilaterals, consistent mass,
clamped top and bottom edges, and massless rigid layers at the contact points (Sec. II B).

Assembly uses scikit-fem (ElementQuadS2 on straight-sided quads: the isoparametric Q8 with
mid-side nodes at the edge midpoints). Rigid layers are multipoint constraints applied by a
transformation x = T q: each layer's nodes follow the rigid motion (u_x, u_y, theta) of its mid
node, so M_r = T'MT and K_r = T'KT.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .base import ContactPoint, LineSampling, Material, Patches, Shape, Slab, SolidKind, SolidModel
from .dispersion import lamb_branches, plane_stress_speeds

Q8_OUTLINE = [0, 4, 1, 5, 2, 6, 3, 7]  # corner, mid-side, corner, ... around a Q8 element


@dataclass(frozen=True)
class LayerSpec:
    """A rigid layer on a vertical edge: the contact name, edge ('left'/'right'), centre height,
    length (R/10 in the paper) and the contact normal n_ik (granule -> solid)."""

    name: str
    edge: str
    y: float
    length: float


def _graded(length: float, n: int, growth: float, cap_ratio: float = np.inf) -> np.ndarray:
    """n sizes summing to `length`, growing by `growth` from both ends toward the middle
    (capped at cap_ratio times the end size)."""
    k = np.arange(n)
    w = np.minimum(growth ** np.minimum(k, n - 1 - k), cap_ratio)
    return length * w / w.sum()


def _count(length: float, first: float, growth: float, max_size: float) -> int:
    """Elements needed to fill `length` growing from `first` at both ends, sizes <= max_size."""
    n, total, s = 0, 0.0, first
    while total < length:
        total += 2 * min(s, max_size)
        n += 2
        s *= growth
    # drop a pair if we overshot by more than half an element
    if n > 2 and total - length > min(s / growth, max_size):
        n -= 1
    return max(n, 1)


def edge_distribution(y0: float, length: float, layers: list[tuple[float, float]], counts=None,
                      growth: float = 1.6, max_size: float = 2.5e-3):
    """Node heights along a vertical edge: exactly two elements on each layer (centre, half
    length) and graded elements between. `counts` fixes the element count of each gap so that
    both edges share one logical grid; returns (nodes, counts)."""
    keys = [y0]
    firsts = []
    for yc, a in sorted(layers):
        keys += [yc - a, yc, yc + a]
        firsts.append(a)
    keys.append(y0 + length)
    keys = np.array(keys)
    if np.any(np.diff(keys) <= 0):
        raise ValueError("rigid layers overlap each other or the clamped edges")
    gaps = [(keys[0], keys[1], firsts[0] if firsts else max_size)]
    for k in range(len(layers)):
        lo = keys[3 * k + 3]
        hi = keys[3 * k + 4]
        a = max(firsts[k], firsts[k + 1] if k + 1 < len(layers) else firsts[k])
        gaps.append((lo, hi, a))
    out = [y0]
    new_counts = []
    for g, (lo, hi, a) in enumerate(gaps):
        n = _count(hi - lo, a * growth, growth, max_size) if counts is None else counts[g]
        new_counts.append(n)
        sizes = _graded(hi - lo, n, growth, max_size / (a * growth) if a > 0 else np.inf)
        out += list(lo + np.cumsum(sizes))
        if g < len(layers):
            yc = keys[3 * g + 2]
            out += [yc, keys[3 * g + 3]]
    return np.array(out), new_counts


def plate_mesh(slab: Slab, left_layers, right_layers, how: PlateMesh = None):
    """A structured Q8 mesh of the rectangle of `slab`, graded toward the contact points as `how`
    says (left_layers, right_layers: (height, half length) of each rigid layer on that edge).

    Both vertical edges get node heights with exactly two elements on each rigid layer; the
    interior nodes blend the two edge distributions linearly across the width, so every layer
    is matched exactly while elements stay nearly rectangular. Layer heights missing on one edge
    are mirrored from the other so that the two distributions have the same structure.
    """
    how = how or PlateMesh()
    x0, y0, width, length = slab.x0, slab.y0, slab.width, slab.length
    nx, growth, max_size, x_growth = how.nx, how.growth, how.max_size, how.x_growth
    heights = sorted({round(y, 12) for y, _ in left_layers} | {round(y, 12) for y, _ in right_layers})
    L = {round(y, 12): a for y, a in left_layers}
    R = {round(y, 12): a for y, a in right_layers}
    lay_l = [(h, L.get(h, R.get(h))) for h in heights]
    lay_r = [(h, R.get(h, L.get(h))) for h in heights]
    _, cl = edge_distribution(y0, length, lay_l, None, growth, max_size)
    _, cr = edge_distribution(y0, length, lay_r, None, growth, max_size)
    counts = [max(a, b) for a, b in zip(cl, cr)]
    yl, _ = edge_distribution(y0, length, lay_l, counts, growth, max_size)
    yr, _ = edge_distribution(y0, length, lay_r, counts, growth, max_size)
    xs = x0 + np.concatenate([[0.0], np.cumsum(_graded(width, nx, x_growth))])
    xs[-1] = x0 + width
    xi = (xs - x0) / width
    ny = len(yl) - 1
    X = np.repeat(xs[:, None], ny + 1, axis=1)  # (nx+1, ny+1)
    Y = (1 - xi[:, None]) * yl[None, :] + xi[:, None] * yr[None, :]
    p = np.vstack([X.ravel(), Y.ravel()])  # node (i, j) -> i * (ny + 1) + j
    idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
    t = []
    for i in range(nx):
        for j in range(ny):
            t.append([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)])
    from skfem import MeshQuad  # scikit-fem is imported only where a plate is built

    return MeshQuad(p, np.array(t, dtype=np.int64).T)


def plane_stress_law(E, nu):
    """Hooke's law in plane stress, sigma = 2 mu eps + lam tr(eps) I with the plane-stress Lame
    parameter lam = E nu / (1 - nu^2): the material matrix D of eq. (7), on strain tensors
    (2, 2, ...) as scikit-fem's forms pass them."""
    lam = E * nu / (1 - nu**2)
    mu = E / (2 * (1 + nu))

    def stress(eps):
        return 2 * mu * eps + lam * _tr_identity(eps)

    return stress


def plane_stress_forms(E, nu, rho, h):
    """The plate's weak forms, eq. (7), for thickness h: the stiffness h sigma(eps(u)) : eps(v) and
    the mass h rho u . v (bilinear), and the strain and kinetic energy functionals."""
    from skfem import BilinearForm, Functional
    from skfem.helpers import ddot, dot, sym_grad

    stress = plane_stress_law(E, nu)

    @BilinearForm
    def stiffness(u, v, w):
        return h * ddot(stress(sym_grad(u)), sym_grad(v))

    @BilinearForm
    def mass(u, v, w):
        return h * rho * dot(u, v)

    @Functional
    def strain_energy(w):
        eps = sym_grad(w["u"])
        return 0.5 * h * ddot(stress(eps), eps)

    @Functional
    def kinetic_energy(w):
        return 0.5 * h * rho * dot(w["vel"], w["vel"])

    return stiffness, mass, strain_energy, kinetic_energy


def _tr_identity(eps):
    tr = eps[0, 0] + eps[1, 1]
    out = np.zeros_like(eps)
    out[0, 0] = tr
    out[1, 1] = tr
    return out


@dataclass(frozen=True)
class PlateMesh:
    """How the plate is meshed: elements across the width, the size growth away from the
    contacts (capped at max_size along the length), the width grading toward the edges, and
    whether the rigid layers are kept."""

    nx: int = 8
    growth: float = 1.6
    max_size: float = 2.5e-3
    x_growth: float = 1.5
    rigid_layers: bool = True


PLATE_CACHE_VERSION = 2  # raise when the assembly below changes what it produces


def build_plate(slab: Slab, material: Material, layers: list[LayerSpec], mesh: PlateMesh = PlateMesh(),
                clamped=(True, True)) -> SolidModel:
    """The reduced plate model (eq. 7, Q8, consistent mass) of the solid `slab` with its contact
    points (one per layer). The assembled matrices are cached on disk by the arguments, so that a run needs no
    scikit-fem (a slow import); the element-level quantities of figures and
    movies (`element_energies`, `basis`) assemble the plate again on first use. A plate that
    differs from a cached one only in thickness, Young's modulus and density is that plate
    scaled (K by E h, M by rho h, the element volumes by h; `_scaled_plate`)."""
    args = _plate_args(slab, material, layers, mesh, clamped)
    path = _plate_cache_path(args)
    model, damage = _load_plate(path, args)
    if model is None:
        model = _scaled_plate(path, args)
        if model is None:
            model = assemble_plate(*_plate_parts(args))
        if damage:
            from .cache_files import note

            note(("rebuilt", path), f"cache: {damage}; the plate is built again")
        _save_plate(path, model, args)
    return model


def _plate_args(slab: Slab, material: Material, layers, mesh: PlateMesh, clamped) -> tuple:
    """A plate's arguments as one flat tuple, the key of its cache file (the layout of cache
    version 2: x0, y0, width, length, thickness, E, nu, rho, layers, mesh, clamped)."""
    return (slab.x0, slab.y0, slab.width, slab.length, slab.thickness, material.E, material.nu, material.rho,
            tuple(layers), mesh, tuple(clamped))


def _plate_parts(args: tuple) -> tuple:
    """The arguments of `assemble_plate` from the flat tuple of `_plate_args`."""
    x0, y0, width, length, thickness, E, nu, rho, layers, mesh, clamped = args
    return Slab(x0, y0, width, length, thickness), Material(E, rho, nu), list(layers), mesh, clamped


def _scale_free_args(args) -> tuple:
    """What the plate's K / (E h) and M / (rho h) depend on: every argument but the thickness,
    Young's modulus and density (Poisson's ratio stays: D / E depends on it)."""
    x0, y0, width, length, thickness, E, nu, rho, layers, mesh, clamped = args
    return (PLATE_CACHE_VERSION, x0, y0, width, length, nu, layers, mesh, clamped)


def _plate_cache_path(args):
    """plate-FAMILY-KEY.npz: KEY by all the arguments, FAMILY by the scale-free ones."""
    import hashlib

    from .cache_files import cache_dir

    key = hashlib.sha256(repr((PLATE_CACHE_VERSION, args)).encode()).hexdigest()[:24]
    family = hashlib.sha256(repr(_scale_free_args(args)).encode()).hexdigest()[:12]
    return cache_dir() / f"plate-{family}-{key}.npz"


def _save_plate(path, model: SolidModel, args) -> None:
    """The assembled arrays of a plate model into the cache, a checked cache file
    (`cache_files.write_checked`); a cache that cannot be written is skipped with a note."""
    import json

    from .cache_files import prune_cache, unwritable, write_checked

    thickness, E, rho = args[4], args[5], args[7]
    arrays = {"info": np.array(json.dumps(model.info)), "nodes": model.nodes, "elements": model.elements,
              "volume": model.element_volume, "node_dofs": model.node_dofs,
              "contacts": np.array(json.dumps([c.__dict__ for c in model.contacts])),
              "family": np.array(repr(_scale_free_args(args))), "scales": np.array([thickness, E, rho], float),
              "unit_weight": model.unit_weights()}
    for name, A in (("M", model.M), ("K", model.K), ("T", model.T)):
        A = A.tocsr()
        arrays.update({f"{name}_data": A.data, f"{name}_indices": A.indices, f"{name}_indptr": A.indptr,
                       f"{name}_shape": np.array(A.shape)})
    try:
        write_checked(path, arrays)
        prune_cache(keep=(path,))
    except OSError as e:
        unwritable(path.parent, e)


def _scaled_plate(path, args) -> SolidModel | None:
    """The plate of `args` from a cached plate of the same family (`_scale_free_args`) at another
    thickness h0, modulus E0 and density rho0: K (E h) / (E0 h0), M (rho h) / (rho0 h0), element
    volumes h / h0; nothing else of the assembly depends on them. None without such a plate; a
    damaged one is removed."""
    from .cache_files import discard

    thickness, E, rho = args[4], args[5], args[7]
    family = path.name.split("-")[1]
    for other in sorted(path.parent.glob(f"plate-{family}-*.npz")):
        if other == path:
            continue
        model, damage = _load_plate(other, args, scales=(thickness, E, rho))
        if model is not None:
            return model
        if damage:
            discard([other], damage)
    return None


def _load_plate(path, args, scales=None) -> tuple[SolidModel | None, str | None]:
    """(the cached plate of these arguments, None), or (None, what is wrong with the cache file)
    for a damaged one, or (None, None) without one. `scales` (thickness, E, rho): the plate at
    `path` is one of the same family, scaled to these."""
    import json
    import zipfile

    from .cache_files import touch, verify

    if not path.exists():
        return None, None
    damage = verify(path)
    if damage:
        return None, damage
    try:
        with np.load(path) as z:
            mats = {n: sp.csr_matrix((z[f"{n}_data"], z[f"{n}_indices"], z[f"{n}_indptr"]), shape=tuple(z[f"{n}_shape"]))
                    for n in ("M", "K", "T")}
            info = json.loads(str(z["info"]))
            contacts = [ContactPoint(**{**c, "position": tuple(c["position"]), "normal": tuple(c["normal"])})
                        for c in json.loads(str(z["contacts"]))]
            nodes, elements, volume, node_dofs = z["nodes"], z["elements"], z["volume"], z["node_dofs"]
            weight = z["unit_weight"] if "unit_weight" in z.files else None  # (a cache of an earlier granel: none)
            if scales is not None:
                if str(z["family"]) != repr(_scale_free_args(args)):
                    return None, None
                (h0, E0, rho0), (h, E, rho) = z["scales"], scales
                if not (h0 > 0 and E0 > 0 and rho0 > 0):
                    return None, None
                mats["K"] = mats["K"] * ((E * h) / (E0 * h0))
                mats["M"] = mats["M"] * ((rho * h) / (rho0 * h0))
                weight = None if weight is None else weight * ((rho * h) / (rho0 * h0))
                volume = volume * (h / h0)
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as e:  # matches its record
        return None, f"{path.name} cannot be read ({type(e).__name__})"
    touch(path)  # recently used: pruned last
    model = CachedPlate("plate", mats["M"], mats["K"], contacts, info, mats["T"], nodes, elements, None, volume, None)
    model.node_dofs = node_dofs
    model.unit_weight = weight
    model.full_displacement = model.full
    model.element_energies = model.energies
    model.args = args
    return model, None


class CachedPlate(SolidModel):
    """A plate model from the cache: matrices, contacts and geometry; scikit-fem's basis (for the
    element energies and point probes) is assembled again on first use."""

    def full(self, q):  # (ndof,) -> (n_nodes, 2); (ndof, m) -> (n_nodes, 2, m)
        if getattr(self, "_node_rows", None) is None:  # the rows of the nodes' x and y, sliced once
            T = sp.csr_matrix(self.T)
            self._node_rows = T[self.node_dofs[0]], T[self.node_dofs[1]]
        return np.stack([self._node_rows[0] @ q, self._node_rows[1] @ q], axis=1)

    @property
    def basis(self):
        return self._assembled().basis

    def energies(self, q, v):
        return self._assembled().element_energies(q, v)

    def unit_weights(self):
        return self.unit_weight if self.unit_weight is not None else self._assembled().unit_weights()

    def _assembled(self) -> SolidModel:
        if getattr(self, "_full_model", None) is None:
            self._full_model = assemble_plate(*_plate_parts(self.args))
        return self._full_model


def assemble_plate(slab: Slab, material: Material, layers: list[LayerSpec], mesh: PlateMesh = PlateMesh(),
                   clamped=(True, True)) -> SolidModel:
    """Assemble the reduced plate model (eq. 7, Q8, consistent mass) of the solid `slab` with its
    contact points (one per layer)."""
    x0, y0, width, length, thickness = slab.x0, slab.y0, slab.width, slab.length, slab.thickness
    E, nu, rho = material.E, material.nu, material.rho
    rigid_layers, nx = mesh.rigid_layers, mesh.nx
    left = [(l.y, l.length / 2) for l in layers if l.edge == "left"]
    right = [(l.y, l.length / 2) for l in layers if l.edge == "right"]
    mesh = plate_mesh(slab, left, right, mesh)
    from skfem import Basis, ElementQuadS2, ElementVector, Functional

    basis = Basis(mesh, ElementVector(ElementQuadS2()), intorder=4)
    Kf, Mf, strain_energy, kinetic_energy = plane_stress_forms(E, nu, rho, thickness)
    K = Kf.assemble(basis).tocsr()
    M = Mf.assemble(basis).tocsr()
    loc = basis.doflocs  # (2, N): position of each DOF's node
    N = basis.N
    comp = np.zeros(N, dtype=np.int64)  # 0 = x, 1 = y
    comp[basis.nodal_dofs[1]] = 1
    comp[basis.facet_dofs[1]] = 1
    tol = 1e-9 * length
    fixed = np.zeros(N, bool)
    if clamped[0]:
        fixed |= np.abs(loc[1] - y0) < tol
    if clamped[1]:
        fixed |= np.abs(loc[1] - (y0 + length)) < tol
    # rigid layers: DOFs on the edge within the layer's extent
    slave = -np.ones(N, dtype=np.int64)  # layer index for constrained DOFs
    mids = []
    for k, lay in enumerate(layers):
        xe = x0 if lay.edge == "left" else x0 + width
        on = (np.abs(loc[0] - xe) < tol) & (np.abs(loc[1] - lay.y) <= lay.length / 2 + tol)
        mid = on & (np.abs(loc[1] - lay.y) < tol)
        mx = int(np.flatnonzero(mid & (comp == 0))[0])
        my = int(np.flatnonzero(mid & (comp == 1))[0])
        mids.append((mx, my))
        if rigid_layers:
            n_on = int(on.sum())
            if n_on != 10:
                raise RuntimeError(f"layer {lay.name}: expected 5 nodes (two Q8 elements), found {n_on // 2}")
            slave[on & ~mid] = k
    # reduced numbering: free unconstrained DOFs, then one rotation per layer
    keep = ~fixed & (slave < 0)
    red = -np.ones(N, dtype=np.int64)
    red[keep] = np.arange(keep.sum())
    nq = int(keep.sum())
    rot = []
    rows, cols, vals = list(np.flatnonzero(keep)), list(red[keep]), [1.0] * nq
    for k, lay in enumerate(layers):
        if not rigid_layers:
            rot.append(-1)
            continue
        r = nq + len([x for x in rot if x >= 0])
        rot.append(r)
        mx, my = mids[k]
        for d in np.flatnonzero(slave == k):
            if comp[d] == 0:  # u_x = U_x - theta (y - y_c)
                rows += [d, d]
                cols += [red[mx], r]
                vals += [1.0, -(loc[1, d] - lay.y)]
            else:  # u_y = U_y + theta (x - x_c) = U_y on a vertical edge
                rows += [d, d]
                cols += [red[my], r]
                vals += [1.0, loc[0, d] - loc[0, mx]]
    nred = nq + sum(1 for x in rot if x >= 0)
    T = sp.csr_matrix((vals, (rows, cols)), shape=(N, nred))
    Mr = (T.T @ M @ T).tocsr()
    Kr = (T.T @ K @ T).tocsr()
    contacts = []
    for k, lay in enumerate(layers):
        xe = x0 if lay.edge == "left" else x0 + width
        nrm = (1.0, 0.0) if lay.edge == "left" else (-1.0, 0.0)
        mx, my = mids[k]
        contacts.append(ContactPoint(lay.name, (xe, lay.y), nrm, int(red[mx]), int(red[my]), int(rot[k])))
    # node numbering for plotting: vertices then edge midpoints (skfem's DOF order)
    vx = basis.nodal_dofs[0]
    ex = basis.facet_dofs[0]
    node_dofx = np.concatenate([vx, ex])
    node_dofy = np.concatenate([basis.nodal_dofs[1], basis.facet_dofs[1]])
    nodes = loc[:, node_dofx].T.copy()
    nv = mesh.p.shape[1]
    elem = np.hstack([mesh.t.T, nv + mesh.t2f.T])  # 4 corners + 4 edge midpoints

    T_nodes = sp.csr_matrix(T)[node_dofx], sp.csr_matrix(T)[node_dofy]  # the rows of the nodes' x and y

    def full(q):  # (ndof,) -> (n_nodes, 2); (ndof, m) -> (n_nodes, 2, m)
        return np.stack([T_nodes[0] @ q, T_nodes[1] @ q], axis=1)

    def energies(q, v):
        ue = basis.interpolate(T @ q)
        ve = basis.interpolate(T @ v)
        return kinetic_energy.elemental(basis, vel=ve), strain_energy.elemental(basis, u=ue)

    @Functional
    def area(w):
        return thickness + 0.0 * w.x[0]

    vol = area.elemental(basis)
    info = {"dofs": int(nred), "elements": int(mesh.t.shape[1]), "nodes": int(len(nodes)), "nx": nx,
            "ny": int(mesh.t.shape[1] // nx), "full_dofs": int(N), "rigid_layers": bool(rigid_layers)}
    model = SolidModel("plate", Mr, Kr, contacts, info, T, nodes, elem, energies, vol, full)
    model.unit_weight = np.column_stack([T.T @ (M @ (comp == 0).astype(float)), T.T @ (M @ (comp == 1).astype(float))])
    model.basis = basis
    model.node_dofs = np.vstack([node_dofx, node_dofy])
    return model


def element_stress(model: SolidModel, E: float, nu: float, x: np.ndarray) -> dict[str, np.ndarray]:
    """The plate's element-mean plane-stress Cauchy stress and von Mises stress [Pa], (ne,) each,
    from the full nodal DOF vector x (= T q, scikit-fem's DOF order), with the plate's own
    plane-stress law (`plane_stress_law`, eq. 7) at its Gauss points."""
    from skfem.helpers import sym_grad

    basis = model.basis
    S = plane_stress_law(E, nu)(sym_grad(basis.interpolate(np.asarray(x, float))))  # (2, 2, ne, nqp)
    dx = basis.dx  # quadrature weight x Jacobian (ne, nqp)
    S = (S * dx).sum(axis=-1) / dx.sum(axis=-1)
    sxx, syy, sxy = S[0, 0], S[1, 1], S[0, 1]
    vm = np.sqrt(sxx**2 - sxx * syy + syy**2 + 3 * sxy**2)
    return {"stress_xx": sxx, "stress_yy": syy, "stress_xy": sxy, "von_mises": vm}


def quadratic_weights(y: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices (n, 3), weights (n, 3)) of the quadratic Lagrange interpolation at points y
    through the node triples (vertex, mid-side, vertex) of a line whose sorted node heights are
    `nodes` (2 m + 1 of them)."""
    sides = (len(nodes) - 1) // 2
    m = np.clip(np.searchsorted(nodes[2::2], y, side="left"), 0, sides - 1)
    idx = np.stack([2 * m, 2 * m + 1, 2 * m + 2], axis=1)
    p = nodes[idx]
    w = np.empty_like(p)
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        w[:, a] = (y - p[:, b]) * (y - p[:, c]) / ((p[:, a] - p[:, b]) * (p[:, a] - p[:, c]))
    return idx, w


def _sample_grid(model: SolidModel, nx=9, ny=81):
    x0, x1 = model.nodes[:, 0].min(), model.nodes[:, 0].max()
    y0, y1 = model.nodes[:, 1].min(), model.nodes[:, 1].max()
    xs = np.linspace(x0, x1, nx)
    ys = np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return X.ravel(), Y.ravel(), 0.5 * (x0 + x1), 0.5 * (y0 + y1)


def _mirror_probes(model: SolidModel):
    """Point-evaluation matrices at a sample grid and at its two mirror images (cached)."""
    cached = getattr(model, "_mirror_probes", None)
    if cached is None:
        basis = model.basis
        X, Y, xc, yc = _sample_grid(model)
        cached = (basis.probes(np.vstack([X, Y])), basis.probes(np.vstack([2 * xc - X, Y])),
                  basis.probes(np.vstack([X, 2 * yc - Y])), len(X))
        model._mirror_probes = cached
    return cached


def symmetry_coefficients(model: SolidModel, shape: np.ndarray) -> tuple[float, float]:
    """(width-mirror, up-down-mirror) symmetry of a plate field in reduced coordinates, each in
    [-1, 1]: +1 symmetric, -1 antisymmetric. The width mirror flips u_x, the up-down one u_y."""
    P, Pw, Pu, npt = _mirror_probes(model)
    full = model.T @ shape
    u, uw, uu = P @ full, Pw @ full, Pu @ full
    mw = np.concatenate([-uw[:npt], uw[npt:]])
    mu = np.concatenate([uu[:npt], -uu[npt:]])
    return float(u @ mw / (u @ u)), float(u @ mu / (u @ u))


class PlateKind(SolidKind):
    """The plane-stress plate of eq. (7) (`build_plate`), drawn as its Q8 elements."""

    name = "plate"
    fields = SolidKind.fields | {"material", "thickness", "mesh", "clamped"}

    def layer(self, section) -> float:
        return section.mesh.layer_fraction

    def recipe_fields(self, section, material) -> dict:
        m = section.mesh
        return super().recipe_fields(section, material) | dict(
            thickness=section.thickness, E=material.E, rho=material.rho, nu=material.nu, clamped=tuple(section.clamped),
            mesh=PlateMesh(m.nx, m.growth, m.max_size, m.x_growth, m.rigid_layers))

    def build(self, recipe) -> SolidModel:
        r = recipe
        layers = [LayerSpec(c.name, c.edge, c.position[1], c.layer) for c in r.contacts]
        return build_plate(r.slab, r.material, layers, r.mesh, r.clamped)

    def size(self, section, focus=()) -> tuple[int, int]:
        """Rows of elements at least length / mesh.max_size (`plate_mesh`); Q8 nodes
        (2 nx + 1)(2 ny + 1) - nx ny, two DOFs each."""
        nx = section.mesh.nx
        ny = max(2, math.ceil(section.length / section.mesh.max_size))
        return 2 * ((2 * nx + 1) * (2 * ny + 1) - nx * ny), nx * ny

    def box(self, model):
        """Its nodes' extent."""
        (x0, y0), (x1, y1) = model.nodes.min(axis=0), model.nodes.max(axis=0)
        return float(x0), float(y0), float(x1), float(y1)

    def shape(self, model, u=None, scale=0.0) -> Shape:
        xy = model.nodes + (scale * u if u is not None else 0.0)
        return Shape(polygons=xy[np.asarray(model.elements)[:, Q8_OUTLINE]])

    def energy_cells(self, model, q, v) -> Patches:
        return Patches(self.shape(model).polygons, model.element_energy_density(q, v))

    def export_cells(self, model):
        """Q8 elements: corners, then the midpoints of the sides 0-1, 1-2, 2-3, 3-0 (VTK's quad8)."""
        return [("quad8", np.asarray(model.elements, dtype=np.int64))]

    def stress(self, model, x, E, nu):
        return element_stress(model, E, nu, x)

    def mode_kinds(self, model, shapes, which):
        """Bending if antisymmetric across the width, else axial if antisymmetric up-down, else
        bulk (`symmetry_coefficients`)."""
        kinds = []
        for k in which:
            s_width, s_updown = symmetry_coefficients(model, shapes[:, k])
            kinds.append("bending" if s_width < 0 else ("axial" if s_updown < 0 else "bulk"))
        return kinds

    def wave_lines(self, model, samples=None) -> LineSampling:
        """Its vertex columns (2 ny + 1 nodes each), both components, sampled at `samples` heights
        (default: two per the longest node gap along the length) by quadratic interpolation; the
        mass per length rho h times each column's trapezoid share of the width."""
        r = model.recipe
        if r is None:
            return super().wave_lines(model, samples)
        nodes = np.asarray(model.nodes, float)
        ny = int(model.info["ny"])
        tol = 1e-9 * r.width
        xs = np.unique(np.round(nodes[:, 0] / tol) * tol)
        columns = [np.flatnonzero(np.abs(nodes[:, 0] - x) < 2 * tol) for x in xs]
        columns = [c[np.argsort(nodes[c, 1])] for c in columns if len(c) == 2 * ny + 1]
        x = np.array([nodes[c[0], 0] for c in columns])
        gaps = max(float(np.diff(nodes[c, 1]).max()) for c in columns)
        count = int(math.ceil(2 * r.length / gaps)) if samples is None else int(samples)
        full = model.T.shape[0]

        def sampler(y):
            rows, cols, vals = [], [], []
            n = len(y)
            for i, c in enumerate(columns):
                idx, w = quadratic_weights(np.asarray(y, float), nodes[c, 1])
                for comp in (0, 1):
                    dofs = np.asarray(model.node_dofs[comp])[c][idx]
                    rows.append(np.repeat((2 * i + comp) * n + np.arange(n), 3))
                    cols.append(dofs.ravel())
                    vals.append(w.ravel())
            return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                 shape=(2 * len(columns) * n, full))

        share = np.zeros(len(x))  # the trapezoid rule across the width
        share[:-1] += np.diff(x) / 2
        share[1:] += np.diff(x) / 2
        return LineSampling(x, r.rho * r.thickness * share, ("x", "y"), count, 2 * gaps, sampler)

    def branches(self, model, k, count=3):
        """The Rayleigh-Lamb branches S0, S1, ..., A0, A1, ... of a plane-stress strip as wide as the
        plate, with its recipe's E, nu, rho."""
        r = model.recipe
        lamb = lamb_branches(k, r.width, plane_stress_speeds(r.E, r.nu, r.rho), count)
        out = {}
        for family, rows in (("S", lamb.symmetric), ("A", lamb.antisymmetric)):
            out.update({f"{family}{n}": rows[n] for n in range(len(rows))})
        return out


PLATE = PlateKind()
