"""What a spectrum leaves for a reader: its figure (`plot_spectrum`), its report
(`spectrum_report`, with the bands' table `band_report`), and the three files written side by
side (`write_spectrum`). The measures are `spectrum`'s."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import xarray as xr

from .spectrum import BAND_MEASURES, SpectrumSpec, curves_selection, resolved, spectrum_dataset


def plot_spectrum(ds: xr.Dataset, output):
    """Four panels over drive frequency, one colour per amplitude, forward solid and backward
    dashed: the transmissibility |V_B| / |V_A| and the mobility |V_B| / F, with the linearised
    chain's (black) and the infinite chain's band edges (grey) when there is a chain; the nonreciprocity
    [dB] (open symbols where a mobility is 60 dB below its peak, `resolved`); and, with several
    amplitudes, its map over frequency x amplitude. Any other sweep axis at its first value."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..viz.plots import save

    sub, rest = curves_selection(ds)
    f = sub["frequency"].values / 1e3
    amps = sub["amplitude"].values if "amplitude" in sub.dims else [None]
    has_map = "nonreciprocity_db" in sub and "amplitude" in sub.dims and len(amps) > 1
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), squeeze=False)
    (ax_t, ax_m), (ax_n, ax_map) = axes
    colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(amps)))
    for c, a in zip(colors, amps):
        one = sub.sel(amplitude=a) if a is not None else sub
        for d, style in zip(one["direction"].values, ("-", "--")):
            label = f"{a:g} N, {d}" if a is not None else d
            ax_t.plot(f, one["transmissibility"].sel(direction=d).values, style, color=c, marker="o", ms=3, label=label)
            ax_m.plot(f, one["mobility"].sel(direction=d).values, style, color=c, marker="o", ms=3, label=label)
        if "nonreciprocity_db" in one:
            nr, ok = one["nonreciprocity_db"].values, resolved(one)
            ax_n.plot(f, np.where(ok, nr, np.nan), "-o", color=c, ms=3, label=f"{a:g} N" if a is not None else None)
            ax_n.plot(f[~ok], nr[~ok], "o", mfc="none", color=c, ms=3)
    if "transmissibility_linear" in sub:  # the linearised chain, at the same frequencies
        for ax, name in ((ax_t, "transmissibility"), (ax_m, "mobility")):
            measured = sub[name].values[np.isfinite(sub[name].values) & (sub[name].values > 0)]
            for d, style in zip(sub["direction"].values, ("-", "--")):  # a wide grey band under the measured curves
                ax.plot(f, sub[f"{name}_linear"].sel(direction=d).values, style, color="0.4", lw=4, alpha=0.35,
                        zorder=0, label=f"linearised chain, {d}")
            if measured.size:  # the linear chain's stop band falls far below any run's floor: keep the runs in view
                ax.set_ylim(bottom=measured.min() / 10, top=measured.max() * 10)
    if "band_edge_hz" in sub:
        for ax in (ax_t, ax_m):
            for k, (name, edge) in enumerate(zip(sub["band_edge"].values, sub["band_edge_hz"].values)):
                ax.axvline(edge / 1e3, color="0.5", lw=0.8, ls="--",
                           label="infinite chain's band edges" if not k else None)
    route = f"fwd: {ds.attrs.get('drive')} -> {ds.attrs.get('measure')}"
    ax_t.set_ylabel("transmissibility |V_measured| / |V_driven|")
    ax_t.set_title(route, fontsize=9)
    ax_m.set_ylabel("mobility |V_measured| / F [m/(N s)]")
    ax_m.set_title(route, fontsize=9)
    for ax in (ax_t, ax_m):
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    ax_n.axhline(0.0, color="0.6", lw=0.8)
    ax_n.set_ylabel("nonreciprocity 20 log10(mobility fwd / bwd) [dB]")
    ax_n.set_title("open symbols: a mobility 60 dB below its peak (deep stop band)", fontsize=8)
    if "nonreciprocity_db" in sub and (len(amps) > 1 or amps[0] is not None):
        ax_n.legend(fontsize=7)
    wide = f.max() > 5 * f.min()  # a log frequency axis over wide ranges only
    for ax in (ax_t, ax_m, ax_n, ax_map):
        ax.set_xlabel("drive frequency [kHz]")
        ax.set_xscale("log" if wide else "linear")
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    if has_map:
        vals = np.array([np.where(resolved(sub.sel(amplitude=a)), sub["nonreciprocity_db"].sel(amplitude=a).values, np.nan)
                         for a in amps])  # blank where a mobility is at its floor
        top = np.nanmax(np.abs(vals)) if np.isfinite(vals).any() else 1.0
        m = ax_map.pcolormesh(f, amps, vals, shading="nearest", cmap="RdBu_r", vmin=-top, vmax=top)
        if max(amps) > 5 * min(amps):
            ax_map.set_yscale("log")
        ax_map.set_yticks(amps, [f"{a:g}" for a in amps])
        ax_map.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax_map.set_ylabel("drive amplitude [N]")
        fig.colorbar(m, ax=ax_map, label="nonreciprocity [dB] (blank: stop band)")
    else:
        ax_map.set_visible(False)
    if rest:
        fig.suptitle(", ".join(f"{k} = {ds[k].values[0]}" for k in rest), fontsize=9)
    fig.tight_layout()
    return save(fig, output)


def spectrum_report(ds: xr.Dataset) -> str:
    """A short Markdown report: what was driven and measured, and per amplitude the strongest
    nonreciprocity, the band where the forward mobility stays within 20 dB of its peak, and how
    many runs were steady or failed."""
    sub, rest = curves_selection(ds)
    f = sub["frequency"].values
    lines = [f"# Spectrum: {ds.attrs.get('name', '')}", "",
             f"Drive {ds.attrs.get('drive')} (fwd) and {ds.attrs.get('measure')} (bwd), harmonic force, "
             f"{len(f)} frequencies from {f.min() / 1e3:.3g} to {f.max() / 1e3:.3g} kHz.", ""]
    if rest:
        lines += [f"Other axes at their first value: {', '.join(f'{k} = {ds[k].values[0]}' for k in rest)}.", ""]
    lines += ["| amplitude [N] | strongest nonreciprocity [dB] (mobilities within 60 dB of peak) | at [kHz] | fwd pass band (within 20 dB of peak) [kHz] "
              "| steady runs | failed cases |", "|---|---|---|---|---|---|"]
    amps = sub["amplitude"].values if "amplitude" in sub.dims else [None]
    for a in amps:
        one = sub.sel(amplitude=a) if a is not None else sub
        nr = one["nonreciprocity_db"].values if "nonreciprocity_db" in one else np.full(len(f), np.nan)
        nr = np.where(resolved(one), nr, np.nan)
        if np.isfinite(nr).any():
            k = int(np.nanargmax(np.abs(nr)))
            strongest, at = f"{nr[k]:+.2f}", f"{f[k] / 1e3:.3g}"
        else:
            strongest, at = "n/a", "n/a"
        mob = one["mobility"].sel(direction="fwd").values
        band = "n/a"
        if np.isfinite(mob).any() and np.nanmax(mob) > 0:
            ok = f[mob >= np.nanmax(mob) * 0.1]
            band = f"{ok.min() / 1e3:.3g} - {ok.max() / 1e3:.3g}"
        steady = one["steady"].values
        failed = int(np.sum(one["status"].values != "ok")) if "status" in one else 0
        lines.append(f"| {a if a is None else f'{a:g}'} | {strongest} | {at} | {band} | "
                     f"{int(np.nansum(steady))} of {steady.size} | {failed} |")
    bal = np.nanmax(ds["balance"].values) if np.isfinite(ds["balance"].values).any() else float("nan")
    lines += ["", f"Largest energy-balance error (13) of any run, over its input work: {bal:.2e}.", "",
              "Mobility |V(f)| / F: the measured granule's velocity amplitude at the drive frequency, along its own "
              "drive direction, per newton of drive. A linear reciprocal system has equal mobilities both ways "
              "(0 dB). A run is steady when its last periods repeat within 2 %."]
    return "\n".join(lines + band_report(ds)) + "\n"


# the rows of the band measures' table: (measure, label of a monatomic chain's, of a diatomic
# chain's, the infinite chain's edge it stands beside, or None)
BAND_ROWS = [("passband_db", "pass band level [dB]", "acoustic band level [dB]", None),
             ("cutoff_hz", "cut-off, 3 dB below it [kHz]", "acoustic band top, 3 dB below it [kHz]", 0),
             ("db20_hz", "20 dB point [kHz]", "20 dB point of the acoustic band [kHz]", None),
             ("optical_bottom_hz", None, "optical band bottom [kHz]", 1),
             ("optical_top_hz", None, "optical band top [kHz]", 2),
             ("gap_attenuation_db", None, "gap's mean attenuation [dB]", None),
             ("wall_force_db", "wall force over drive, mean over the pass band [dB]",
              "wall force over drive, mean over the acoustic band [dB]", None)]


def band_report(ds: xr.Dataset) -> list[str]:
    """The report's lines on the band measures (`add_bands`): per direction, each measured one
    per amplitude beside the linearised chain's and the infinite chain's, and the grid step
    where the linearised chain's edge lies (the resolution of a measured edge)."""
    if "cutoff_hz" not in ds:
        return []
    f = np.sort(ds["frequency"].values)
    diatomic = "band_edge" in ds.coords and ds.sizes["band_edge"] == 3
    amps = list(ds["amplitude"].values) if "amplitude" in ds["cutoff_hz"].dims else [None]
    lines = ["", "## Band measures", "",
             f"Linearised chain: {ds.attrs['chain']}." if "chain" in ds.attrs else
             f"No linearised chain: {ds.attrs.get('chain_note', '')}.",
             "", "From the transmissibility |V_measured| / |V_driven| over frequency (docs/narrowband.md, \"Band "
             "measures\"): the pass band runs up to the first frequency more than 20 dB below the mean (in dB) of "
             "those below it, still falling; its level is that mean; an edge lies 3 dB below a band's level, the "
             "20 dB point 20 dB below it. Measured edges are interpolated between the frequencies run; the "
             "linearised chain's (its exact response, the same definitions on the same frequencies) are exact, "
             "the grid step there is the resolution.", ""]
    head = "| measure | direction | " + " | ".join(f"{a:g} N" if a is not None else "measured" for a in amps)
    lines += [head + " | linearised chain | infinite chain | grid step there [kHz] |",
              "|" + "---|" * (len(amps) + 5)]

    def cell(v, unit):
        return "n/a" if not np.isfinite(v) else (f"{v / 1e3:.4g}" if unit == "Hz" else f"{v:.2f}")

    for name, mono, dia, edge in BAND_ROWS:
        label = dia if diatomic else mono
        if label is None:
            continue
        unit = BAND_MEASURES[name]
        for d in ds["direction"].values:
            got = [float(ds[name].sel(direction=d, amplitude=a)) if a is not None else float(ds[name].sel(direction=d))
                   for a in amps]
            lin = float(ds[f"{name}_linear"].sel(direction=d)) if f"{name}_linear" in ds else math.nan
            inf = float(ds["band_edge_hz"].values[edge]) if edge is not None and "band_edge_hz" in ds else math.nan
            step = "n/a"
            if unit == "Hz" and np.isfinite(lin) and f[0] < lin < f[-1]:
                k = int(np.searchsorted(f, lin))
                step = f"{(f[k] - f[k - 1]) / 1e3:.3g}"
            lines.append(f"| {label} | {d} | " + " | ".join(cell(v, unit) for v in got) +
                         f" | {cell(lin, unit)} | {cell(inf, unit)} | {step} |")
    return lines


def write_spectrum(summary: xr.Dataset, spec: SpectrumSpec, path, chain=None, note: str = "") -> xr.Dataset:
    """A spectrum sweep's outputs beside each other, each written atomically: PATH (.nc, the
    `spectrum_dataset` with the runs' linearised `chain`, if any), its figure (.png) and its
    report (.md). Returns the Dataset."""
    from ..guard.owners import text_mark
    from ..guard.writing import write_text
    from ..io.results import write_netcdf

    path = Path(path)
    ds = spectrum_dataset(summary, spec, chain, note)
    write_netcdf(ds, path)
    plot_spectrum(ds, path.with_suffix(".png"))
    write_text(path.with_suffix(".md"), text_mark("<!--") + "\n" + spectrum_report(ds))
    return ds
