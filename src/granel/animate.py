"""Animations (Appendix C): magnified deformation or normalised energy density, as MP4
(imageio-ffmpeg) with a GIF fallback."""

from __future__ import annotations

import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

# the paper's magnification of the deformation movies
MAGNIFICATION = {"weak": 5000.0, "moderate": 1000.0, "strong": 200.0}


def default_magnification(ds) -> float:
    e = tomllib.loads(ds.attrs["scenario"]).get("excitations", [{}])[0]
    if e.get("shock") in MAGNIFICATION:
        return MAGNIFICATION[e["shock"]]
    disp = np.hypot(ds["x"].values - ds["x"].values[0], ds["y"].values - ds["y"].values[0]).max()
    return float(0.003 / disp) if disp > 0 else 1.0


def frame_indices(n: int, max_frames: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, max_frames)).round().astype(int))


def _canvas_frame(fig) -> np.ndarray:
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()


def write_movie(frames: list[np.ndarray], out: Path, fps: int) -> Path:
    """MP4 through imageio-ffmpeg; a GIF next to it if that fails (or if `out` ends in .gif)."""
    import imageio.v2 as imageio

    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() != ".gif":
        try:
            with imageio.get_writer(out, fps=fps, codec="libx264", quality=7, macro_block_size=16) as w:
                for f in frames:
                    w.append_data(f)
            return out
        except Exception:  # noqa: BLE001 - any ffmpeg problem: fall back to GIF
            if out.exists():
                out.unlink()
            out = out.with_suffix(".gif")
    imageio.mimsave(out, frames, duration=1.0 / fps, loop=0)
    return out


def animate(ds, out, field: str = "deformation", magnification: float | None = None, max_frames: int = 120,
            fps: int = 20) -> Path:
    """Render one movie of a result Dataset; returns the written path (.mp4 or .gif)."""
    from .figures import draw_energy_density, model_of, solid_state_at
    from .plots import draw_plate

    if field not in ("deformation", "energy-density"):
        raise ValueError(f"field must be 'deformation' or 'energy-density', got {field!r}")
    out = Path(out)
    sc, system, model = model_of(ds)
    times = ds["time"].values
    idx = frame_indices(len(times), max_frames)
    mag = magnification or default_magnification(ds)
    modes = None
    if "solid_eta" in ds:
        from .coupling.fast import all_modes

        modes = all_modes(model)
    x0, y0 = ds["x"].values[0], ds["y"].values[0]
    rmax = float(system.radius.max())
    xlim = [float(x0.min()) - 1.5 * rmax, float(x0.max()) + 1.5 * rmax]
    ylim = [float(y0.min()) - 1.5 * rmax, float(y0.max()) + 1.5 * rmax]
    if model.nodes is not None:
        xlim = [min(xlim[0], model.nodes[:, 0].min()), max(xlim[1], model.nodes[:, 0].max())]
        ylim = [min(ylim[0], model.nodes[:, 1].min() - 0.05 * rmax), max(ylim[1], model.nodes[:, 1].max() + 0.05 * rmax)]
    frames = []
    fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=100)
    if field == "energy-density":
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import LogNorm

        fig.colorbar(ScalarMappable(norm=LogNorm(1e-6, 1.0), cmap="inferno"), ax=ax, shrink=0.8,
                     label="normalised energy density w / w0, eq. (14)")
    for k in idx:
        ax.clear()
        t = float(times[k])
        if field == "deformation":
            xs = x0 + mag * (ds["x"].values[k] - x0)
            ys = y0 + mag * (ds["y"].values[k] - y0)
            ax.add_collection(PatchCollection([Circle((a, b), r) for a, b, r in zip(xs, ys, system.radius)],
                                              facecolor="#9db4d6", edgecolor="k", linewidth=0.5))
            if model.kind != "rigid" and "solid_time" in ds:
                q, _, _ = solid_state_at(ds, t, modes)
                u = model.full_displacement(q)
                if model.kind == "plate":
                    draw_plate(ax, model, u, mag, color="C3", lw=0.25)
                else:
                    ax.plot(model.nodes[:, 0] + mag * u[:, 0], model.nodes[:, 1], "C3-", lw=2)
            ax.set_title(f"deformation x{mag:g}, t = {t * 1e3:.3f} ms", fontsize=9)
        else:
            draw_energy_density(ax, ds, t, modes=modes)
            ax.set_title(f"normalised energy density, t = {t * 1e3:.3f} ms", fontsize=9)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        frames.append(_canvas_frame(fig))
    plt.close(fig)
    return write_movie(frames, out, fps)
