"""Drawing primitives of the schematics, in millimetres on a matplotlib axes: the colours, the
gid tags ``"panel|kind|name"`` (`tagged` finds them again), clamped boundaries, granules, arrows,
dimension lines, Q8 element outlines, and the solid, walls and shocks of a planar model."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

from ..solid.kinds import kind_of  # noqa: E402
from .model_geometry import solid_box  # noqa: E402

MM = 1e3  # drawing unit: millimetres per metre

# colours: one per medium, the solid, the boundary conditions
MEDIUM_COLOURS = ["#8FB3D9", "#E8B08A", "#9CCB9C", "#D99A9A"]
SOLID_COLOUR = "#C8C8C8"
GROUND_COLOUR = "0.25"
SHOCK_COLOUR = "#C0392B"
SWAPPED_COLOUR = "#7D3C98"
CONTACT_COLOUR = "#D62728"
FREE_EDGE_COLOUR = "#1F77B4"
LAYER_COLOUR = "#E67E22"


# ------------------------------------------------------------------ tags


def _tag(artist, panel: str, kind: str, name: str = ""):
    artist.set_gid(f"{panel}|{kind}|{name}")
    return artist


def tagged(fig, panel: str, kind: str) -> dict:
    """The artists of `fig` tagged ``panel|kind|name``, keyed by name.

    E.g. ``tagged(fig, "a", "wall")`` gives the rigid walls of Fig. 1(a) as Line2D objects
    (data in mm); ``tagged(fig, "b", "elements")[""]`` is the plate mesh of Fig. 2(b).
    """
    out = {}
    for a in fig.findobj(lambda a: isinstance(a.get_gid(), str) and a.get_gid().count("|") >= 2):
        p, k, name = a.get_gid().split("|", 2)
        if p == panel and k == kind:
            out[name] = a
    return out


# ------------------------------------------------------------------ drawing primitives


def _clean(ax) -> None:
    ax.set_aspect("equal")
    ax.grid(False)
    ax.tick_params(labelsize=8)


def draw_ground(ax, p0, p1, outward, depth, panel, kind, name, colour=GROUND_COLOUR, lw=2.0):
    """A clamped boundary: the line p0-p1 [mm] with a hatched band of `depth` on its `outward`
    side. Returns the boundary line (tagged `kind`); the band is tagged `kind`-hatch."""
    p0, p1, o = (np.asarray(v, float) for v in (p0, p1, outward))
    band = np.array([p0, p1, p1 + depth * o, p0 + depth * o])
    hatch = Polygon(band, closed=True, fc="none", ec=colour, lw=0, hatch="////")
    ax.add_patch(_tag(hatch, panel, kind + "-hatch", name))
    (line,) = ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=colour, lw=lw, solid_capstyle="butt")
    return _tag(line, panel, kind, name)


def draw_granules(ax, system, panel, members=None, fontsize=8, alpha=1.0, labels=True):
    """Discs with their labels (the part after 'MEDIUM:'); labels tagged granule-label."""
    members = range(system.n) if members is None else members
    for g in members:
        x, y = system.pos0[g] * MM
        fc = MEDIUM_COLOURS[system.medium_index[g] % len(MEDIUM_COLOURS)]
        ax.add_patch(_tag(Circle((x, y), system.radius[g] * MM, fc=fc, ec="k", lw=0.7, alpha=alpha),
                          panel, "granule", system.labels[g]))
        if labels:
            small = fontsize * min(1.0, system.radius[g] / system.radius.max()) ** 0.3
            _tag(ax.text(x, y, system.labels[g].split(":", 1)[1], ha="center", va="center", fontsize=small),
                 panel, "granule-label", system.labels[g])


def draw_arrow(ax, tail, head, colour, panel, kind, name, lw=1.6, ls="-", mutation_scale=12):
    """An arrow from tail to head [mm] (an Annotation: .xy is the head, .xyann the tail)."""
    ann = ax.annotate("", xy=tuple(head), xytext=tuple(tail),
                      arrowprops=dict(arrowstyle="-|>", color=colour, lw=lw, ls=ls, shrinkA=0, shrinkB=0,
                                      mutation_scale=mutation_scale))
    return _tag(ann, panel, kind, name)


def draw_dimension(ax, a, b, panel, name, colour="k"):
    """A dimension line between a and b [mm] (arrows both ends), tagged layer-span."""
    ann = ax.annotate("", xy=tuple(b), xytext=tuple(a),
                      arrowprops=dict(arrowstyle="<|-|>", color=colour, lw=0.9, shrinkA=0, shrinkB=0,
                                      mutation_scale=7))
    return _tag(ann, panel, "layer-span", name)


def _element_polygons(model, elements=None) -> list[np.ndarray]:
    """The solid's element outlines [mm] (`SolidKind.shape`: a plate's Q8 through its corner and
    mid-side nodes), all or those of `elements`."""
    polygons = kind_of(model).shape(model).polygons
    return list((polygons if elements is None else polygons[elements]) * MM)


# ------------------------------------------------------------------ the planar model's parts (Fig. 1)


def draw_solid(ax, sc, model, panel, box=None):
    """The elastic solid of Fig. 1(b): outline, clamped ends (hatched), free lateral edges."""
    kind = kind_of(model)
    x0, y0, x1, y1 = np.array(box if box is not None else solid_box(model)) * MM
    ax.add_patch(_tag(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=SOLID_COLOUR, ec="k", lw=0.8,
                                hatch=None if kind.elastic else "x"), panel, "solid", model.kind))
    line = kind.shape(model).line if kind.elastic else None
    if line is not None:  # a solid drawn as its centre line (the beam's neutral axis)
        ax.plot(line[:, 0] * MM, line[:, 1] * MM, color="k", lw=0.8, ls="-.")
    depth = 0.03 * (y1 - y0)
    bottom, top = sc.solid.clamped
    if bottom:
        draw_ground(ax, (x0, y0), (x1, y0), (0, -1), depth, panel, "clamp", "bottom")
    if top:
        draw_ground(ax, (x0, y1), (x1, y1), (0, 1), depth, panel, "clamp", "top")
    for name, x in (("left", x0), ("right", x1)):
        (ln,) = ax.plot([x, x], [y0, y1], color=FREE_EDGE_COLOUR, lw=1.6, ls=(0, (4, 2)))
        _tag(ln, panel, "free-edge", name)
    return depth


def draw_walls(ax, system, panel, depth, fontsize=7):
    """Every rigid wall of the granular media as a hatched clamped boundary, named."""
    for w in system.walls:
        p0, p1 = np.asarray(w.p0) * MM, np.asarray(w.p1) * MM
        out = -np.asarray(w.normal, float) / np.hypot(*w.normal)
        draw_ground(ax, p0, p1, out, depth, panel, "wall", w.name)
        mid = 0.5 * (p0 + p1) + (depth + 0.6 * depth) * out
        vertical = abs(out[0]) > abs(out[1])
        ha = ("right" if out[0] < 0 else "left") if vertical else "center"
        va = "center" if vertical else ("top" if out[1] < 0 else "bottom")
        _tag(ax.text(*mid, w.name, ha=ha, va=va, fontsize=fontsize, rotation=90 if vertical else 0,
                     rotation_mode="anchor" if not vertical else "default"), panel, "wall-label", w.name)


def draw_shock(ax, system, exc, colour, panel, text="F(t)", ls="-"):
    """The shock F(t) on its granule: an arrow inside the disc along the force direction,
    ending short of the centre (the granule touches a wall on the side the force comes from)."""
    g = exc.granule
    c, R = system.pos0[g] * MM, system.radius[g] * MM
    d = np.asarray(exc.direction, float) / np.hypot(*exc.direction)
    draw_arrow(ax, c - 0.92 * R * d, c - 0.3 * R * d, colour, panel, "shock", system.labels[g], lw=2.0, ls=ls)
    _tag(ax.text(c[0], c[1] + 0.35 * R, text, color=colour, ha="center", va="bottom", fontsize=6.5,
                 fontweight="bold"), panel, "shock-label", system.labels[g])
