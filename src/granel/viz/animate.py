"""Animations (Appendix C): the magnified deformation or the normalised energy density of
eq. (14), as MP4 with a GIF fallback (`viz.encoding`). `plan_frames` computes what every frame
shows, `MovieFigure` draws it, `animate` renders one movie and `render_movies` many in parallel
processes. docs/analysis.md ("Figures and movies") describes the stages."""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field as dc_field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..analysis.density import granule_energies, granule_energy_density, granule_states  # noqa: E402
from ..analysis.result_model import result_modes, result_solid, result_system  # noqa: E402
from ..solid.kinds import kind_of  # noqa: E402
from ..io.model import read_record, read_result  # noqa: E402
from ..io.results import ResultFileError  # noqa: E402,F401 - the error of a result that cannot be used
from ..io.results import require, require_states  # noqa: E402
from ..granular.loads import load_history  # noqa: E402
from .encoding import write_movie  # noqa: E402

# the paper's magnification of the deformation movies (Appendix C)
MAGNIFICATION = {"weak": 5000.0, "moderate": 1000.0, "strong": 200.0}
FIELDS = ("deformation", "energy-density")
# colour scale of the energy-density movies: w / w0 of eq. (14) on a log scale
W_MIN, W_MAX = 1e-6, 1.0
CMAP = "inferno"
# the largest frame rate a movie may ask for (a GIF shows at most 100 frames per second)
MAX_FPS = 1000


def default_magnification(ds) -> float:
    """The deformation movies' magnification: the paper's for its shock levels (the first load's
    `shock_level`), else 3 mm over the largest displacement of a granule."""
    loads = read_record(ds).loads
    level = load_history(loads[0].kind, loads[0].params, loads[0].times, loads[0].values).shock_level if loads else None
    if level in MAGNIFICATION:
        return MAGNIFICATION[level]
    require_states(ds, "the movie's magnification")
    disp = np.hypot(ds["x"].values - ds["x"].values[0], ds["y"].values - ds["y"].values[0]).max()
    return float(0.003 / disp) if disp > 0 else 1.0


def frame_indices(n: int, max_frames: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, max_frames)).round().astype(int))


def _check_field(field: str) -> None:
    if field not in FIELDS:
        raise ValueError(f"field must be 'deformation' or 'energy-density', got {field!r}")


def check_movie_options(max_frames=120, fps=20, magnification=None) -> None:
    """ValueError naming the option for a frame count that is not a whole number >= 1, a frame
    rate that is not a whole number from 1 to MAX_FPS, or a magnification that is not a finite
    number > 0."""
    for name, v, top in (("frames", max_frames, None), ("fps", fps, MAX_FPS)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1 or (top is not None and v > top):
            raise ValueError(f"{name} must be a whole number from 1{f' to {top}' if top else ' up'}, got {v!r}")
    if magnification is not None:
        try:
            m = float(magnification)
        except (TypeError, ValueError):
            m = float("nan")
        if not (np.isfinite(m) and m > 0):
            raise ValueError(f"magnification must be a finite number > 0, got {magnification!r}")


# what a movie reads from a result (besides its model record and the scenario text in its attributes)
RESULT_VARIABLES = ("x", "y", "theta", "v_x", "v_y", "omega")


def check_result(ds, name="result") -> None:
    """ResultFileError unless `ds` is a granel result that fits the model it carries."""
    from ..io.model import check_result_model, read_record
    from ..io.results import check_result_schema

    check_result_schema(ds, name)
    check_result_model(ds, read_record(ds, name), name)


def _first_line(e: Exception) -> str:
    lines = str(e).strip().splitlines()
    return f"{type(e).__name__}: {lines[0]}" if lines else type(e).__name__


# --------------------------------------------------------------------------------------------
# 1. what every frame shows


def solid_states(ds, times: np.ndarray, modes=None) -> tuple[np.ndarray, np.ndarray]:
    """The solid's reduced (q, v), shape (len(times), ndof) each, at the stored solid times
    nearest to `times` (`analysis.solid.reduced_states`, modes cached per process)."""
    from ..analysis.solid import reduced_states

    if modes is None and "solid_eta" in ds:
        modes = result_modes(ds)
    return reduced_states(ds, times, result_solid(ds), modes)


@dataclass
class FramePlan:
    """Everything the frames of one movie show, precomputed (F frames, n granules)."""

    field: str
    times: np.ndarray  # (F,) frame times [s]
    radius: np.ndarray  # (n,) granule radii [m]
    centres: np.ndarray  # (F, n, 2) granule centres as drawn (magnified for deformation)
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    magnification: float | None = None
    granule_w: np.ndarray | None = None  # (F, n) w / w0, clipped at W_MIN (energy density)
    # the solid, as its kind draws it (`SolidKind.shape`, `energy_cells`); all None: none drawn
    solid_polygons: np.ndarray | None = None  # (F, P, k, 2) magnified deformed cells (deformation)
    solid_line: np.ndarray | None = None  # (F, n, 2) magnified deformed centre line (deformation)
    solid_cells: np.ndarray | None = None  # (P, k, 2) the cells coloured by energy density
    solid_w: np.ndarray | None = None  # (F, P) their w / w0, clipped
    walls: list = dc_field(default_factory=list)  # ((x0, x1), (y0, y1)) of each rigid wall, static

    @property
    def frames(self) -> int:
        return len(self.times)

    def title(self, i: int) -> str:
        t = float(self.times[i]) * 1e3
        if self.field == "deformation":
            return f"deformation x{self.magnification:g}, t = {t:.3f} ms"
        return f"normalised energy density, t = {t:.3f} ms"


def _limits(ds, system, model) -> tuple[list[float], list[float]]:
    """Fixed axis limits covering the granules' initial positions and the solid."""
    x0, y0 = ds["x"].values[0], ds["y"].values[0]
    rmax = float(system.radius.max())
    xlim = [float(x0.min()) - 1.5 * rmax, float(x0.max()) + 1.5 * rmax]
    ylim = [float(y0.min()) - 1.5 * rmax, float(y0.max()) + 1.5 * rmax]
    if model.nodes is not None:
        xlim = [min(xlim[0], model.nodes[:, 0].min()), max(xlim[1], model.nodes[:, 0].max())]
        ylim = [min(ylim[0], model.nodes[:, 1].min() - 0.05 * rmax), max(ylim[1], model.nodes[:, 1].max() + 0.05 * rmax)]
    return xlim, ylim


def plan_frames(ds, field: str = "deformation", magnification: float | None = None, max_frames: int = 120) -> FramePlan:
    """Precompute the frames of an Appendix C movie of `ds`: the magnified deformation, or the
    normalised energy density w / w0 of eq. (14) (granules and solid elements)."""
    _check_field(field)
    system, model = result_system(ds), result_solid(ds)
    times_all = ds["time"].values
    idx = frame_indices(len(times_all), max_frames)
    times = times_all[idx].astype(float)
    xlim, ylim = _limits(ds, system, model)
    kind = kind_of(model)
    has_solid = kind.elastic and "solid_time" in ds
    modes = result_modes(ds) if has_solid and "solid_x" not in ds else None
    require_states(ds, "a movie")
    if kind.elastic:
        require(ds, ["solid_time"], "a movie of the solid")
    X, Yp = ds["x"].values[idx], ds["y"].values[idx]
    plan = FramePlan(field, times, np.asarray(system.radius, float), np.stack([X, Yp], axis=-1), tuple(xlim), tuple(ylim),
                     walls=[((w.p0[0], w.p1[0]), (w.p0[1], w.p1[1])) for w in system.walls])
    if field == "deformation":
        mag = magnification or default_magnification(ds)
        plan.magnification = mag
        x0, y0 = ds["x"].values[0], ds["y"].values[0]
        plan.centres = np.stack([x0 + mag * (X - x0), y0 + mag * (Yp - y0)], axis=-1)
        if has_solid:
            Q, _ = solid_states(ds, times, modes)
            shapes = [kind.shape(model, model.full_displacement(q), mag) for q in Q]
            if shapes[0].polygons is not None:
                plan.solid_polygons = np.stack([s.polygons for s in shapes])
            else:
                plan.solid_line = np.stack([s.line for s in shapes])
        return plan

    # energy density, eq. (14): w / w0 with w0 the excited granule's peak kinetic energy density
    from ..analysis.density import excited_reference

    w0 = excited_reference(ds)
    SU = None
    if has_solid:
        Q, V = solid_states(ds, times, modes)
        B = model.contact_map()
        SU = np.ascontiguousarray((B @ Q.T).T).reshape(len(times), -1, 2)  # C order, as the kernel was compiled for
        cells = [kind.energy_cells(model, q, v) for q, v in zip(Q, V)]
        plan.solid_cells = cells[0].polygons
        plan.solid_w = np.clip(np.stack([c.values for c in cells]) / w0, W_MIN, None)
    e = granule_energies(system, granule_states(ds, idx), SU)
    plan.granule_w = np.clip(granule_energy_density(system, e, system.radius) / w0, W_MIN, None)
    return plan


# --------------------------------------------------------------------------------------------
# 2. the figure, built once


class MovieFigure:
    """The figure of one movie: artists built once from a FramePlan, then `show(i)` updates them
    to frame i and `rgb()` renders the canvas."""

    def __init__(self, plan: FramePlan, figsize=(6.4, 6.4), dpi=100):
        from matplotlib.collections import EllipseCollection
        from matplotlib.colors import LogNorm

        from . import figures  # noqa: F401 - the figures' rcParams (font size, grid)
        from ..solid.base import Patches, Shape
        from .plots import draw_patches, draw_shape

        self.plan = plan
        self.fig, self.ax = fig, ax = plt.subplots(figsize=figsize, dpi=dpi)
        energy = plan.field == "energy-density"
        self.norm = LogNorm(W_MIN, W_MAX) if energy else None
        if energy:
            from matplotlib.cm import ScalarMappable

            fig.colorbar(ScalarMappable(norm=LogNorm(W_MIN, W_MAX), cmap=CMAP), ax=ax, shrink=0.8,
                         label="normalised energy density w / w0, eq. (14)")
        d = 2.0 * plan.radius
        style = dict(cmap=CMAP, norm=self.norm, edgecolor="0.5", linewidth=0.3) if energy else \
            dict(facecolor="#9db4d6", edgecolor="k", linewidth=0.5)
        self.granules = EllipseCollection(d, d, np.zeros_like(d), units="xy", offsets=plan.centres[0],
                                          offset_transform=ax.transData, **style)
        if energy:
            self.granules.set_array(plan.granule_w[0])
        ax.add_collection(self.granules)
        self.solid = None
        if energy and plan.solid_cells is not None:
            self.solid = draw_patches(ax, Patches(plan.solid_cells, plan.solid_w[0]), CMAP, self.norm)
        elif plan.solid_polygons is not None:
            self.solid = draw_shape(ax, Shape(polygons=plan.solid_polygons[0]), color="C3", lw=0.25)
        elif plan.solid_line is not None:
            self.solid = draw_shape(ax, Shape(line=plan.solid_line[0]), color="C3", line_lw=2)
        if energy:
            ax.set_xticks([])
            ax.set_yticks([])
        # the rigid walls never move, but granules touch them: they are redrawn over the granules
        self.walls = [ax.plot(xs, ys, color="k", lw=2.0, solid_capstyle="butt")[0] for xs, ys in plan.walls]
        self.title = ax.set_title(plan.title(0), fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(*plan.xlim)
        ax.set_ylim(*plan.ylim)
        self.show(0)
        self._prepare_blit()

    def show(self, i: int) -> None:
        """Set every artist to frame i."""
        p = self.plan
        self.granules.set_offsets(p.centres[i])
        if p.field == "energy-density":
            self.granules.set_array(p.granule_w[i])
            if p.solid_w is not None:
                self.solid.set_array(p.solid_w[i])
        elif p.solid_polygons is not None:
            self.solid.set_verts(p.solid_polygons[i])
        elif p.solid_line is not None:
            self.solid.set_data(p.solid_line[i, :, 0], p.solid_line[i, :, 1])
        self.title.set_text(p.title(i))

    def _prepare_blit(self) -> None:
        """Render the static part of the figure once (axes, ticks, labels, colour bar) and note the
        artists to redraw on top of it per frame, in the order Axes.draw would draw them: the
        moving artists, the grid lines over them (zorder 1.5), the beam line (2), the spines (2.5)
        and the title (3). Tick marks and labels lie outside the axes box, where nothing moves."""
        ax, canvas = self.ax, self.fig.canvas
        moving = [a for a in (self.granules, self.solid) if a is not None] + self.walls
        spines = list(ax.spines.values()) if ax.axison and ax.get_frame_on() else []
        over = sorted(moving + spines + [self.title], key=lambda a: a.zorder)  # stable: insertion order
        canvas.draw()  # creates and places the ticks
        grid = []
        if ax.axison:
            for axis in (ax.xaxis, ax.yaxis):
                lo, hi = sorted(axis.get_view_interval())
                tol = 1e-10 * (hi - lo)
                grid += [t.gridline for t in axis.get_major_ticks() + axis.get_minor_ticks()
                         if t.gridline.get_visible() and lo - tol <= t.get_loc() <= hi + tol]
        for a in over:
            a.set_animated(True)
        for g in grid:
            g.set_visible(False)
        canvas.draw()
        self._background = canvas.copy_from_bbox(self.fig.bbox)
        for g in grid:
            g.set_visible(True)
        z_grid = ax.xaxis.get_zorder()
        below = [a for a in over if a.zorder <= z_grid]
        self._layers = below + grid + [a for a in over if a.zorder > z_grid]

    def rgb(self, blit: bool = True) -> np.ndarray:
        """The figure as an RGB array: the static background restored and the moving artists drawn
        over it (blit=True), or a full redraw (blit=False; the same pixels, slower)."""
        canvas = self.fig.canvas
        if not blit:
            animated = [a for a in self._layers if a.get_animated()]
            for a in animated:
                a.set_animated(False)
            canvas.draw()
            for a in animated:
                a.set_animated(True)
        else:
            canvas.restore_region(self._background)
            for a in self._layers:
                self.ax.draw_artist(a)
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        plt.close(self.fig)


def iter_frames(plan: FramePlan) -> Iterator[np.ndarray]:
    """The RGB frames of a plan, one at a time (the figure is built once)."""
    mf = MovieFigure(plan)
    try:
        for i in range(plan.frames):
            mf.show(i)
            yield mf.rgb()
    finally:
        mf.close()


# --------------------------------------------------------------------------------------------
# 3. one movie


def animate(ds, out, field: str = "deformation", magnification: float | None = None, max_frames: int = 120,
            fps: int = 20) -> Path:
    """Render one Appendix C movie of a result Dataset: the deformation magnified (x5000 / x1000 /
    x200 for weak / moderate / strong shocks unless `magnification` is given) or the normalised
    energy density w / w0 of eq. (14) on a log colour scale [1e-6, 1]. Returns the written path
    (.mp4, or .gif if the MP4 encoder is unavailable). ValueError for a bad option (see
    `check_movie_options`)."""
    _check_field(field)
    check_movie_options(max_frames, fps, magnification)
    plan = plan_frames(ds, field, magnification, max_frames)
    return write_movie(lambda: iter_frames(plan), Path(out), fps)


# --------------------------------------------------------------------------------------------
# many movies in parallel


@dataclass(frozen=True)
class MovieJob:
    """One movie to render: a result NetCDF file and animate()'s arguments."""

    result: Path
    out: Path
    field: str = "deformation"
    magnification: float | None = None
    max_frames: int = 120
    fps: int = 20

    @classmethod
    def of(cls, job) -> "MovieJob":
        """From a MovieJob, a tuple (result, out, field, magnification, max_frames, fps) (trailing
        items optional) or a dict with those keys (`nc`/`path` for result, `output` for out and
        `frames` for max_frames also accepted)."""
        if isinstance(job, MovieJob):
            return job
        if isinstance(job, dict):
            d = dict(job)
            alias = {"nc": "result", "path": "result", "output": "out", "frames": "max_frames"}
            d = {alias.get(k, k): v for k, v in d.items()}
            unknown = set(d) - set(cls.__dataclass_fields__)
            if unknown:
                raise ValueError(f"movie job {job!r}: unknown keys {sorted(unknown)}")
        else:
            names = list(cls.__dataclass_fields__)
            if not 2 <= len(job) <= len(names):
                raise ValueError(f"movie job {job!r}: expected (result, out[, field, magnification, max_frames, fps])")
            d = dict(zip(names, job))
        d["result"], d["out"] = Path(d["result"]), Path(d["out"])
        return cls(**d)


class MovieError(RuntimeError):
    """One or more movies of render_movies failed; `failures` maps output path -> message."""

    def __init__(self, failures: dict):
        self.failures = failures
        lines = [f"{len(failures)} movie(s) failed:"] + [f"--- {out}:\n{msg}" for out, msg in failures.items()]
        super().__init__("\n".join(lines))


def _render_group(jobs: list[MovieJob], read=read_result) -> list[tuple[bool, str, float]]:
    """Render jobs sharing one result file (read once by `read`): [(ok, path or error text, seconds)]."""
    res = []
    try:
        ds = read(jobs[0].result)
    except Exception as e:  # noqa: BLE001 - reported per job
        msg = f"{jobs[0].result}: cannot read: {type(e).__name__}: {e}"
        return [(False, f"{j.out.name}: {msg}", 0.0) for j in jobs]
    for j in jobs:
        t0 = time.perf_counter()
        try:
            p = animate(ds, j.out, j.field, j.magnification, j.max_frames, j.fps)
            res.append((True, str(p), time.perf_counter() - t0))
        except Exception as e:  # noqa: BLE001 - reported per job
            res.append((False, f"{j.out.name} (from {j.result}): {type(e).__name__}: {e}\n{traceback.format_exc()}",
                        time.perf_counter() - t0))
    return res


def render_movies(jobs, workers: int = 2, progress: Callable[[Path], None] | None = None, read=read_result) -> list[Path]:
    """Render many Appendix C movies (the magnified deformation or the energy density of eq. 14;
    e.g. the 24 of `granel paper`) and return their paths in job order.

    jobs: MovieJobs, tuples (result .nc, output, field, magnification, max_frames, fps) or dicts
    (see MovieJob.of). Jobs on one result file share a task (the file read and the solid built
    once), unless there are fewer files than workers. workers > 1 renders in worker processes of a
    'spawn' context (numba and forked threads do not mix: a script calling this must guard its entry
    point with `if __name__ == "__main__":`); workers = 1 renders in this process. progress(path) is
    called as each movie is written. A failed movie does not stop the others; MovieError then names
    every failed output with its error. `read(path)` reads a result (`io.model.read_result`;
    `run.load_result` for results of an earlier granel)."""
    jobs = [MovieJob.of(j) for j in jobs]
    for j in jobs:
        try:
            _check_field(j.field)
            check_movie_options(j.max_frames, j.fps, j.magnification)
        except ValueError as e:
            raise ValueError(f"movie {j.out.name}: {e}") from None
    if not jobs:
        return []
    groups: dict[Path, list[int]] = {}
    for k, j in enumerate(jobs):
        groups.setdefault(j.result.resolve(), []).append(k)
    tasks = list(groups.values())
    if len(tasks) < workers:  # too few files to keep every worker busy
        tasks = [[k] for k in range(len(jobs))]

    def cost(t):  # longest first: movies x file size (plate results are the big, slow ones)
        r = jobs[t[0]].result
        return len(t), r.stat().st_size if r.exists() else 0

    tasks.sort(key=cost, reverse=True)
    results: dict[int, tuple[bool, str, float]] = {}

    def done(t, res):
        for k, r in zip(t, res):
            results[k] = r
            if progress and r[0]:
                progress(Path(r[1]))

    if workers <= 1 or len(tasks) == 1:
        for t in tasks:
            done(t, _render_group([jobs[k] for k in t], read))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        from ..guard.signals import pool_initializer

        with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=mp.get_context("spawn"),
                                 initializer=pool_initializer) as ex:
            futures = {ex.submit(_render_group, [jobs[k] for k in t], read): t for t in tasks}
            for fu in as_completed(futures):
                t = futures[fu]
                try:
                    done(t, fu.result())
                except Exception as e:  # noqa: BLE001 - e.g. a worker died
                    done(t, [(False, f"{jobs[k].out.name}: worker failed: {type(e).__name__}: {e}", 0.0) for k in t])
    failures = {str(jobs[k].out): results[k][1] for k in range(len(jobs)) if not results[k][0]}
    if failures:
        raise MovieError(failures)
    return [Path(results[k][1]) for k in range(len(jobs))]


__all__ = ["MAGNIFICATION", "FIELDS", "FramePlan", "MovieFigure", "MovieJob", "MovieError", "ResultFileError", "animate",
           "check_movie_options", "check_result", "default_magnification", "frame_indices", "granule_energies", "iter_frames",
           "plan_frames", "render_movies", "solid_states"]


def check_movie_request(output: Path, field: str, magnification, frames: int, fps: int) -> None:
    """`granel animate`'s options, before anything is read: InputError naming the option."""
    from ..guard.exits import InputError

    if frames < 1:
        raise InputError(f"--frames {frames}: give a whole number of frames >= 1")
    if not 1 <= fps <= MAX_FPS:
        raise InputError(f"--fps {fps}: give a whole number of frames per second from 1 to {MAX_FPS}")
    if magnification is not None and not (np.isfinite(magnification) and magnification > 0):
        raise InputError(f"--magnification {magnification}: give a finite number > 0")
    if field not in FIELDS:
        raise InputError(f"--field {field!r}: choose deformation or energy-density")
    if Path(output).suffix.lower() not in (".mp4", ".gif"):
        raise InputError(f"--output {output}: give a .mp4 or .gif file name")
