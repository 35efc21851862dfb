"""Euler-Bernoulli beam (eq. 9): Hermite cubic elements, deflection u_x along y.

Contact forces act on the neutral axis at the contact heights (mesh nodes); tangential forces
load nothing (the beam is axially rigid), so the contact points have no y DOF.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .base import ContactPoint, LineSampling, Material, Patches, Shape, Slab, SolidKind, SolidModel, fitting_hint
from .dispersion import euler_bernoulli_frequency


def hermite_stiffness(EI: float, l: float) -> np.ndarray:
    return EI / l**3 * np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
                                 [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]])


def hermite_mass(rhoA: float, l: float) -> np.ndarray:
    return rhoA * l / 420 * np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                                      [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]])


def build_beam(slab: Slab, material: Material, contacts, n_elements=40, clamped=(True, True)) -> SolidModel:
    """The Euler-Bernoulli beam model (eq. 9) of the solid `slab`: Hermite cubic elements,
    consistent mass, the ends clamped where `clamped` says. contacts: list of (name, edge
    'left'/'right', y). Cross-section: depth = width (x), thickness (z); A = width * thickness,
    I = thickness * width^3 / 12 (Poisson's ratio unused)."""
    A = slab.width * slab.thickness
    EI = material.E * slab.thickness * slab.width**3 / 12.0
    fixed = tuple((0, 1) if c else () for c in clamped)
    info = {"EI": EI, "rhoA": material.rho * A}
    return hermite_line("beam", slab, material.rho * A, hermite_stiffness(EI, slab.length / n_elements), contacts,
                        n_elements, fixed, info)


def hermite_line(kind: str, slab: Slab, rhoA: float, ke: np.ndarray, contacts, n_elements: int, fixed, info: dict
                 ) -> SolidModel:
    """A line of `n_elements` equal Hermite cubic elements along y at the middle of `slab`'s width
    (DOFs: deflection u_x and slope at each node), element stiffness `ke`, consistent mass of rho A
    per length; `fixed` = (bottom, top): the local DOFs held at each end (0 deflection, 1 slope).
    contacts: (name, edge 'left'/'right', y), each on a node whose deflection is free; they act
    on the line's faces at x0 and x0 + width and have no y DOF (the line is rigid along its axis)."""
    x0, y0, width, length = slab.x0, slab.y0, slab.width, slab.length
    l = length / n_elements
    nn = n_elements + 1
    ys = y0 + l * np.arange(nn)
    me = hermite_mass(rhoA, l)
    d = 2 * np.arange(n_elements)[:, None] + np.arange(4)[None, :]  # (ne, 4) element DOFs
    rows, cols = np.repeat(d, 4, axis=1).ravel(), np.tile(d, (1, 4)).ravel()
    N = 2 * nn
    K = sp.csr_matrix((np.tile(ke.ravel(), n_elements), (rows, cols)), shape=(N, N))
    M = sp.csr_matrix((np.tile(me.ravel(), n_elements), (rows, cols)), shape=(N, N))
    held = np.zeros(N, bool)
    held[list(fixed[0])] = True
    held[[N - 2 + k for k in fixed[1]]] = True
    keep = np.flatnonzero(~held)
    red = -np.ones(N, dtype=np.int64)
    red[keep] = np.arange(len(keep))
    T = sp.csr_matrix((np.ones(len(keep)), (keep, np.arange(len(keep)))), shape=(N, len(keep)))
    Mr = (T.T @ M @ T).tocsr()
    Kr = (T.T @ K @ T).tocsr()
    cps = []
    for name, edge, y in contacts:
        node = int(round((y - y0) / l))
        if not 0 <= node < nn or abs(ys[node] - y) > 1e-9 * length:
            raise ValueError(f"{kind} contact {name} at y = {y}: not on a node (element length {l:g} m); "
                             "choose beam_elements so that every contact height is a node "
                             f"({fitting_hint(y0, length, [c[2] for c in contacts], n_elements)})")
        if red[2 * node] < 0:
            raise ValueError(f"{kind} contact {name} at y = {y}: on a held end (solid.clamped)")
        xe = x0 if edge == "left" else x0 + width
        nrm = (1.0, 0.0) if edge == "left" else (-1.0, 0.0)
        cps.append(ContactPoint(name, (xe, y), nrm, int(red[2 * node]), -1, int(red[2 * node + 1])))
    nodes = np.column_stack([np.full(nn, x0 + width / 2), ys])
    elems = np.column_stack([np.arange(n_elements), np.arange(1, nn)])

    T_deflection = sp.csr_matrix(T)[0::2]  # the rows of the nodes' deflections

    def full(q):  # (ndof,) -> (nn, 2); (ndof, m) -> (nn, 2, m)
        x = T_deflection @ q
        return np.stack([x, np.zeros_like(x)], axis=1)

    def energies(q, v):
        xq, xv = (T @ q)[d], (T @ v)[d]  # (ne, 4)
        return 0.5 * np.einsum("ei,ij,ej->e", xv, me, xv), 0.5 * np.einsum("ei,ij,ej->e", xq, ke, xq)

    info = {"dofs": int(len(keep)), "elements": int(n_elements), "nodes": int(nn), "width": width,
            "thickness": slab.thickness, "area": width * slab.thickness} | info
    model = SolidModel(kind, Mr, Kr, cps, info, T, nodes, elems, energies, np.full(n_elements, width * slab.thickness * l),
                       full)
    across = np.zeros(N)
    across[0::2] = 1.0  # a unit translation across the line (x); along its axis it is held rigidly
    model.unit_weight = np.column_stack([T.T @ (M @ across), np.zeros(len(keep))])
    return model


def clamped_clamped_periods(E, rho, width, thickness, length, count=5) -> np.ndarray:
    """Exact Euler-Bernoulli periods: cos(bL) cosh(bL) = 1, w = (bL)^2 sqrt(EI / (rho A L^4))."""
    from scipy.optimize import brentq

    f = lambda x: np.cos(x) * np.cosh(x) - 1.0  # noqa: E731
    roots = [brentq(f, (n + 0.5) * np.pi - 0.5, (n + 0.5) * np.pi + 0.5) for n in range(1, count + 1)]
    A = width * thickness
    I = thickness * width**3 / 12.0
    w = np.array(roots) ** 2 * np.sqrt(E * I / (rho * A * length**4))
    return 2 * np.pi / w


STRIPS = 21  # strips across the depth on which pictures spread a beam element's energy


def energy_density_strips(model: SolidModel, q, v, strips: int = STRIPS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's spreading of beam element energies across the width (Sec. IV): kinetic energy
    uniform across the depth, strain energy parabolic (12 s^2 times its mean, zero on the neutral
    axis, s = across / depth in [-1/2, 1/2]), each strip given its mean, so that the strips
    integrate back to the element's energy exactly. Returns (x edges (strips+1,), y edges
    (ne+1,), w (ne, strips)) [m, m, J/m^3]."""
    kin, pot = model.element_energies(q, v)
    vol = model.element_volume
    s = np.linspace(-0.5, 0.5, strips + 1)
    mean = 4.0 * (s[1:] ** 3 - s[:-1] ** 3) / np.diff(s)  # the mean of 12 s^2 over each strip
    w = (kin / vol)[:, None] + (pot / vol)[:, None] * mean[None, :]
    return model.nodes[0, 0] + s * model.info["width"], model.nodes[:, 1], w


# second derivatives d^2/ds^2 of the Hermite cubics N1 = 1 - 3s^2 + 2s^3, N2 = l (s - 2s^2 + s^3),
# N3 = 3s^2 - 2s^3, N4 = l (s^3 - s^2) at the element centre s = 1/2: (0, -l, 0, l); d/dy = (1/l) d/ds
HERMITE_D2_CENTRE = (0.0, -1.0, 0.0, 1.0)  # times (1/l^2, 1/l, 1/l^2, 1/l)


def bending_stress(model: SolidModel, E: float, x: np.ndarray) -> dict[str, np.ndarray]:
    """The beam's outer-fibre bending stress E (h/2) |w''| [Pa] at each element's centre, (ne,),
    from the full DOF vector x (= T q: deflection, rotation dw/dy at each node), w'' from the
    element's Hermite cubic; h = the section depth in the bending plane (`info["width"]`)."""
    x = np.asarray(x, float)
    i, j = np.asarray(model.elements).T
    l = model.nodes[j, 1] - model.nodes[i, 1]
    a, b, c, d = HERMITE_D2_CENTRE
    curvature = (a * x[2 * i] / l + b * x[2 * i + 1] + c * x[2 * j] / l + d * x[2 * j + 1]) / l
    return {"bending_stress": E * model.info["width"] / 2 * np.abs(curvature)}


class BeamKind(SolidKind):
    """The Euler-Bernoulli beam of eq. (9) (`build_beam`), drawn as its centre line."""

    line_is_whole = True  # its axis carries its whole motion (`LineSampling.whole`)
    name = "beam"
    fields = SolidKind.fields | {"material", "thickness", "beam_elements", "clamped"}

    def recipe_fields(self, section, material) -> dict:  # Poisson's ratio unused: it keeps its default
        return super().recipe_fields(section, material) | dict(
            thickness=section.thickness, E=material.E, rho=material.rho, beam_elements=section.beam_elements,
            clamped=tuple(section.clamped))

    def build(self, recipe) -> SolidModel:
        r = recipe
        return build_beam(r.slab, r.material, [(c.name, c.edge, c.position[1]) for c in r.contacts], r.beam_elements,
                          r.clamped)

    def size(self, section, focus=()) -> tuple[int, int]:
        """Two DOFs (deflection, rotation) per node, before clamping."""
        return 2 * (section.beam_elements + 1), section.beam_elements

    def box(self, model):
        """Its node line widened by the section's depth."""
        xm, half = float(model.nodes[0, 0]), 0.5 * model.info["width"]
        return xm - half, float(model.nodes[:, 1].min()), xm + half, float(model.nodes[:, 1].max())

    def shape(self, model, u=None, scale=0.0) -> Shape:
        xy = model.nodes + (scale * u if u is not None else 0.0)
        return Shape(line=np.column_stack([xy[:, 0], model.nodes[:, 1]]))

    def energy_cells(self, model, q, v) -> Patches:
        """The element energies spread across the depth (`energy_density_strips`): ne x 21 rectangles."""
        xe, ys, w = energy_density_strips(model, q, v)
        X0, Y0 = np.meshgrid(xe[:-1], ys[:-1])
        X1, Y1 = np.meshgrid(xe[1:], ys[1:])
        polys = np.stack([np.stack([X0, Y0], -1), np.stack([X1, Y0], -1), np.stack([X1, Y1], -1),
                          np.stack([X0, Y1], -1)], axis=2)  # (ne, nx, 4, 2)
        return Patches(polys.reshape(-1, 4, 2), w.ravel())

    def export_cells(self, model):
        return [("line", np.asarray(model.elements, dtype=np.int64))]

    def stress(self, model, x, E, nu):
        return bending_stress(model, E, x)

    def mode_kinds(self, model, shapes, which):
        return ["bending" for _ in which]

    def deflection_dofs(self, model) -> np.ndarray:
        """The full DOF of each drawn node's deflection (the Hermite line's: every other one)."""
        return 2 * np.arange(len(model.nodes))

    dispersion = LineSampling.dispersion  # Hermite cubics: below the quadratic elements' (kl)^4 / 1440

    def sampled_elements(self, model) -> int:
        """The elements of the uniform grid its wavefield samples along its length: every one."""
        return len(model.nodes) - 1

    def wave_lines(self, model, samples=None) -> LineSampling:
        """Its one line of nodes: every node of the uniform grid of `sampled_elements` that is not
        clamped, the deflection sampled (each sample height read from the node at it)."""
        r = model.recipe
        if r is None:
            return super().wave_lines(model, samples)
        ne = self.sampled_elements(model)
        clamped = tuple(bool(c) for c in r.clamped)
        count = {(True, True): ne - 1, (False, False): ne + 1}.get(clamped, ne)
        full, dofs = model.T.shape[0], self.deflection_dofs(model)
        node_y = np.asarray(model.nodes[:, 1], float)

        def sampler(y):
            y = np.asarray(y, float)
            at = np.clip(np.searchsorted(node_y, y), 1, len(node_y) - 1)
            at = np.where(np.abs(node_y[at - 1] - y) < np.abs(node_y[at] - y), at - 1, at)
            if np.abs(node_y[at] - y).max(initial=0.0) > 1e-6 * r.length / ne:
                raise ValueError(f"a {self.name}'s wavefield samples its nodes: a height off them")
            return sp.csr_matrix((np.ones(len(at)), (np.arange(len(at)), dofs[at])), shape=(len(at), full))

        return LineSampling(np.array([r.x0 + r.width / 2]), np.array([r.rho * r.width * r.thickness]), ("x",), count,
                            float(r.length / ne), sampler, self.dispersion, self.line_is_whole)

    def branches(self, model, k, count=3):
        """The Euler-Bernoulli branch (EB) of its EI and rho A."""
        return {"EB": euler_bernoulli_frequency(k, model.info["EI"], model.info["rhoA"])}


BEAM = BeamKind()
