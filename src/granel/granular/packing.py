"""Granule packings: hexagonal columns beside a solid or anywhere, with the paper's labels.

Geometry conventions (MODEL.md section 1): x is normal to the solid, y along it.
A medium on the `left` of the solid occupies x < face; on the `right`, x > face.
Columns are counted from the solid outward (column 0 touches the solid); labels run from
the outermost column inward, bottom to top, as in the paper (1..14 and A..N). A medium away
from the solid (side = "none") grows from a face line in any of the four axis directions.
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass, field

import numpy as np

from .loads import WallDrive
from .materials import Material
from .neighbours import close_pairs


@dataclass(frozen=True)
class Wall:
    """A rigid flat wall segment from p0 to p1; `normal` points into the granular side. A damped
    wall's contacts carry the Tsuji dashpot of eq. (3) with m* = m; an undamped (elastic) one's
    are Hertz's alone (`materials.wall_coefficients`)."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    normal: tuple[float, float]
    medium: str = ""  # "" = touches granules of every medium
    name: str = ""
    drive: WallDrive | None = None  # a shaker: the wall moves along its normal (excitation.WallDrive)
    damped: bool = True  # False: no dashpot at its contacts (an elastic wall)


@dataclass(frozen=True)
class Placement:
    """Where a built medium lies: the side of the solid it sits on (left, right or none), its face
    line (x = face; y = face for a medium growing up or down), the centre of its first column along
    that line, the gap between the face and the first granules, and the direction it grows (None:
    away from the solid, along `side`)."""

    side: str
    face: float
    center: float
    gap: float = 0.0
    grow: str | None = None


@dataclass
class Medium:
    """One granular medium: granule centres, radii, labels, material and its walls."""

    name: str
    labels: list[str]
    pos: np.ndarray  # (n, 2) [m]
    radius: np.ndarray  # (n,) [m]
    material: Material
    side: str = "left"  # which side of the solid it sits on: left | right | none
    walls: list[Wall] = field(default_factory=list)
    contact_granules: list[int] = field(default_factory=list)  # indices touching the solid face
    granule_materials: list[Material] | None = None  # per granule, overriding `material`

    @property
    def n(self) -> int:
        return len(self.labels)

    def materials(self) -> list[Material]:
        return list(self.granule_materials) if self.granule_materials is not None else [self.material] * self.n


def alpha_labels(n: int) -> list[str]:
    """A..Z, then AA, AB, ... (spreadsheet style)."""
    out = []
    letters = string.ascii_uppercase
    for k in range(n):
        s, q = "", k
        while True:
            s = letters[q % 26] + s
            q = q // 26 - 1
            if q < 0:
                break
        out.append(s)
    return out


def numeric_labels(n: int) -> list[str]:
    return [str(k + 1) for k in range(n)]


def granule_labels(labels: str | list[str], n: int) -> list[str]:
    """n labels: 'numeric' (1..n), 'alpha' (A..Z, AA, ...) or the list given (n of them)."""
    if isinstance(labels, str):
        if labels == "numeric":
            return numeric_labels(n)
        if labels == "alpha":
            return alpha_labels(n)
        raise ValueError(f"labels must be 'numeric', 'alpha' or a list, got {labels!r}")
    lab = [str(s) for s in labels]
    if len(lab) != n:
        raise ValueError(f"{len(lab)} labels given for {n} granules")
    return lab


GROWTHS = ("left", "right", "up", "down")


def channel_names(grow: str) -> tuple[str, str]:
    """The two channel walls' names of a medium growing along `grow`: the walls that run along
    the growth direction, at either end of column 0."""
    return ("bottom", "top") if grow in ("left", "right") else ("left", "right")


# Touching granules are placed so that their overlap, as the kernels compute it
# (`granular.kernels.pair_overlap`, `wall_overlap`, `point_overlap`), is at most -CLEARANCE ulps of
# the sum of radii, never a round-off overlap: a packing spaced exactly by its radii has overlaps
# of about 1e-18 m here and there, whose Hertz forces set a medium that nothing loads moving at
# about 1e-19 m/s. The lattice is spaced by R (1 + lam), lam = 0 first, then 2^k eps: the smallest
# lam that clears every contact (a few 1e-15, moving granules by about 1e-16 m).
CLEARANCE = 2
MAX_SPACINGS = 40  # lam up to 2^38 eps, about 6e-5: beyond it something else is wrong


def _pair_clear(pos: np.ndarray, radius: np.ndarray, pairs: np.ndarray) -> bool:
    """Every pair (i, j) of `pairs` apart by CLEARANCE ulps or more in the kernel's arithmetic:
    (R_i + R_j) - sqrt(dx dx + dy dy) with dx = x_j - x_i (one more ulp covers a fused dx dx + dy dy)."""
    if not len(pairs):
        return True
    i, j = pairs[:, 0], pairs[:, 1]
    dx = pos[j, 0] - pos[i, 0]
    dy = pos[j, 1] - pos[i, 1]
    reach = radius[i] + radius[j]
    return bool(np.all(reach - np.sqrt(dx * dx + dy * dy) <= -CLEARANCE * np.spacing(reach)))


def _wall_clear(pos: np.ndarray, radius: np.ndarray, wall: Wall) -> bool:
    """No granule whose centre projects onto (or within a radius of) the wall overlaps it in the
    kernel's arithmetic, R - ((x - p0) . n), n the unit normal."""
    n = np.asarray(wall.normal, float) / math.hypot(*wall.normal)
    p0, p1 = np.asarray(wall.p0, float), np.asarray(wall.p1, float)
    length = math.hypot(*(p1 - p0))
    t = (p1 - p0) / length if length > 0 else np.zeros(2)
    rx, ry = pos[:, 0] - p0[0], pos[:, 1] - p0[1]
    along = rx * t[0] + ry * t[1]
    near = (along >= -radius) & (along <= length + radius)
    overlap = radius - (rx * n[0] + ry * n[1])
    return bool(np.all(overlap[near] <= -CLEARANCE * np.spacing(radius[near])))


def _face_clear(pos: np.ndarray, radius: np.ndarray, face: float, side: str) -> bool:
    """Column 0 clear of the solid's face x = face, as `point_overlap` computes it at rest: the
    gap (face + 0 - x) n_x along n_x = +1 (a medium on the left) or -1 (on the right)."""
    nx = 1.0 if side == "left" else -1.0
    gap = (face + 0.0 - pos[:, 0]) * nx
    return bool(np.all(radius - gap <= -CLEARANCE * np.spacing(radius)))


def _spaced(layout, name: str):
    """layout(lam) -> (pos, radius, walls, pairs, face check or None) with the lattice spaced by
    R (1 + lam): the first of lam = 0, eps, 2 eps, 4 eps, ... whose contacts all clear (see
    CLEARANCE)."""
    for k in range(MAX_SPACINGS):
        lam = 0.0 if k == 0 else math.ldexp(np.finfo(float).eps, k - 1)
        pos, radius, walls, pairs, face_ok = layout(lam)
        if (_pair_clear(pos, radius, pairs) and all(_wall_clear(pos, radius, w) for w in walls)
                and (face_ok is None or face_ok(pos, radius))):
            return pos, walls
    raise ValueError(f"medium {name}: no spacing within {lam:.1e} of its radii clears every contact in floating point")


def hexagonal_columns(
    name: str,
    columns: list[int],
    radius: float,
    material: Material,
    at: Placement,
    labels: str | list[str] = "numeric",
    walls: tuple[str, ...] = ("bottom", "top"),
) -> Medium:
    """Hexagonally packed, initially touching columns (clear by `CLEARANCE` ulps) parallel to a
    face line, placed `at` (column 0 nearest the face, centred on `at.center`). `walls` names the
    rigid walls that close it (the two channel walls, `outer`, `face`); labels run from the
    outermost column inward, as in the paper (1..14 and A..N). Returns the Medium (lengths in m);
    raises ValueError for a placement, column count, wall or labels it cannot build. docs/model.md
    ("Building the media") gives the layout."""
    side, face, center, gap = at.side, at.face, at.center, at.gap
    grow = side if at.grow is None else at.grow
    if side not in ("left", "right", "none"):
        raise ValueError(f"side must be 'left', 'right' or 'none', got {side!r}")
    if grow not in GROWTHS:
        raise ValueError(f"grow must be one of {list(GROWTHS)}, got {grow!r}")
    if side != "none" and grow != side:
        raise ValueError(f"grow = {grow!r}: a medium on the {side} of the solid grows to the {side}")
    if not columns or any(c < 1 for c in columns):
        raise ValueError(f"columns must be positive counts, got {columns}")
    known = channel_names(grow) + ("outer", "face")
    for w in walls:
        if w not in known:
            raise ValueError(f"walls: {w!r} is not a wall of a medium growing {grow}; choose from {list(known)}")
    if "face" in walls and side != "none":
        raise ValueError("walls: 'face' would lie on the solid's face; only a medium with side = 'none' has one")
    R = float(radius)
    sgn = -1.0 if grow in ("left", "down") else 1.0
    n = sum(columns)
    lab = granule_labels(labels, n)
    contact = list(range(n - columns[0], n))
    rad = np.full(n, R)
    lo, hi = channel_names(grow)
    e_s = (0.0, 1.0) if grow in ("left", "right") else (1.0, 0.0)  # along the face, +s
    along = (sgn, 0.0) if grow in ("left", "right") else (0.0, sgn)  # along the growth

    def frame(u, s):  # (u, s) -> (x, y)
        return (face + sgn * u, s) if grow in ("left", "right") else (s, face + sgn * u)

    def layout(lam):
        Rs = R * (1.0 + lam)  # the lattice's spacing radius (see CLEARANCE)
        local = []  # (u, s) of each column, u the distance from the face
        for c, count in enumerate(columns):
            u = Rs + gap + c * Rs * math.sqrt(3.0)
            # s = center + j R with j on column c's lattice (j = n0 - 1 + c mod 2), centred if possible
            js = [2 * k - (count - 1) for k in range(count)]
            if (js[0] - (columns[0] - 1 + c)) % 2:
                js = [j + 1 for j in js]
            local.append(np.array([[u, center + j * Rs] for j in js]))
        us = np.vstack(list(reversed(local)))  # label order: outermost column first, then along +s
        pos = np.array([frame(u, s) for u, s in us])
        u_out = Rs + gap + (len(columns) - 1) * Rs * math.sqrt(3.0) + Rs
        s_lo, s_hi = float(us[:, 1].min() - Rs), float(us[:, 1].max() + Rs)
        made = []
        if lo in walls:  # the channel wall at s_lo faces +s, the one at s_hi faces -s
            made.append((lo, frame(0.0, s_lo), frame(u_out, s_lo), e_s))
        if hi in walls:
            made.append((hi, frame(0.0, s_hi), frame(u_out, s_hi), (-e_s[0], -e_s[1])))
        if "outer" in walls:
            made.append(("outer", frame(u_out, s_lo), frame(u_out, s_hi), (-along[0], -along[1])))
        if "face" in walls:
            made.append(("face", frame(0.0, s_lo), frame(0.0, s_hi), along))
        out = []
        for w, a, b, nrm in made:
            a, b = sorted((tuple(map(float, a)), tuple(map(float, b))))
            out.append(Wall(a, b, tuple(float(c) + 0.0 for c in nrm), name, f"{name}:{w}"))
        face_ok = None
        if side != "none":  # column 0 against the solid's face
            face_ok = lambda p, r: _face_clear(p[contact], r[contact], face, side)  # noqa: E731
        return pos, rad, out, close_pairs(pos, 2 * R * (1 + 1e-9)), face_ok

    pos, out = _spaced(layout, name)
    return Medium(name=name, labels=lab, pos=pos, radius=np.full(n, R), material=material, side=side, walls=out,
                  contact_granules=contact)


def chain(name: str, radii: list[float], materials: list[Material], at: Placement, walls: tuple[str, ...] = ()) -> Medium:
    """A straight chain of touching beads, radii[0] nearest the face, grown from the face line
    along `at.grow` (as `hexagonal_columns`; centred on `at.center` along the face), each bead of its
    own material. Labels 1..n run from the far end to the face, as a column's do: label 1 is the
    outermost bead. `walls`: `face` (on the face line, only away from a solid) and `outer`
    (touching the last bead). Touching beads and walls clear by a few ulps (`CLEARANCE`)."""
    side, face, center, gap = at.side, at.face, at.center, at.gap
    grow = side if at.grow is None else at.grow
    if grow not in GROWTHS:
        raise ValueError(f"grow must be one of {list(GROWTHS)}, got {grow!r}")
    if side != "none" and grow != side:
        raise ValueError(f"grow = {grow!r}: a medium on the {side} of the solid grows to the {side}")
    if not radii or any(not r > 0 for r in radii):
        raise ValueError(f"radii must be positive, got {radii}")
    if len(materials) != len(radii):
        raise ValueError(f"{len(materials)} materials for {len(radii)} beads")
    for w in walls:
        if w not in ("face", "outer"):
            raise ValueError(f"walls: {w!r} is not a wall of a chain; choose from ['face', 'outer']")
    if "face" in walls and side != "none":
        raise ValueError("walls: 'face' would lie on the solid's face; only a medium with side = 'none' has one")
    sgn = -1.0 if grow in ("left", "down") else 1.0
    n = len(radii)

    def frame(a, b):  # (distance from the face, position along it) -> (x, y)
        return (face + sgn * a, b) if grow in ("left", "right") else (b, face + sgn * a)

    order = list(reversed(range(n)))  # label 1 = the outermost bead
    rad = np.array([float(radii[k]) for k in order])
    mats = [materials[k] for k in order]
    top = max(radii)
    links = np.array([[k, k + 1] for k in range(n - 1)], dtype=int).reshape(-1, 2)  # neighbours in label order

    def layout(lam):
        u, prev = [], None  # each bead's distance from the face, spaced by its radii (1 + lam)
        for r in radii:
            u.append(gap + r * (1.0 + lam) if prev is None else u[-1] + (prev + r) * (1.0 + lam))
            prev = r
        u_out = u[-1] + radii[-1] * (1.0 + lam)
        pos = np.array([frame(u[k], center) for k in order])
        made = {"face": (frame(0.0, center - top), frame(0.0, center + top),
                         (sgn, 0.0) if grow in ("left", "right") else (0.0, sgn)),
                "outer": (frame(u_out, center - top), frame(u_out, center + top),
                          (-sgn, 0.0) if grow in ("left", "right") else (0.0, -sgn))}
        out = []
        for w in walls:
            a, b, nrm = made[w]
            a, b = sorted((tuple(map(float, a)), tuple(map(float, b))))
            out.append(Wall(a, b, tuple(float(c) + 0.0 for c in nrm), name, f"{name}:{w}"))
        face_ok = None
        if side != "none":  # the bead nearest the face (the last label) against the solid
            face_ok = lambda p, r: _face_clear(p[-1:], r[-1:], face, side)  # noqa: E731
        return pos, rad, out, links, face_ok

    pos, out = _spaced(layout, name)
    return Medium(name=name, labels=numeric_labels(n), pos=pos, radius=rad, material=mats[0], side=side, walls=out,
                  contact_granules=[n - 1], granule_materials=mats)


def medium_from_table(name: str, rows: list[dict], material: Material, side: str = "none",
                      materials: dict[str, Material] | None = None) -> Medium:
    """A medium from explicit granules: rows of {label, x, y, radius[, material]}; a row's
    `material` names an entry of `materials` (empty: the medium's material)."""
    lab = [str(r["label"]) for r in rows]
    pos = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    rad = np.array([float(r["radius"]) for r in rows])
    per = None
    if any(r.get("material") for r in rows):
        per = []
        for r in rows:
            key = (r.get("material") or "").strip()
            if key and (materials is None or key not in materials):
                raise ValueError(f"granule {r['label']}: unknown material {key!r}; defined: {sorted(materials or {})}")
            per.append(materials[key] if key else material)
    return Medium(name=name, labels=lab, pos=pos, radius=rad, material=material, side=side, walls=[],
                  contact_granules=[], granule_materials=per)


def read_granules_csv(path) -> list[dict]:
    """Read `label,x,y,radius[,material]` rows (header required). Every value is checked: a
    non-empty label, unique in the file, finite x and y, a finite positive radius; the error
    names the file, the line and the column."""
    import csv

    rows, seen = [], {}
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        need = ("label", "x", "y", "radius")
        if reader.fieldnames is None or not set(need).issubset(reader.fieldnames):
            raise ValueError(f"{path}: header must contain {list(need)}, got {reader.fieldnames}")
        for r in reader:
            line = reader.line_num
            where = f"{path}, line {line}"
            if None in r or any(r.get(k) is None for k in need):
                raise ValueError(f"{where}: expected {len(reader.fieldnames)} columns ({','.join(reader.fieldnames)})")
            label = r["label"].strip()
            if not label:
                raise ValueError(f"{where}: empty label")
            if label in seen:
                raise ValueError(f"{where}: label {label!r} repeats line {seen[label]}")
            seen[label] = line
            row = {"label": label, "material": (r.get("material") or "").strip()}
            for k in ("x", "y", "radius"):
                try:
                    row[k] = float(r[k])
                except ValueError:
                    raise ValueError(f"{where}: {k} = {r[k]!r} is not a number") from None
                if not math.isfinite(row[k]):
                    raise ValueError(f"{where}: {k} = {r[k]!r} is not finite")
            if row["radius"] <= 0:
                raise ValueError(f"{where}: radius = {r['radius']!r} must be positive")
            rows.append(row)
    if not rows:
        raise ValueError(f"{path}: no granules")
    return rows


def hexagonal_block(nx: int, ny: int, radius: float, origin=(0.0, 0.0)) -> np.ndarray:
    """Centres of an nx-by-ny hexagonal block of touching discs (rows along x)."""
    R = radius
    pts = []
    for j in range(ny):
        x0 = origin[0] + R + (R if j % 2 else 0.0)
        y = origin[1] + R + j * R * math.sqrt(3.0)
        for i in range(nx):
            pts.append((x0 + 2 * R * i, y))
    return np.array(pts)
