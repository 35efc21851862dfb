"""Initial overlaps of a built granular system, whatever built it, by one rule: no two granules
start pressed into each other; a granule may start pressed into a wall or the solid's face where a
contact law acts there, by up to `range_share` of its radius; nowhere else. Depths [m] are the
contact laws' own (eq. 2 for a pair, `kernels.wall_overlap` for a wall); one up to ROUND_OFF of
the radius is touching. `initial_overlaps` returns the deepest refused one of each kind.
docs/model.md ("Initial overlaps") gives the rule in full."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .neighbours import close_pairs

# touching within round-off of the positions (a table written with finite decimals)
ROUND_OFF = 1e-9


@dataclass(frozen=True)
class Overlap:
    """The deepest initial overlap of one kind: what (granule label), with what, how deep [m]."""

    kind: str  # "granules", "wall" or "solid"
    granule: str
    other: str
    depth: float


def pair_overlaps(pos: np.ndarray, radius: np.ndarray, labels) -> Overlap | None:
    if len(pos) < 2:
        return None
    pairs = close_pairs(pos, 2 * float(radius.max()))
    if not len(pairs):
        return None
    i, j = pairs[:, 0], pairs[:, 1]
    depth = radius[i] + radius[j] - np.hypot(*(pos[j] - pos[i]).T)
    bad = depth > ROUND_OFF * np.minimum(radius[i], radius[j])
    if not bad.any():
        return None
    k = int(np.argmax(np.where(bad, depth, -np.inf)))
    return Overlap("granules", labels[i[k]], labels[j[k]], float(depth[k]))


def wall_overlaps(pos: np.ndarray, radius: np.ndarray, labels, medium_index, wall_geometry, names,
                  range_share: float) -> Overlap | None:
    """The deepest granule-wall overlap beyond the law's range (`range_share` of the radius)
    among the granules a wall acts on (its medium, or all)."""
    p0, tan, length, nrm, medium, _ = wall_geometry
    worst = None
    for w in range(len(p0)):
        r = pos - p0[w]
        along = r @ tan[w]
        depth = radius - r @ nrm[w]
        act = (along >= 0) & (along <= length[w]) & ((medium[w] < 0) | (medium_index == medium[w]))
        bad = act & (depth > range_share * radius)
        if bad.any():
            g = int(np.argmax(np.where(bad, depth, -np.inf)))
            if worst is None or depth[g] > worst.depth:
                worst = Overlap("wall", labels[g], names[w], float(depth[g]))
    return worst


def solid_overlaps(pos: np.ndarray, radius: np.ndarray, labels, box, face=None, range_share: float = 0.0) -> Overlap | None:
    """The deepest overlap with the solid's rectangle `box` = (x0, y0, x1, y1): R minus the
    distance from the centre to the rectangle (R + the depth inside it for a centre within);
    the granules in `face` (the face's contacts, whose centres lie outside the rectangle) may be
    pressed in by up to `range_share` of their radius."""
    x0, y0, x1, y1 = box
    dx = np.maximum(np.maximum(x0 - pos[:, 0], pos[:, 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - pos[:, 1], pos[:, 1] - y1), 0.0)
    outside = np.hypot(dx, dy)
    inside = np.minimum.reduce([pos[:, 0] - x0, x1 - pos[:, 0], pos[:, 1] - y0, y1 - pos[:, 1]])
    depth = radius - np.where(outside > 0, outside, -np.maximum(inside, 0.0))
    allowed = np.full(len(pos), ROUND_OFF)
    if face is not None and len(face):
        allowed[np.asarray(face, int)] = np.where(outside[np.asarray(face, int)] > 0, max(range_share, ROUND_OFF), ROUND_OFF)
    bad = depth > allowed * radius
    if not bad.any():
        return None
    g = int(np.argmax(np.where(bad, depth, -np.inf)))
    return Overlap("solid", labels[g], "the solid", float(depth[g]))


def initial_overlaps(system, box=None, range_share: float = 0.1, wall_names=()) -> list[Overlap]:
    """Every kind's deepest initial overlap of `system` (its pos0) that the module's rule refuses,
    `box` the solid's rectangle (None: no solid), `range_share` the contact laws' range as a share
    of the radius."""
    pos, R, labels = system.pos0, system.radius, list(system.labels)
    names = list(wall_names) or [w.name or f"wall {k}" for k, w in enumerate(system.walls)]
    face = [c.granule for c in system.solid_contacts]
    found = [pair_overlaps(pos, R, labels),
             wall_overlaps(pos, R, labels, system.medium_index, system.wall_geometry, names, range_share)
             if system.walls else None,
             solid_overlaps(pos, R, labels, box, face, range_share) if box is not None else None]
    return [o for o in found if o is not None]
