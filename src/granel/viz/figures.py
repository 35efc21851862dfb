"""The paper's figures (3-11), each a function of result Datasets that writes PNG and PDF."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from ..analysis.modal import accumulated_modal_energy, modal_coordinates, modal_energies, time_averaged_accumulation  # noqa: E402
from ..analysis.reciprocity import directed_velocity, excitation_of  # noqa: E402
from ..analysis.result_model import result_solid, result_system  # noqa: E402
from ..io.model import read_record  # noqa: E402
from ..io.results import require, require_states  # noqa: E402
from ..solid.base import Patches  # noqa: E402
from ..solid.kinds import kind_of  # noqa: E402

plt.rcParams.update({"font.size": 9, "axes.grid": True, "grid.alpha": 0.3, "savefig.dpi": 200, "figure.dpi": 100})

SIDE_NAME = {"LSGM:3": "shock on LSGM granule 3", "SSGM:C": "shock on SSGM granule C"}


def save_both(fig, path) -> list[Path]:
    """Write `path` as PNG and PDF (same stem)."""
    from ..guard.writing import save_figure

    path = Path(path)
    outs = []
    try:
        for ext in (".png", ".pdf"):
            outs.append(save_figure(fig, path.with_suffix(ext), close=False, bbox_inches="tight"))
    finally:
        plt.close(fig)
    return outs


def modal_energy_history(ds, modes=None):
    """(solid times, modal energies (nt, nm) of eq. (15), omega) of a run; a solid too large for
    all modes stores the reduced state, projected here on the modes of its model."""
    t, X, Xd, w = modal_coordinates(ds, modes, result_solid(ds) if "solid_x" in ds else None)
    return t, modal_energies(X, Xd, w), w


def solid_state_at(ds, time: float, modes=None):
    """The solid's reduced (q, v) at the stored solid time closest to `time`, and its index."""
    from ..analysis.solid import nearest_solid_outputs, reduced_states

    q, v = reduced_states(ds, [time], result_solid(ds), modes)
    return q[0], v[0], int(nearest_solid_outputs(ds, [time])[0])


def fig3_velocities(fwd, bwd, out, window=(4e-4, 8e-4)):
    """Fig. 3: (a) the shock; (b) v_3C (granule 3 when C is shocked) and v_C3; (c) their amplitude
    spectra over `window` (the text's "lower frequency content for v_3C ... especially for
    tau > 0.6 ms"), with the dominant frequencies marked."""
    from ..analysis.signals import amplitude_spectrum, spectrum_peak
    from ..granular.loads import load_history
    from ..io.model import read_record

    A, dA = excitation_of(fwd)
    B, dB = excitation_of(bwd)
    e = read_record(fwd).loads[0]
    shock = load_history(e.kind, e.params, e.times, e.values)  # the paper's: a half-sine
    fmax, tau = shock.peak(), getattr(shock, "tau", np.nan)
    fig = plt.figure(figsize=(10, 6.4), layout="constrained")
    gs = fig.add_gridspec(2, 2, width_ratios=[1, 1.6])
    ax1, ax3, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, :])
    tt = np.linspace(0, 2 * tau, 400)
    ax1.plot(tt * 1e3, np.where(tt <= tau, fmax * np.sin(np.pi * tt / tau), 0.0), "k")
    ax1.set_xlabel("time [ms]")
    ax1.set_ylabel("F [N]")
    ax1.set_title(f"(a) half-sine shock, Fmax = {fmax:g} N", fontsize=9)
    a_lab, b_lab = A.split(":")[1], B.split(":")[1]
    # the measured granules sit at the walled outer edge: plot the outward velocity
    traces = ((fwd, -directed_velocity(fwd, B, dB), f"v_{b_lab}{a_lab}: granule {B} (shock on {A})"),
              (bwd, -directed_velocity(bwd, A, dA), f"v_{a_lab}{b_lab}: granule {A} (shock on {B})"))
    for k, (ds, v, label) in enumerate(traces):
        t = ds["time"].values
        ax2.plot(t * 1e3, v, color=f"C{k}", label=label)
        f, S = amplitude_spectrum(t, v, window)
        fd = spectrum_peak(f, S)
        ax3.plot(f / 1e3, S, color=f"C{k}", label=f"{label.split(':')[0]}: dominant {fd / 1e3:.1f} kHz")
        ax3.axvline(fd / 1e3, color=f"C{k}", lw=0.8, ls=":")
    ax2.axvspan(window[0] * 1e3, window[1] * 1e3, color="0.9", zorder=0, label="window of (c)")
    ax2.set_xlabel("time [ms]")
    ax2.set_ylabel("outward velocity [m/s]")
    ax2.set_title(f"(b) swapped excitation and measurement ({fwd.attrs.get('solid_kind', '')})", fontsize=9)
    ax2.legend(fontsize=8)
    ax3.set_xlim(0, 50)
    ax3.set_xlabel("frequency [kHz]")
    ax3.set_ylabel("amplitude [m/s]")
    ax3.set_title(f"(c) spectra over {window[0] * 1e3:g}-{window[1] * 1e3:g} ms (Hann window)", fontsize=9)
    ax3.legend(fontsize=8)
    return save_both(fig, out)


def _energy_curves(ds):
    w = float(ds["input_work"].values.max())
    t = ds["time"].values * 1e3
    el, es, eso = (ds[k].values / w for k in ("energy_lsgm", "energy_ssgm", "energy_solid"))
    d = (ds["dissipated_viscous"].values + ds["dissipated_friction"].values) / w
    return t, {"LSGM": el, "SSGM": es, "solid": eso, "total": el + es + eso, "total + dissipated": el + es + eso + d}


def fig4_energies(runs: dict, out):
    """Fig. 4: normalised energies, rows weak / moderate / strong, columns LSGM / SSGM shock;
    plate solid lines, beam dashed."""
    fig, axes = plt.subplots(3, 2, figsize=(10, 10), sharex=True)
    colors = {"LSGM": "C0", "SSGM": "C1", "solid": "C2", "total": "C3", "total + dissipated": "k"}
    letters = iter("abcdef")
    for r, shock in enumerate(("weak", "moderate", "strong")):
        for c, exc in enumerate(("LSGM:3", "SSGM:C")):
            ax = axes[r, c]
            for solid, ls in (("plate", "-"), ("beam", "--")):
                ds = runs.get((solid, exc, shock))
                if ds is None:
                    continue
                t, curves = _energy_curves(ds)
                for name, y in curves.items():
                    ax.plot(t, 100 * y, ls, color=colors[name], lw=1.1, label=f"{name} ({solid})" if (r, c) == (0, 0) else None)
            ax.set_title(f"({next(letters)}) {shock}, {SIDE_NAME[exc]}", fontsize=9)
            ax.set_ylim(-2, 105)
            if c == 0:
                ax.set_ylabel("energy / input [%]")
            if r == 2:
                ax.set_xlabel("time [ms]")
    axes[0, 0].legend(fontsize=7, ncol=2)
    _fig4_inset(axes[2, 1], runs, colors["solid"])
    fig.tight_layout()
    return save_both(fig, out)


def _fig4_inset(ax, runs, color, tmax=0.2):
    """The inset of Fig. 4(f): the solid's energy, plate vs beam, strong shock on the SSGM,
    over the primary wave (0 to `tmax` ms)."""
    pair = [(runs.get((solid, "SSGM:C", "strong")), ls) for solid, ls in (("plate", "-"), ("beam", "--"))]
    if any(ds is None for ds, _ in pair):
        return None
    ins = ax.inset_axes([0.5, 0.38, 0.47, 0.5])
    top = 0.0
    for ds, ls in pair:
        t, curves = _energy_curves(ds)
        sel = t <= tmax
        ins.plot(t[sel], 100 * curves["solid"][sel], ls, color=color, lw=1.0)
        top = max(top, 100 * curves["solid"][sel].max())
    ins.set_xlim(0, tmax)
    ins.set_xticks([0, tmax / 2, tmax])
    ins.set_ylim(0, 1.15 * top if top > 0 else 1)
    ins.set_title("solid: plate (-) vs beam (--)", fontsize=7)
    ins.tick_params(labelsize=6)
    return ins


def granule_energies_at(ds, k: int, su=None):
    """Per-granule energy (kinetic + rotational + contact share) at output index k, with the
    solid contact points displaced by su (nc, 2): `analysis.density.granule_energies` for one frame."""
    from ..analysis.density import granule_energies, granule_states

    system = result_system(ds)
    return granule_energies(system, granule_states(ds, [k]), None if su is None else su[None])[0], system


def draw_energy_density(ax, ds, time: float, norm=None, cmap="inferno", modes=None):
    """Granules and the solid coloured by the normalised energy density (14) at `time`."""
    from ..analysis.density import excited_reference, granule_energy_density
    from .plots import draw_patches

    system, model = result_system(ds), result_solid(ds)
    w0 = excited_reference(ds)
    k = int(np.argmin(np.abs(ds["time"].values - time)))
    q, v, _ = solid_state_at(ds, ds["time"].values[k], modes)
    su = (model.contact_map() @ q).reshape(-1, 2)
    e, _ = granule_energies_at(ds, k, su)
    wg = granule_energy_density(system, e, system.radius) / w0
    norm = norm or LogNorm(1e-6, 1.0)
    require_states(ds, "the energy density figure")
    patches = [Circle((x, y), r) for x, y, r in zip(ds["x"].values[k], ds["y"].values[k], system.radius)]
    pc = PatchCollection(patches, cmap=cmap, norm=norm, edgecolor="0.5", linewidth=0.3)
    pc.set_array(np.clip(wg, norm.vmin, None))
    ax.add_collection(pc)
    cells = kind_of(model).energy_cells(model, q, v)
    draw_patches(ax, Patches(cells.polygons, np.clip(cells.values / w0, norm.vmin, None)), cmap, norm)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xticks([])
    ax.set_yticks([])
    return pc


def snapshot_time(ds) -> float:
    """The output time at which the solid's energy is largest: Fig. 5's snapshot instant ("when
    the energy density in the elastic solid reaches its maximum")."""
    return float(ds["time"].values[int(np.argmax(ds["energy_solid"].values))])


def system_extent(ds, margin=0.15):
    """(xlim, ylim) holding every granule, wall and the solid of a run, with a margin relative to
    the largest radius: one frame for every panel of a figure."""
    rec = read_record(ds)
    x, y, r = rec.position0[:, 0], rec.position0[:, 1], rec.radius
    xs = [x.min() - r.max(), x.max() + r.max()] + [p for w in rec.walls for p in (w.p0[0], w.p1[0])]
    ys = [y.min() - r.max(), y.max() + r.max()] + [p for w in rec.walls for p in (w.p0[1], w.p1[1])]
    if rec.nodes is not None:
        xs += [rec.nodes[:, 0].min(), rec.nodes[:, 0].max()]
        ys += [rec.nodes[:, 1].min(), rec.nodes[:, 1].max()]
    pad = margin * r.max()
    return (min(xs) - pad, max(xs) + pad), (min(ys) - pad, max(ys) + pad)


def fig5_energy_density(runs: dict, out):
    """Fig. 5: normalised energy density (14), strong shocks: (a, b) shock on the LSGM, plate and
    beam; (c, d) shock on the SSGM. Each side is drawn at the instant of the plate's largest
    solid energy (computed, printed in each title); the beam panel at the same instant, as in the
    paper. One colour scale and one frame for all four panels."""
    panels = [("plate", "LSGM:3", "a"), ("beam", "LSGM:3", "b"), ("plate", "SSGM:C", "c"), ("beam", "SSGM:C", "d")]
    present = [runs.get((solid, exc, "strong")) for solid, exc, _ in panels]
    ref = next((ds for ds in present if ds is not None), None)
    if ref is None:
        raise ValueError("Fig. 5 needs at least one strong-shock run")
    xlim, ylim = system_extent(ref)
    times = {}
    for exc in ("LSGM:3", "SSGM:C"):
        ds = runs.get(("plate", exc, "strong")) or runs.get(("beam", exc, "strong"))
        if ds is not None:
            times[exc] = snapshot_time(ds)
    fig = plt.figure(figsize=(12, 4.4))
    gs = fig.add_gridspec(1, 5, width_ratios=[1, 1, 1, 1, 0.06], wspace=0.08)
    norm = LogNorm(1e-6, 1.0)
    for k, ((solid, exc, letter), ds) in enumerate(zip(panels, present)):
        ax = fig.add_subplot(gs[0, k])
        if ds is None:
            ax.set_visible(False)
            continue
        t = times[exc]
        draw_energy_density(ax, ds, t, norm=norm)
        draw_walls(ax, ds)
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
        ax.set_title(f"({letter}) {solid}, shock on {exc}\nt = {t * 1e3:.3f} ms (plate's energy maximum)", fontsize=8)
    from matplotlib.cm import ScalarMappable

    fig.colorbar(ScalarMappable(norm=norm, cmap="inferno"), cax=fig.add_subplot(gs[0, 4]),
                 label="normalised energy density w / w0, eq. (14)")
    return save_both(fig, out)


def draw_walls(ax, ds, color="k", lw=2.0):
    """The rigid walls of a run's granular media."""
    for w in read_record(ds).walls:
        ax.plot([w.p0[0], w.p1[0]], [w.p0[1], w.p1[1]], color=color, lw=lw, solid_capstyle="butt")


def _energy_panel_labels(ax, title):
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("time [ms]")
    ax.set_ylabel("energy / input [%]")
    ax.legend(fontsize=8)


def fig7_modal_accumulation(runs: dict, out, counts=(6, 100, 1000), modes=None):
    """Fig. 7: accumulated modal energy of the leading 6, 100, 1000 plate modes vs time, strong."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for ax, exc, letter in zip(axes, ("LSGM:3", "SSGM:C"), "ab"):
        ds = runs.get(("plate", exc, "strong"))
        if ds is None:
            continue
        t, E, _ = modal_energy_history(ds, modes)
        win = float(ds["input_work"].values.max())
        ax.plot(t * 1e3, 100 * E.sum(axis=1) / win, "k", lw=1.5, label="total")
        for n, y in accumulated_modal_energy(E, counts).items():
            ax.plot(t * 1e3, 100 * y / win, label=f"{n} modes")
        _energy_panel_labels(ax, f"({letter}) plate, strong, {SIDE_NAME[exc]}")
    fig.tight_layout()
    return save_both(fig, out)


def fig8_solid_partition(runs: dict, out):
    """Fig. 8: kinetic, potential and total energy of the plate, strong shock, both sides."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for ax, exc, letter in zip(axes, ("LSGM:3", "SSGM:C"), "ab"):
        ds = runs.get(("plate", exc, "strong"))
        if ds is None:
            continue
        w = float(ds["input_work"].values.max())
        t = ds["time"].values * 1e3
        ax.plot(t, 100 * ds["energy_solid"].values / w, "k", label="total")
        ax.plot(t, 100 * ds["energy_solid_potential"].values / w, "C0", label="potential (elastic)")
        ax.plot(t, 100 * ds["energy_solid_kinetic"].values / w, "C3", label="kinetic")
        _energy_panel_labels(ax, f"({letter}) plate, strong, {SIDE_NAME[exc]}")
    fig.tight_layout()
    return save_both(fig, out)


def time_averaged(ds, modes=None):
    t, E, _ = modal_energy_history(ds, modes)
    return time_averaged_accumulation(E, t)


def fig9_time_averaged(runs: dict, out, nmax=1000):
    """Fig. 9: time-averaged accumulated modal energy (16) vs N, 12 cases."""
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.5), sharey=True)
    for ax, shock, letter in zip(axes, ("weak", "moderate", "strong"), "abc"):
        for solid, ls in (("plate", "-"), ("beam", "--")):
            for exc, color in (("LSGM:3", "C0"), ("SSGM:C", "C3")):
                ds = runs.get((solid, exc, shock))
                if ds is None:
                    continue
                acc = time_averaged(ds)[:nmax]
                ax.semilogx(np.arange(1, len(acc) + 1), acc, ls, color=color, label=f"{solid}, {exc}")
        ax.set_title(f"({letter}) {shock}", fontsize=9)
        ax.set_xlabel("number of modes N")
        ax.set_ylim(0, 1.02)
    axes[0].set_ylabel("time-averaged energy fraction, eq. (16)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return save_both(fig, out)


def fig10_friction_law(out, mu=0.099, k_s=100.0, N=1.0):
    """Fig. 10: the tanh-Coulomb law (5) and discontinuous Coulomb friction."""
    v = np.linspace(-0.1, 0.1, 801)
    fig, axes = plt.subplots(1, 2, figsize=(8, 3), sharey=True)
    axes[0].plot(v, -mu * N * np.tanh(k_s * v))
    axes[0].set_title(f"(a) tanh-Coulomb, k_s = {k_s:g} s/m", fontsize=9)
    axes[1].plot(v, -mu * N * np.sign(v))
    axes[1].set_title("(b) Coulomb", fontsize=9)
    for ax in axes:
        ax.set_xlabel("relative tangential velocity [m/s]")
    axes[0].set_ylabel("f / |N|")
    fig.tight_layout()
    return save_both(fig, out)


def fig11_eigenvalues(ds, out, tmax=2e-4, source="", left=("LSGM:10", "LSGM:11", "LSGM:12"), right=("SSGM:J", "SSGM:K", "SSGM:L")):
    """Fig. 11: |lambda| (A9) at the six tracked contacts, strong shock on C, plate, from a run of
    the paper's algorithm: at every accepted step, the values at the common step that (B1) chose
    for all contacts. `source` says where the run came from (printed under the title)."""
    if ds.attrs.get("solver_name") != "paper":
        raise ValueError("Fig. 11 needs a run of the paper's algorithm (simulation.solver = \"paper\")")
    require(ds, ["step_time", "step_lambda"], "Fig. 11")
    t = ds["step_time"].values
    lam = ds["step_lambda"].values
    names = list(ds["contact"].values)
    sel = t <= tmax * (1 + 1e-9)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for ax, group, letter, side in zip(axes, (left, right), "ab", ("left", "right")):
        for name in group:
            if name in names:
                ax.plot(t[sel] * 1e3, lam[sel, names.index(name)], lw=0.6, label=f"lambda_{name.split(':')[1]}")
        ax.axhline(0.5, color="0.4", lw=0.8, ls="--")
        ax.set_title(f"({letter}) contacts on the {side} edge of the plate", fontsize=9)
        ax.set_xlabel("time [ms]")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("|lambda| (A9)")
    axes[0].set_ylim(0, 1.0)
    fig.suptitle(f"paper's algorithm (A1-A9, B1): {int(sel.sum())} steps over 0-{tmax * 1e3:g} ms, smallest "
                 f"{ds['step_dt'].values[sel].min():.3g} s" + (f"; {source}" if source else ""), fontsize=8)
    fig.tight_layout()
    return save_both(fig, out)
