"""Pictures of a solid's wavefield (`analysis.wavefield.Wavefield`): E(k, t) over wavenumber and
time, the frequency-wavenumber map with the analytic branches and its ridges, the spectrum's
centroid, variance (with its fitted growth law) and entropy over time, snapshots of the
band-filtered fields, and the frames of their movie. Each function returns a matplotlib figure
(or frames); the caller saves it (`guard.writing.save_figure`, `viz.encoding.write_movie`)."""

from __future__ import annotations

from collections.abc import Iterator

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..analysis.wavefield import Wavefield, band_field  # noqa: E402

DYNAMIC_RANGE = 1e-5  # the colour scales' floor, relative to the largest value (log scales)
BRANCH_STYLE = {"S": dict(color="white", ls="--", lw=0.9), "A": dict(color="tab:red", ls="--", lw=0.9),
                "E": dict(color="white", ls="--", lw=0.9)}


def _log_image(ax, x, y, values, label: str):
    """A log-scaled image of values (len(x), len(y)) with its colour bar."""
    from matplotlib.colors import LogNorm

    top = float(np.nanmax(values)) if np.any(values > 0) else 1.0
    im = ax.pcolormesh(x, y, np.maximum(values, top * DYNAMIC_RANGE).T, shading="auto", cmap="magma",
                       norm=LogNorm(top * DYNAMIC_RANGE, top), rasterized=True)
    ax.figure.colorbar(im, ax=ax, label=label)
    return im


def kt_figure(wf: Wavefield, title: str = ""):
    """E(k, t) [J] over time [ms] and wavenumber [rad/m], with the moments' upper wavenumber and
    the elements' resolution limit, and the spectral centroid."""
    s = wf.spectrum
    fig, ax = plt.subplots(figsize=(8, 5), layout="constrained")
    top = min(s.k[-1], wf.k_plot)
    sel = s.k <= top
    _log_image(ax, s.t * 1e3, s.k[sel], s.energy[sel].T, "kinetic energy E(k, t) [J]")
    ax.plot(s.t * 1e3, wf.moments.centroid, color="cyan", lw=1.0, label="centroid")
    ax.axhline(wf.moments.k_max, color="white", ls=":", lw=1,
               label=f"moments' range: k <= {wf.moments.k_max:.0f} rad/m")
    if wf.k_resolved <= top:
        ax.axhline(wf.k_resolved, color="white", ls="--", lw=0.8, label="element resolution limit")
    ax.set(xlabel="t [ms]", ylabel="k [rad/m]", ylim=(0, top), title=title or "kinetic energy over wavenumber and time")
    ax.legend(loc="upper right", fontsize=8)
    return fig


def fk_figure(wf: Wavefield, title: str = ""):
    """The frequency-wavenumber map [kHz over rad/m] with the analytic branches (Rayleigh-Lamb S
    and A families, or Euler-Bernoulli), the ridges located, and the validated range's edges."""
    fk, b = wf.fk, wf.branches
    sel = fk.k <= wf.k_plot
    curves = b.curves()
    f_top = min(fk.f[-1], 1.2 * max(float(np.nanmax(c[b.k <= wf.k_plot])) for c in curves.values()))
    fs = fk.f <= f_top
    fig, ax = plt.subplots(figsize=(8, 6), layout="constrained")
    _log_image(ax, fk.k[sel], fk.f[fs] / 1e3, fk.power[np.ix_(sel, fs)], "power [J s]")
    for name, f in curves.items():
        ax.plot(b.k, f / 1e3, label=name, **BRANCH_STYLE.get(name[0], BRANCH_STYLE["E"]))
    r = wf.ridges
    ax.plot(r.k, r.f / 1e3, "o", ms=3, mfc="none", mec="cyan", label="ridges")
    for k in (wf.k_window, wf.k_resolved):
        if k <= wf.k_plot:
            ax.axvline(k, color="cyan", ls=":", lw=0.8)
    ax.set(xlabel="k [rad/m]", ylabel="f [kHz]", xlim=(0, wf.k_plot), ylim=(0, f_top / 1e3),
           title=title or "frequency-wavenumber map and the analytic branches")
    ax.legend(loc="upper left", fontsize=7, ncol=2)
    return fig


def moments_figure(wf: Wavefield, title: str = ""):
    """The centroid, variance (with the fitted growth law) and entropy over time of the kinetic
    energy spectrum E(k, t) and, for a modal result, of the modal energy spectrum."""
    t = wf.spectrum.t * 1e3
    fig, ax = plt.subplots(1, 3, figsize=(14, 4), layout="constrained")
    for label, m, style in (("kinetic", wf.kinetic, dict(lw=0.6, color="tab:blue")),
                            ("modal", wf.modal, dict(lw=1.4, color="tab:orange"))):
        if m is None:
            continue
        mo, g = m.moments, m.growth
        ax[0].plot(t, mo.centroid, label=label, **style)
        ax[1].plot(t, mo.variance, label=label, **style)
        if np.isfinite(g.exponent):
            tt = np.linspace(g.t0, g.t_end, 100)[1:]
            ax[1].plot(tt * 1e3, g.prefactor * (tt - g.t0) ** g.exponent, "--", color="k" if label == "modal"
                       else "tab:gray", label=f"{label} fit: exponent {g.exponent:.2f} +- {g.stderr:.2f}")
        ax[2].plot(t, mo.entropy, label=label, **style)
    ax[0].set(xlabel="t [ms]", ylabel="centroid [rad/m]")
    ax[1].set(xlabel="t [ms]", ylabel="variance [(rad/m)^2]", yscale="log")
    ax[1].axvspan(wf.growth.t0 * 1e3, wf.growth.t_end * 1e3, color="0.9", zorder=0)
    ax[2].set(xlabel="t [ms]", ylabel="entropy [nats]")
    for a in ax:
        a.legend(fontsize=7)
    fig.suptitle(title or f"moments of the spectrum over k <= {wf.moments.k_max:.0f} rad/m")
    return fig


def snapshot_times(wf: Wavefield, count: int = 4) -> np.ndarray:
    """`count` output indices spread over the record after the arrival."""
    t = wf.spectrum.t
    start = int(np.searchsorted(t, wf.arrival)) if np.isfinite(wf.arrival) else 0
    return np.unique(np.linspace(start, len(t) - 1, count + 1)[1:].round().astype(int))


def _speed(field: np.ndarray) -> np.ndarray:
    """|v| of a sampled field (..., nl, nc, N): (..., nl, N)."""
    return np.sqrt((np.asarray(field) ** 2).sum(axis=-2))


def band_speeds(wf: Wavefield, indices) -> np.ndarray:
    """The speed |v| of each band's field at the outputs `indices`, (nb, len(indices), nl, N) [m/s]."""
    return np.stack([_speed(band_field(wf.spectrum, wf.lines, lo, hi)[np.asarray(indices)]) for lo, hi in wf.bands])


def bands_figure(wf: Wavefield, indices=None, title: str = ""):
    """Snapshots of each band's field (rows) at a few times (columns): the speed |v| over the
    solid's lines (across) and its length, each band on its own colour scale."""
    idx = snapshot_times(wf) if indices is None else np.asarray(indices)
    speeds = band_speeds(wf, idx)
    nb, nt = speeds.shape[:2]
    fig, axes = plt.subplots(nb, nt, figsize=(2.2 * nt + 1, 2.6 * nb), squeeze=False, layout="constrained")
    x, y = wf.lines.x * 1e3, wf.lines.basis.y * 1e3
    for b in range(nb):
        top = float(speeds[b].max()) or 1.0
        for j in range(nt):
            ax = axes[b, j]
            if len(x) > 1:
                im = ax.pcolormesh(x, y, speeds[b, j].T, shading="nearest", cmap="viridis", vmin=0, vmax=top)
            else:
                im = ax.pcolormesh([x[0] - 1, x[0] + 1], y, np.repeat(speeds[b, j].T, 2, axis=1), cmap="viridis",
                                   vmin=0, vmax=top)
            ax.set_aspect("auto")
            if b == 0:
                ax.set_title(f"t = {wf.spectrum.t[idx[j]] * 1e3:.3f} ms", fontsize=9)
            if j == 0:
                lo, hi = wf.bands[b]
                ax.set_ylabel(f"{lo:.0f}-{hi:.0f} rad/m\ny [mm]", fontsize=9)
            if b == nb - 1:
                ax.set_xlabel("x [mm]")
        fig.colorbar(im, ax=axes[b, -1], label="|v| [m/s]")
    fig.suptitle(title or "band-filtered fields")
    return fig


def band_movie_frames(wf: Wavefield, frames: int = 120) -> Iterator[np.ndarray]:
    """RGB frames of the band-filtered fields over time: one panel per band (speed |v| over the
    lines and the length, each band on its own colour scale over the whole record)."""
    from .animate import frame_indices

    idx = frame_indices(len(wf.spectrum.t), frames)
    speeds = band_speeds(wf, idx)  # (nb, F, nl, N)
    nb = speeds.shape[0]
    x, y = wf.lines.x * 1e3, wf.lines.basis.y * 1e3
    if len(x) == 1:
        x = np.array([x[0] - 1, x[0] + 1])
        speeds = np.repeat(speeds, 2, axis=2)
    fig, axes = plt.subplots(1, nb, figsize=(2.2 * nb + 1, 6), squeeze=False, dpi=80, layout="constrained")
    images = []
    for b in range(nb):
        ax = axes[0, b]
        top = float(speeds[b].max()) or 1.0
        images.append(ax.pcolormesh(x, y, speeds[b, 0].T, shading="nearest", cmap="viridis", vmin=0, vmax=top))
        lo, hi = wf.bands[b]
        ax.set(title=f"{lo:.0f}-{hi:.0f} rad/m", xlabel="x [mm]", ylabel="y [mm]" if b == 0 else "")
    heading = fig.suptitle("")
    try:
        for j, i in enumerate(idx):
            for b, im in enumerate(images):
                im.set_array(speeds[b, j].T.ravel())
            heading.set_text(f"band-filtered speed |v|, t = {wf.spectrum.t[i] * 1e3:.4f} ms")
            fig.canvas.draw()
            rgb = np.asarray(fig.canvas.buffer_rgba())[:, :, :3]
            h, w = (rgb.shape[0] // 16) * 16, (rgb.shape[1] // 16) * 16  # the encoder's macro blocks
            yield rgb[:h, :w].copy()
    finally:
        plt.close(fig)
