"""Figures (matplotlib, Agg backend): geometry now; the paper's figures build on these helpers."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from ..scenario.build import built_models  # noqa: E402

Q8_OUTLINE = [0, 4, 1, 5, 2, 6, 3, 7]  # corner, mid-side, corner, ... around a Q8 element


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
    if sc.solid is not None and sc.solid.kind != "none":
        s = sc.solid
        ax.add_patch(Rectangle((s.x0, s.y0), s.width, s.length, fc="#BBBBBB", ec="k", lw=0.8, hatch="//" if s.kind == "rigid" else None))
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


def _element_outlines(model, disp=None, scale=0.0):
    """Polygons (one per element) through the Q8 corner and mid-side nodes."""
    xy = model.nodes + (scale * disp if disp is not None else 0.0)
    return [xy[e[Q8_OUTLINE]] for e in model.elements]


def draw_plate(ax, model, disp=None, scale=0.0, color="k", lw=0.3, field=None, cmap="viridis", vmin=None, vmax=None):
    from matplotlib.collections import PolyCollection

    polys = _element_outlines(model, disp, scale)
    pc = PolyCollection(polys, facecolors="none" if field is None else None, edgecolors=color, linewidths=lw)
    if field is not None:
        pc.set_array(np.asarray(field))
        pc.set_cmap(cmap)
        pc.set_clim(vmin, vmax)
    ax.add_collection(pc)
    ax.autoscale_view()
    ax.set_aspect("equal")
    return pc


def plot_modes(model, modes, kinds, which=(0, 3, 6), output="modes.png"):
    """Fig. 6: the undeformed mesh and the shapes of the selected modes with their periods."""
    n = len(which) + 1
    fig, axes = plt.subplots(1, n, figsize=(2.2 * n, 7.5), sharey=True)
    if model.kind == "plate":
        draw_plate(axes[0], model, lw=0.25)
        axes[0].set_title(f"(a) mesh\n{model.info['elements']} elements, {model.ndof} DOFs", fontsize=9)
    else:
        axes[0].plot(model.nodes[:, 0], model.nodes[:, 1], "k.-", ms=3)
        axes[0].set_title(f"(a) beam\n{model.info['elements']} elements, {model.ndof} DOFs", fontsize=9)
    width = np.ptp(model.nodes[:, 0]) or 0.01
    for ax, k, letter in zip(axes[1:], which, "bcdefgh"):
        d = model.full_displacement(modes.shapes[:, k])
        scale = 0.25 * width / np.abs(d).max()
        if model.kind == "plate":
            draw_plate(ax, model, lw=0.15, color="0.75")
            draw_plate(ax, model, d, scale, color="C0", lw=0.3)
        else:
            ax.plot(model.nodes[:, 0], model.nodes[:, 1], color="0.75")
            ax.plot(model.nodes[:, 0] + scale * d[:, 0], model.nodes[:, 1], "C0.-", ms=3)
        ax.set_title(f"({letter}) mode {k + 1}: {kinds[k]}\nT = {modes.periods[k] * 1e3:.4g} ms", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    axes[0].set_ylabel("y [m]")
    fig.tight_layout()
    return save(fig, output)
