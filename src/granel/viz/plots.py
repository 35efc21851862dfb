"""Figures (matplotlib, Agg backend): geometry now; the paper's figures build on these helpers."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from ..scenario.build import built_models, present_solid  # noqa: E402
from ..solid.kinds import is_elastic, kind_of  # noqa: E402



def save(fig, path: str | Path, dpi: int = 200) -> Path:
    """A figure to `path`, atomically and marked as granel's (`guard.writing.save_figure`), closed."""
    from ..guard.writing import save_figure

    return save_figure(fig, path, dpi=dpi, bbox_inches="tight")


def plot_geometry(sc, output: str | Path, ax=None):
    """The packing with labels, walls, the solid, the solid contact points and excitations."""
    system = built_models(sc)[0]
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(7, 7))
    colors = ["#4C72B0", "#DD8452", "#55A868", "#C44E52", "#8172B3"]
    for g in range(system.n):
        c = colors[system.medium_index[g] % len(colors)]
        x, y = system.pos0[g]
        ax.add_patch(Circle((x, y), system.radius[g], fc=c, ec="k", lw=0.6, alpha=0.55))
        ax.text(x, y, system.labels[g].split(":")[-1], ha="center", va="center", fontsize=7)
    for w in system.walls:
        ax.plot([w.p0[0], w.p1[0]], [w.p0[1], w.p1[1]], color="k", lw=2.5, solid_capstyle="butt")
    if present_solid(sc) is not None:
        s = sc.solid
        ax.add_patch(Rectangle((s.x0, s.y0), s.width, s.length, fc="#BBBBBB", ec="k", lw=0.8,
                               hatch=None if is_elastic(s.kind) else "//"))
        ax.plot([s.x0, s.x0 + s.width], [s.y0, s.y0], color="k", lw=3)
        ax.plot([s.x0, s.x0 + s.width], [s.y0 + s.length, s.y0 + s.length], color="k", lw=3)
        ax.set_title(f"{sc.name}: solid = {s.kind}")
    for c in system.solid_contacts:
        ax.plot(*c.point, "r.", ms=5)
    for e in system.excitations:
        x, y = system.pos0[e.granule]
        d = np.asarray(e.direction, float)
        L = 2.5 * system.radius[e.granule]
        ax.annotate("", xy=(x - d[0] * system.radius[e.granule], y - d[1] * system.radius[e.granule]),
                    xytext=(x - d[0] * L, y - d[1] * L), arrowprops=dict(arrowstyle="-|>", color="r", lw=2))
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if own:
        return save(fig, output)
    return ax


def draw_shape(ax, shape, color="k", lw=0.3, marker=None, line_lw=1.2):
    """A solid's `Shape` (`SolidKind.shape`): its cells outlined with width lw (a PolyCollection)
    or its centre line with width line_lw (a Line2D, with `marker` at the nodes)."""
    from matplotlib.collections import PolyCollection

    if shape.polygons is not None:
        artist = PolyCollection(shape.polygons, facecolors="none", edgecolors=color, linewidths=lw)
        ax.add_collection(artist)
        ax.autoscale_view()
    else:
        (artist,) = ax.plot(shape.line[:, 0], shape.line[:, 1], color=color, lw=line_lw, marker=marker, ms=3)
    ax.set_aspect("equal")
    return artist


def draw_patches(ax, patches, cmap="viridis", norm=None):
    """A solid's `Patches` (`SolidKind.energy_cells`) coloured by their values: a PolyCollection."""
    from matplotlib.collections import PolyCollection

    pc = PolyCollection(patches.polygons, cmap=cmap, norm=norm, edgecolors="none", linewidths=0)
    pc.set_array(np.asarray(patches.values))
    ax.add_collection(pc)
    ax.autoscale_view()
    ax.set_aspect("equal")
    return pc


def plot_modes(model, modes, kinds, which=(0, 3, 6), output="modes.png"):
    """Fig. 6: the undeformed mesh and the shapes of the selected modes with their periods."""
    n = len(which) + 1
    fig, axes = plt.subplots(1, n, figsize=(2.2 * n, 7.5), sharey=True)
    kind = kind_of(model)
    draw_shape(axes[0], kind.shape(model), lw=0.25, marker=".")
    axes[0].set_title(f"(a) {model.kind} mesh\n{model.info['elements']} elements, {model.ndof} DOFs", fontsize=9)
    width = np.ptp(model.nodes[:, 0]) or 0.01
    for ax, k, letter in zip(axes[1:], which, "bcdefgh"):
        d = model.full_displacement(modes.shapes[:, k])
        scale = 0.25 * width / np.abs(d).max()
        draw_shape(ax, kind.shape(model), color="0.75", lw=0.15)
        draw_shape(ax, kind.shape(model, d, scale), color="C0", lw=0.3, marker=".")
        ax.set_title(f"({letter}) mode {k + 1}: {kinds[k]}\nT = {modes.periods[k] * 1e3:.4g} ms", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    axes[0].set_ylabel("y [m]")
    fig.tight_layout()
    return save(fig, output)
