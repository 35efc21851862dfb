"""Where things are in a scenario's built models, for the schematics: the solid's box, a plate
contact's rigid layer, a medium's central contact, a granule's touching partner, the mirrored
shock site; and the scenario's models built again with another solid kind."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scenario.build import built_models, present_solid
from ..solid.kinds import kind_of


# ------------------------------------------------------------------ look-ups


def _require_solid(sc) -> None:
    if present_solid(sc) is None:
        raise ValueError(f"scenario {sc.name!r} has no solid ([solid] table or kind = none): Figs. 1-2 draw a granular-solid "
                         "interface; add a solid (kind = plate | beam | rigid)")


def with_solid_kind(sc, kind: str):
    """A copy of the scenario whose solid is of `kind` (a name of `solid.kinds.KINDS`)."""
    _require_solid(sc)
    return sc.model_copy(update={"solid": sc.solid.model_copy(update={"kind": kind})})


def _system(sc):
    return built_models(with_solid_kind(sc, "rigid"))[0]


def _solid_model(sc, system, kind: str):
    return built_models(with_solid_kind(sc, kind))[1]


def _contact(model, name: str):
    for c in model.contacts:
        if c.name == name:
            return c
    raise KeyError(f"no contact {name!r} on the {model.kind}; contacts: {', '.join(c.name for c in model.contacts)}")


# ------------------------------------------------------------------ geometry from the models


@dataclass(frozen=True)
class RigidLayer:
    """The massless rigid layer of a plate contact (Sec. II B; Fig. 2(c)-(d)).

    `nodes` are the plate nodes on the layer (sorted by height), `x` the edge abscissa and
    `y_lo`, `y_hi` its ends [m]."""

    name: str
    nodes: np.ndarray
    x: float
    y_lo: float
    y_hi: float

    @property
    def length(self) -> float:
        return self.y_hi - self.y_lo

    @property
    def centre(self) -> float:
        return 0.5 * (self.y_lo + self.y_hi)


def rigid_layer(model, name: str) -> RigidLayer:
    """Find the rigid layer of contact `name` from the plate's constraints: its nodes are those
    that follow a unit translation u_x of the layer's driven (mid-node) DOF rigidly.

    Without rigid layers (mesh.rigid_layers = false) only the contact node moves: length 0."""
    if "rigid_layers" not in model.info:
        raise ValueError(f"rigid layers belong to the plate model, not to a {model.kind}")
    c = _contact(model, name)
    q = np.zeros(model.ndof)
    q[c.dof_x] = 1.0
    u = model.full_displacement(q)
    nodes = np.flatnonzero(np.abs(u[:, 0] - 1.0) < 1e-12)
    nodes = nodes[np.argsort(model.nodes[nodes, 1])]
    ys = model.nodes[nodes, 1]
    return RigidLayer(name, nodes, float(model.nodes[nodes[0], 0]), float(ys[0]), float(ys[-1]))


def solid_box(model) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) of the solid [m], as its kind gives it (`SolidKind.box`: a plate's node
    extents, a beam's node line widened by its depth, a rigid solid's rectangle)."""
    return kind_of(model).box(model)


def central_contact(model, system, medium: str) -> str | None:
    """The solid contact of `medium` nearest the middle of its contact column (the paper's
    LSGM:12 and SSGM:L), or None if the medium does not touch the solid."""
    names = [c.name for c in model.contacts if c.name.split(":")[0] == medium]
    if not names:
        return None
    ys = np.array([_contact(model, n).position[1] for n in names])
    return names[int(np.argmin(np.abs(ys - 0.5 * (ys.min() + ys.max()))))]


def touching_partner(system, i: int) -> int:
    """A granule touching granule i, preferring an oblique contact (largest |n_x n_y|, then
    the upper one), as in the paper's Fig. 1(c)."""
    d = system.pos0 - system.pos0[i]
    dist = np.hypot(d[:, 0], d[:, 1])
    touch = np.abs(dist - (system.radius + system.radius[i])) < 1e-9 * system.radius[i]
    touch[i] = False
    cands = np.flatnonzero(touch)
    if not len(cands):
        raise ValueError(f"granule {system.labels[i]} touches no other granule")
    n = d[cands] / dist[cands, None]
    score = np.round(np.abs(n[:, 0] * n[:, 1]), 9) + 1e-3 * n[:, 1]
    return int(cands[np.argmax(score)])


def unit_normal_tangent(n) -> tuple[np.ndarray, np.ndarray]:
    """(n, t) with t = k x n: the tangent is n turned by +90 degrees (eq. 5)."""
    n = np.asarray(n, float) / np.hypot(*n)
    return n, np.array([-n[1], n[0]])


def swapped_shock(sc, system):
    """The paper's reciprocal excitation site (Fig. 3: shock on 3 vs on C).

    With a single excitation on a medium beside the solid and another medium on the opposite
    side, return (label, Excitation) for the mirror granule of the other medium (same column
    counted from the solid, same offset from the medium's mid-height in radii), pushed toward
    the solid; otherwise None."""
    if len(sc.excitations) != 1:
        return None
    spec = sc.excitations[0]
    sides = {m.name: m.side for m in sc.media}
    medium, _ = spec.granule.split(":", 1)
    others = [m for m, s in sides.items() if s in ("left", "right") and s != sides.get(medium)]
    if sides.get(medium) not in ("left", "right") or len(others) != 1:
        return None
    g = system.index(spec.granule)
    col, row = _lattice_place(sc, system, g)
    best = None
    for h in system.medium_members(others[0]):
        c, r = _lattice_place(sc, system, h)
        if c == col and abs(r - row) < 0.5:
            best = h
    if best is None:
        return None
    label = system.labels[best]
    swapped = sc.model_copy(update={"excitations": [spec.model_copy(update={"granule": label})]})
    return label, _system(swapped).excitations[0]


def _lattice_place(sc, system, g: int) -> tuple[int, float]:
    """(column counted from the solid, height offset from the medium's middle in radii)."""
    s = sc.solid
    members = np.flatnonzero(system.medium_index == system.medium_index[g])
    side = {m.name: m.side for m in sc.media}[system.media[system.medium_index[g]]]
    face = s.x0 if side == "left" else s.x0 + s.width
    R = system.radius[g]
    dist = np.abs(system.pos0[members, 0] - face)
    col = int(round((abs(system.pos0[g, 0] - face) - dist.min()) / (R * np.sqrt(3.0))))
    ym = 0.5 * (system.pos0[members, 1].min() + system.pos0[members, 1].max())
    return col, float((system.pos0[g, 1] - ym) / R)
