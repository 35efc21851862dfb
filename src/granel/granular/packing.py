"""Granule packings: hexagonal columns beside a solid, with the paper's labels.

Geometry conventions (MODEL.md section 1): x is normal to the solid, y along it.
A medium on the `left` of the solid occupies x < face; on the `right`, x > face.
Columns are counted from the solid outward (column 0 touches the solid); labels run from
the outermost column inward, bottom to top, as in the paper (1..14 and A..N).
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass, field

import numpy as np

from ..excitation import WallDrive
from ..materials import Material


@dataclass(frozen=True)
class Wall:
    """A rigid flat wall segment from p0 to p1; `normal` points into the granular side."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    normal: tuple[float, float]
    medium: str = ""  # "" = touches granules of every medium
    name: str = ""
    drive: WallDrive | None = None  # a shaker: the wall moves along its normal (excitation.WallDrive)


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


def hexagonal_columns(
    name: str,
    columns: list[int],
    radius: float,
    material: Material,
    side: str,
    face_x: float,
    center_y: float,
    labels: str | list[str] = "numeric",
    channel_walls: bool = True,
    outer_wall: bool = False,
    gap: float = 0.0,
) -> Medium:
    """Hexagonally packed, initially touching columns parallel to a vertical solid face.

    columns[c] is the number of granules of column c (c = 0 touches the face). Column c sits at
    x = face -/+ (R + gap + c R sqrt(3)) and is shifted by R in y when c is odd; column 0 is
    centred on `center_y`. Channel walls (y = bottom - R and top + R of column 0) and an optional
    outer wall close the medium.
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    if not columns or any(c < 1 for c in columns):
        raise ValueError(f"columns must be positive counts, got {columns}")
    R = float(radius)
    sgn = -1.0 if side == "left" else 1.0
    col_pos = []
    for c, count in enumerate(columns):
        x = face_x + sgn * (R + gap + c * R * math.sqrt(3.0))
        # y = center_y + j R with j on column c's lattice (j = n0 - 1 + c mod 2), centred if possible
        js = [2 * k - (count - 1) for k in range(count)]
        if (js[0] - (columns[0] - 1 + c)) % 2:
            js = [j + 1 for j in js]
        col_pos.append(np.array([[x, center_y + j * R] for j in js]))
    # label order: outermost column first, bottom to top
    ordered = [p for p in reversed(col_pos)]
    pos = np.vstack(ordered)
    n = len(pos)
    if isinstance(labels, str):
        if labels == "numeric":
            lab = numeric_labels(n)
        elif labels == "alpha":
            lab = alpha_labels(n)
        else:
            raise ValueError(f"labels must be 'numeric', 'alpha' or a list, got {labels!r}")
    else:
        lab = [str(s) for s in labels]
        if len(lab) != n:
            raise ValueError(f"{len(lab)} labels given for {n} granules")
    contact = list(range(n - columns[0], n))
    walls = []
    x_in = face_x
    x_out = face_x + sgn * (R + gap + (len(columns) - 1) * R * math.sqrt(3.0) + R)
    xa, xb = min(x_in, x_out), max(x_in, x_out)
    if channel_walls:
        y_bot = float(pos[:, 1].min() - R)
        y_top = float(pos[:, 1].max() + R)
        walls.append(Wall((xa, y_bot), (xb, y_bot), (0.0, 1.0), name, f"{name}:bottom"))
        walls.append(Wall((xa, y_top), (xb, y_top), (0.0, -1.0), name, f"{name}:top"))
    if outer_wall:
        y_bot = float(pos[:, 1].min() - R)
        y_top = float(pos[:, 1].max() + R)
        walls.append(Wall((x_out, y_bot), (x_out, y_top), (-sgn, 0.0), name, f"{name}:outer"))
    return Medium(name, lab, pos, np.full(n, R), material, side, walls, contact)


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
    return Medium(name, lab, pos, rad, material, side, [], [], per)


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
