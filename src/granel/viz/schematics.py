"""Schematics of the paper's Figs. 1(b)-(c) and 2 (Wang, Tawfick & Vakakis, Phys. Rev. E 104,
044906 (2021)), drawn in millimetres from the model objects (`fig1_geometry`, `fig2_meshes`).
Every artist that carries meaning has a gid ``"panel|kind|name"`` (`drawing.tagged`).
docs/analysis.md ("Figures and movies") says what each panel shows."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from .drawing import (CONTACT_COLOUR, FREE_EDGE_COLOUR, GROUND_COLOUR, LAYER_COLOUR, MEDIUM_COLOURS, MM,  # noqa: E402
                      SHOCK_COLOUR, SOLID_COLOUR, SWAPPED_COLOUR, _clean, _element_polygons, _tag, draw_arrow,
                      draw_dimension, draw_granules, draw_ground, draw_shock, draw_solid, draw_walls)
from .model_geometry import (_contact, _require_solid, _solid_model, _system, central_contact,  # noqa: E402
                             rigid_layer, solid_box, swapped_shock, touching_partner, unit_normal_tangent)


# ------------------------------------------------------------------ Fig. 1


def _panel_planar(ax, sc, system, model, swapped, zoom_box):
    """Fig. 1(a) here (the paper's Fig. 1(b)): the planar model with boundary conditions."""
    panel = "a"
    x0, y0, x1, y1 = solid_box(model)
    depth = draw_solid(ax, sc, model, panel)
    draw_walls(ax, system, panel, depth)
    draw_granules(ax, system, panel)
    xm = 0.5 * (x0 + x1) * MM
    ax.text((0.7 * x0 + 0.3 * x1) * MM, (0.62 * y0 + 0.38 * y1) * MM, f"elastic solid ({model.kind})", rotation=90,
            ha="center", va="bottom", fontsize=7, bbox=dict(fc=SOLID_COLOUR, ec="none", pad=0.5))
    for c in system.solid_contacts:
        (ln,) = ax.plot(*(np.asarray(c.point) * MM), "o", ms=3.5, color=CONTACT_COLOUR, mec="k", mew=0.4, zorder=5)
        _tag(ln, panel, "solid-contact", c.name)
    for e in system.excitations:
        draw_shock(ax, system, e, SHOCK_COLOUR, panel)
    if swapped is not None:
        draw_shock(ax, system, swapped[1], SWAPPED_COLOUR, panel, ls="--")
    for m in system.media:
        members = system.medium_members(m)
        top = max([max(w.p0[1], w.p1[1]) for w in system.walls if w.medium == m] or [system.pos0[members, 1].max()])
        xc = system.pos0[members, 0].mean() * MM
        R = system.radius[members].max() * MM
        ax.text(xc, top * MM + 3.2 * depth, f"{m}  (R = {R:g} mm)", ha="center", va="bottom", fontsize=9,
                fontweight="bold")
    for side, ypos in (("bottom", y0), ("top", y1)):
        if sc.solid.clamped[0 if side == "bottom" else 1]:
            ax.text(xm, ypos * MM + (-1.6 if side == "bottom" else 1.6) * depth, "clamped", ha="center",
                    va="top" if side == "bottom" else "bottom", fontsize=7)
    zx0, zy0, zx1, zy1 = np.asarray(zoom_box) * MM
    ax.add_patch(_tag(Rectangle((zx0, zy0), zx1 - zx0, zy1 - zy0, fc="none", ec="k", lw=0.7, ls=":"),
                      panel, "zoom", "b"))
    ax.text(zx0, zy1, "(b)", fontsize=7, ha="left", va="bottom")
    handles = [
        Line2D([], [], color=FREE_EDGE_COLOUR, lw=1.6, ls=(0, (4, 2)), label="free edge of the solid"),
        Line2D([], [], ls="none", marker="o", ms=4, color=CONTACT_COLOUR, mec="k", mew=0.4,
               label="granule-solid contact"),
        Line2D([], [], color=SHOCK_COLOUR, lw=2, label=f"F(t) on {system.labels[system.excitations[0].granule]}"
               if system.excitations else "F(t)"),
    ]
    if swapped is not None:
        handles.append(Line2D([], [], color=SWAPPED_COLOUR, lw=2, ls="--",
                              label=f"F(t) on {swapped[0]} (swapped case)"))
    handles.append(Rectangle((0, 0), 1, 1, fc="none", ec=GROUND_COLOUR, hatch="////", lw=0,
                             label="clamped / rigid wall"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=3, fontsize=7, frameon=False)
    _clean(ax)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title("(a) planar model and boundary conditions [cf. Fig. 1(b)]", fontsize=9)
    ax.autoscale_view()
    xl, yl = ax.get_xlim(), ax.get_ylim()
    ax.set_xlim(xl[0] - 4, xl[1] + 4)
    ax.set_ylim(yl[0] - 4, yl[1] + 4 * depth)


def _closeup_box(system, i, j, model, sc):
    """The window of Fig. 1(b) [m]: granules i and j, the whole width of the solid, and room
    below for the rigid-layer inset."""
    ij = [i, j]
    lo = (system.pos0[ij] - system.radius[ij, None]).min(axis=0)
    hi = (system.pos0[ij] + system.radius[ij, None]).max(axis=0)
    x0, _, x1, _ = solid_box(model)
    margin = 0.3 * system.radius[i]
    return (min(lo[0], x0) - margin, lo[1] - margin - 0.9 * system.radius[i],
            max(hi[0], x1) + margin, hi[1] + margin)


def _panel_contacts(ax, sc, system, model, plate, contact, box):
    """Fig. 1(b) here (the paper's Fig. 1(c)): contact points with unit normal and tangent."""
    panel = "b"
    i = contact.granule
    j = touching_partner(system, i)
    draw_solid(ax, sc, model, panel)
    draw_granules(ax, system, panel, [i, j], labels=False)
    si, sj = system.pos0[i] * MM, system.pos0[j] * MM
    Ri = system.radius[i] * MM
    for g, role, centre in ((i, "i", si), (j, "j", sj)):
        text = f"${role}$ = {system.labels[g].split(':', 1)[1]}"
        _tag(ax.text(centre[0], centre[1] + 0.3 * system.radius[g] * MM, text, ha="center", va="bottom", fontsize=10),
             panel, "granule-label", system.labels[g])
    L = 0.6 * Ri
    # granule-granule contact: n_ij from i to j, t_ij = k x n_ij
    n, t = unit_normal_tangent(sj - si)
    p = si + Ri * n
    _unit_pair(ax, p, n, t, L, "ij", f"{system.labels[i]}-{system.labels[j]}", panel)
    ax.plot(*p, "o", ms=3.5, color="k", zorder=6)
    # granule-solid contact: n_ik from the model (granule -> solid), at the contact point
    n, t = unit_normal_tangent(contact.normal)
    p = np.asarray(contact.point) * MM
    _unit_pair(ax, p, n, t, L, "ik", contact.name, panel)
    (ln,) = ax.plot(*p, "o", ms=3.5, color=CONTACT_COLOUR, mec="k", mew=0.4, zorder=6)
    _tag(ln, panel, "solid-contact", contact.name)
    # k out of the plane, at the centre of granule i
    ax.plot(*(si + np.array([0.0, -0.45 * Ri])), marker="o", ms=7, mfc="w", mec="k", mew=0.8)
    ax.plot(*(si + np.array([0.0, -0.45 * Ri])), marker=".", ms=3, color="k")
    ax.text(*(si + np.array([0.12 * Ri, -0.45 * Ri])), r"$\mathbf{k}$", fontsize=9, va="center")
    layer = rigid_layer(plate, contact.name) if plate is not None else None
    if layer is not None and layer.length > 0:
        ax.plot([layer.x * MM] * 2, [layer.y_lo * MM, layer.y_hi * MM], color=LAYER_COLOUR, lw=3,
                solid_capstyle="butt", zorder=5)
        _layer_inset(ax, sc, system, model, contact, layer, panel)
    _clean(ax)
    ax.set_xlim(box[0] * MM, box[2] * MM)
    ax.set_ylim(box[1] * MM, box[3] * MM)
    ax.set_xlabel("x [mm]")
    ax.set_title(f"(b) contacts {system.labels[i]}-{system.labels[j]} and {contact.name}-solid:\n"
                 r"unit normal $\mathbf{n}$, tangent $\mathbf{t} = \mathbf{k}\times\mathbf{n}$ [cf. Fig. 1(c)]",
                 fontsize=9)


def _unit_pair(ax, p, n, t, L, sub, name, panel):
    """Arrows n and t (length L [mm]) at the contact point p, labelled n_sub and t_sub."""
    for vec, other, sym, kind, colour in ((n, t, "n", "normal", "k"), (t, n, "t", "tangent", "#2E86C1")):
        draw_arrow(ax, p, p + L * vec, colour, panel, kind, name, lw=1.4)
        q = p + 1.12 * L * vec
        if abs(vec[0]) < 0.3:  # along y: beside the tip, away from the other arrow
            q = q - 0.1 * L * np.sign(other[0]) * np.array([1.0, 0.0])
            ha = "right" if other[0] > 0 else "left"
        else:
            ha = "left" if vec[0] > 0 else "right"
        ax.text(*q, rf"$\mathbf{{{sym}}}_{{{sub}}}$", fontsize=10, color=colour, ha=ha,
                va="bottom" if vec[1] > 0.3 else ("top" if vec[1] < -0.3 else "center"))


def _layer_inset(ax, sc, system, model, contact, layer, panel):
    """An inset zooming on the rigid layer of Fig. 1(c): length R/10 on the solid's edge."""
    g = contact.granule
    R = system.radius[g] * MM
    Lm = layer.length * MM
    c = np.array([layer.x * MM, layer.centre * MM])
    side = -np.sign(contact.normal[0])  # granule side of the edge: -1 left, +1 right
    ins = ax.inset_axes([0.03 if side < 0 else 0.55, 0.03, 0.42, 0.3])
    h = 1.4 * Lm
    ins.add_patch(Circle(system.pos0[g] * MM, R, fc=MEDIUM_COLOURS[system.medium_index[g] % 4], ec="k", lw=0.8))
    x0, y0, x1, y1 = np.array(solid_box(model)) * MM
    ins.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=SOLID_COLOUR, ec="k", lw=0.8))
    ins.plot([c[0]] * 2, [layer.y_lo * MM, layer.y_hi * MM], color=LAYER_COLOUR, lw=4, solid_capstyle="butt")
    xd = c[0] + side * 0.45 * Lm
    draw_dimension(ins, (xd, layer.y_lo * MM), (xd, layer.y_hi * MM), panel, contact.name)
    ins.text(xd + side * 0.1 * Lm, c[1], f"rigid layer\nR/10 = {Lm:.2f} mm", fontsize=6.5, va="center",
             ha="right" if side < 0 else "left")
    ins.set_xlim(c[0] - 2.4 * h if side < 0 else c[0] - h, c[0] + h if side < 0 else c[0] + 2.4 * h)
    ins.set_ylim(c[1] - h, c[1] + h)
    ins.set_aspect("equal")
    ins.set_xticks([])
    ins.set_yticks([])
    ax.indicate_inset_zoom(ins, edgecolor="0.3", lw=0.6)


def figure1(sc):
    """The paper's Fig. 1(b)-(c) as a matplotlib Figure: (a) the planar model, (b) a contact
    close-up. Granules, walls, contacts and excitations come from the scenario's models."""
    _require_solid(sc)
    system = _system(sc)
    model = _solid_model(sc, system, sc.solid.kind)
    plate = model if "rigid_layers" in model.info else _solid_model(sc, system, "plate")  # the close-up: a rigid layer
    swapped = swapped_shock(sc, system)
    fig = plt.figure(figsize=(13.0, 7.2))
    gs = fig.add_gridspec(1, 2, width_ratios=[1.45, 1.0], wspace=0.12)
    ax_a, ax_b = fig.add_subplot(gs[0]), fig.add_subplot(gs[1])
    contact = _closeup_contact(system)
    if contact is None:
        box = solid_box(model)
        _panel_planar(ax_a, sc, system, model, swapped, box)
        ax_b.set_axis_off()
        ax_b.text(0.5, 0.5, "no granule touches the solid", ha="center", transform=ax_b.transAxes)
        return fig
    i = contact.granule
    box = _closeup_box(system, i, touching_partner(system, i), model, sc)
    _panel_planar(ax_a, sc, system, model, swapped, box)
    _panel_contacts(ax_b, sc, system, model, plate, contact, box)
    return fig


def _closeup_contact(system):
    """The central solid contact of the first medium touching the solid (the paper's LSGM:12)."""
    if not system.solid_contacts:
        return None
    first = system.medium_index[system.solid_contacts[0].granule]
    cs = [c for c in system.solid_contacts if system.medium_index[c.granule] == first]
    ys = np.array([c.point[1] for c in cs])
    return cs[int(np.argmin(np.abs(ys - 0.5 * (ys.min() + ys.max()))))]


def fig1_geometry(sc, out) -> list[Path]:
    """Write the paper's Fig. 1(b)-(c) (planar model, contact close-up) to `out` as PNG and PDF."""
    from .figures import save_both

    return save_both(figure1(sc), out)


# ------------------------------------------------------------------ Fig. 2


def _panel_beam(ax, sc, system, beam):
    """Fig. 2(a): the beam's nodes on its neutral axis; the contact forces act at nodes."""
    panel = "a"
    x0, y0, x1, y1 = np.array(solid_box(beam)) * MM
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=SOLID_COLOUR, ec="0.5", lw=0.5))
    xy = beam.nodes * MM
    (ln,) = ax.plot(xy[:, 0], xy[:, 1], "-", color="k", lw=0.9)
    (nd,) = ax.plot(xy[:, 0], xy[:, 1], "o", ms=2.2, color="k")
    _tag(nd, panel, "beam-nodes")
    depth = 0.03 * (y1 - y0)
    for k, yy in ((0, y0), (1, y1)):
        if sc.solid.clamped[k]:
            draw_ground(ax, (x0, yy), (x1, yy), (0, -1 if k == 0 else 1), depth, panel, "clamp",
                        "bottom" if k == 0 else "top")
    w = x1 - x0
    for c in beam.contacts:
        node = int(np.argmin(np.abs(beam.nodes[:, 1] - c.position[1])))
        xn, yn = xy[node]
        s = np.sign(c.normal[0])  # +1: pushed from the left
        (mk,) = ax.plot(xn - s * 0.22 * w, yn, ">" if s > 0 else "<", ms=5, color=CONTACT_COLOUR, mec="k", mew=0.3)
        _tag(mk, panel, "beam-contact", c.name)
        ax.annotate("", xy=(xn - s * 0.35 * w, yn), xytext=(xn - s * 1.2 * w, yn),
                    arrowprops=dict(arrowstyle="-|>", color=CONTACT_COLOUR, lw=0.8, mutation_scale=7))
        ax.text(xn - s * 1.3 * w, yn, c.name.split(":", 1)[1], fontsize=6.5, va="center",
                ha="right" if s > 0 else "left")
    _clean(ax)
    ax.set_xlim(x0 - 1.9 * w, x1 + 1.9 * w)
    ax.set_ylim(y0 - 2 * depth, y1 + 2 * depth)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"(a) beam\n{beam.nelements} Hermite elements\n{beam.ndof} DOFs", fontsize=9)


def _panel_plate(ax, sc, system, plate):
    """Fig. 2(b): every Q8 element; the rigid layers on the edges; the clamped ends."""
    panel = "b"
    pc = PolyCollection(_element_polygons(plate), facecolors="none", edgecolors="k", linewidths=0.25)
    ax.add_collection(_tag(pc, panel, "elements"))
    x0, y0, x1, y1 = np.array(solid_box(plate)) * MM
    depth = 0.03 * (y1 - y0)
    for k, yy in ((0, y0), (1, y1)):
        if sc.solid.clamped[k]:
            draw_ground(ax, (x0, yy), (x1, yy), (0, -1 if k == 0 else 1), depth, panel, "clamp",
                        "bottom" if k == 0 else "top")
    for c in plate.contacts:
        lay = rigid_layer(plate, c.name)
        (ln,) = ax.plot([lay.x * MM] * 2, [lay.y_lo * MM, lay.y_hi * MM], color=LAYER_COLOUR, lw=3,
                        solid_capstyle="butt")
        _tag(ln, panel, "layer", c.name)
    w = x1 - x0
    _clean(ax)
    ax.set_xlim(x0 - 0.6 * w, x1 + 0.6 * w)
    ax.set_ylim(y0 - 2 * depth, y1 + 2 * depth)
    ax.set_xlabel("x [mm]")
    ax.set_title(f"(b) plate\n{plate.nelements} Q8 elements\n{plate.ndof} DOFs", fontsize=9)


def _panel_layer(ax, sc, system, plate, name, panel, letter):
    """Fig. 2(c)/(d): the elements around a contact's rigid layer, its nodes, its length, and
    the granule touching it."""
    layer = rigid_layer(plate, name)
    contact = _contact(plate, name)
    g = system.index(name)
    R = system.radius[g]
    L = layer.length if layer.length > 0 else sc.solid.mesh.layer_fraction * R
    side = -np.sign(contact.normal[0])  # granule side: -1 left of the edge, +1 right
    xlo, xhi = (layer.x - 2.6 * L, layer.x + 2.4 * L) if side < 0 else (layer.x - 2.4 * L, layer.x + 2.6 * L)
    ylo, yhi = layer.centre - 2.0 * L, layer.centre + 2.0 * L
    near = _elements_in_window(plate, (xlo, ylo, xhi, yhi))
    ax.add_collection(_tag(PolyCollection(_element_polygons(plate, near), facecolors=SOLID_COLOUR,
                                          edgecolors="k", linewidths=0.6), panel, "elements", name))
    on_layer = np.array([np.isin(e, layer.nodes).sum() >= 2 for e in plate.elements])
    ax.add_collection(_tag(PolyCollection(_element_polygons(plate, np.flatnonzero(on_layer)), facecolors="#F6D7B0",
                                          edgecolors="k", linewidths=0.9), panel, "layer-elements", name))
    used = np.unique(plate.elements[near])
    ax.plot(*(plate.nodes[used] * MM).T, "o", ms=2.5, color="0.3", zorder=4)
    ax.add_patch(_tag(Circle(system.pos0[g] * MM, R * MM, fc=MEDIUM_COLOURS[system.medium_index[g] % 4], ec="k",
                             lw=1.0, alpha=0.8), panel, "granule", name))
    ax.plot([layer.x * MM] * 2, [layer.y_lo * MM, layer.y_hi * MM], color=LAYER_COLOUR, lw=4,
            solid_capstyle="butt", zorder=5)
    (ln,) = ax.plot(*(plate.nodes[layer.nodes] * MM).T, "o", ms=6, mfc=LAYER_COLOUR, mec="k", mew=0.8, zorder=6)
    _tag(ln, panel, "layer-nodes", name)
    xd = (layer.x + side * 0.45 * L) * MM
    draw_dimension(ax, (xd, layer.y_lo * MM), (xd, layer.y_hi * MM), panel, name)
    Lmm = layer.length * MM
    _tag(ax.text(xd + side * 0.08 * L * MM, layer.centre * MM, f"rigid layer\n{Lmm:.2f} mm = R/{R / layer.length:.3g}"
                 if layer.length > 0 else "no rigid layer", fontsize=8, va="center",
                 ha="right" if side < 0 else "left", bbox=dict(fc="w", ec="none", alpha=0.75, pad=1.0)),
         panel, "layer-label", name)
    ax.text((layer.x + side * 0.9 * L) * MM, (layer.centre + 1.6 * L) * MM, name, fontsize=9, fontweight="bold",
            ha="center", va="center")
    _clean(ax)
    ax.set_xlim(xlo * MM, xhi * MM)
    ax.set_ylim(ylo * MM, yhi * MM)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    medium = name.split(":")[0]
    detail = f"{len(layer.nodes)} nodes, {int(on_layer.sum())} elements" if layer.length > 0 else "no rigid layer"
    ax.set_title(f"({letter}) rigid layer at {medium} contact {name.split(':', 1)[1]}: {detail}", fontsize=9)


def _elements_in_window(model, box) -> np.ndarray:
    """Indices of the elements with a node inside box = (x0, y0, x1, y1) [m]."""
    x0, y0, x1, y1 = box
    xy = model.nodes[model.elements]  # (ne, 8, 2)
    inside = (xy[..., 0] >= x0) & (xy[..., 0] <= x1) & (xy[..., 1] >= y0) & (xy[..., 1] <= y1)
    return np.flatnonzero(inside.any(axis=1))


def figure2(sc):
    """The paper's Fig. 2 as a matplotlib Figure: (a) beam mesh, (b) plate mesh, (c)/(d) the
    rigid layers at the central LSGM and SSGM contacts. Both solid models are built from the
    scenario, whatever its solid kind."""
    _require_solid(sc)
    system = _system(sc)
    beam = _solid_model(sc, system, "beam")
    plate = _solid_model(sc, system, "plate")
    fig = plt.figure(figsize=(12.0, 8.0))
    gs = fig.add_gridspec(2, 3, width_ratios=[0.8, 0.55, 1.25], wspace=0.22, hspace=0.32)
    _panel_beam(fig.add_subplot(gs[:, 0]), sc, system, beam)
    _panel_plate(fig.add_subplot(gs[:, 1]), sc, system, plate)
    sides = [m for m in system.media if central_contact(plate, system, m) is not None][:2]
    for row, (medium, letter) in enumerate(zip(sides, "cd")):
        _panel_layer(fig.add_subplot(gs[row, 2]), sc, system, plate, central_contact(plate, system, medium),
                     letter, letter)
    return fig


def fig2_meshes(sc, out) -> list[Path]:
    """Write the paper's Fig. 2 (beam and plate meshes, rigid layers) to `out` as PNG and PDF."""
    from .figures import save_both

    return save_both(figure2(sc), out)
