"""`granel wavefield`: the solid's wavefield of a result in wavenumber and time
(`analysis.wavefield`), written to a folder: wavefield.nc, the figures kt.png, fk.png,
moments.png and bands.png, and on request the movie bands.mp4 (docs/wavefield.md).

The options are checked before anything is read (`check_options`), the result before anything
is computed (`read_wavefield_result`: a result whose solid is rigid, or that has none, is
refused with exit code 2); every file is written atomically (`guard.writing`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..guard.exits import InputError
from ..io.results import require
from ..solid.kinds import is_elastic

FILES = ("wavefield.nc", "kt.png", "fk.png", "moments.png", "bands.png")
MOVIE = "bands.mp4"
MAX_BANDS = 12


@dataclass(frozen=True)
class WavefieldOptions:
    """What `granel wavefield` computes: `bands` (a count of equal bands up to k_max, or their
    edges [rad/m], ascending), the moments' largest wavenumber `k_max` [rad/m] (None: the
    elements' resolution limit), the growth law's window `fit` (t0, t_end) [s] (None: from the
    arrival to the end), and the movie (`movie`, its `frames` and `fps`)."""

    bands: int | tuple[float, ...] = 4
    k_max: float | None = None
    fit: tuple[float, float] | None = None
    movie: bool = False
    frames: int = 120
    fps: int = 20


def parse_bands(text: str | None) -> int | tuple[float, ...]:
    """`--bands`: a whole number of equal bands (1..MAX_BANDS), or two or more ascending edges
    [rad/m] separated by commas. ValueError with the reason."""
    if text is None:
        return 4
    text = text.strip()
    if "," not in text:
        try:
            n = int(text)
        except ValueError:
            raise ValueError("give a whole number of bands or their edges in rad/m, e.g. 4 or 0,200,400,700") from None
        if not 1 <= n <= MAX_BANDS:
            raise ValueError(f"give 1 to {MAX_BANDS} bands")
        return n
    try:
        edges = tuple(float(e) for e in text.split(","))
    except ValueError:
        raise ValueError("the edges must be numbers in rad/m, e.g. 0,200,400,700") from None
    if not all(np.isfinite(edges)) or edges[0] < 0 or np.any(np.diff(edges) <= 0):
        raise ValueError("the edges must be finite, >= 0 and ascending")
    if len(edges) - 1 > MAX_BANDS:
        raise ValueError(f"at most {MAX_BANDS} bands")
    return edges


def parse_window(text: str | None) -> tuple[float, float] | None:
    """`--fit`: START:END simulated times (e.g. 0.1ms:0.8ms). ValueError with the reason."""
    if text is None:
        return None
    from ..io.units import parse_time

    parts = text.split(":")
    if len(parts) != 2:
        raise ValueError("give START:END, e.g. 0.1ms:0.8ms")
    try:
        t0, t1 = parse_time(parts[0].strip()), parse_time(parts[1].strip())
    except ValueError as e:
        raise ValueError(str(e)) from None
    if not (np.isfinite(t0) and np.isfinite(t1) and 0 <= t0 < t1):
        raise ValueError("START and END must be finite with 0 <= START < END")
    return float(t0), float(t1)


def check_options(options: WavefieldOptions) -> None:
    """InputError naming the option for a k_max that is not a positive number, or a movie's frame
    count or rate out of range (`viz.animate.check_movie_options`)."""
    from ..viz.animate import check_movie_options

    if options.k_max is not None and not (np.isfinite(options.k_max) and options.k_max > 0):
        raise InputError(f"--k-max {options.k_max}: give a positive wavenumber in rad/m")
    try:
        check_movie_options(options.frames, options.fps)
    except ValueError as e:
        raise InputError(f"--{str(e).split()[0]}: {e}") from None


def read_wavefield_result(path) -> "xr.Dataset":
    """A run's result (`run.load_result`: exit 4 unreadable, 2 not a result or damaged), refused
    (InputError, exit 2) unless its solid is a plate or a beam with stored states."""
    from ..io.model import read_record
    from ..run import load_result

    ds = load_result(path)
    kind = read_record(ds, path).solid_kind
    if not is_elastic(kind):
        raise InputError(f"{path}: its solid is {kind or 'absent'}: a wavefield needs an elastic solid "
                         "(run with --solid plate or --solid beam)")
    require(ds, ["solid_time"], f"{path}: a wavefield")
    if ds.sizes.get("solid_time", 0) < 4:
        raise InputError(f"{path}: {ds.sizes.get('solid_time', 0)} stored solid outputs; a wavefield needs 4 or more")
    if "solid_eta_dot" not in ds and "solid_v" not in ds:
        raise InputError(f"{path}: damaged result (solid_time without the solid's state: no solid_eta_dot or solid_v)")
    ts, t = np.asarray(ds["solid_time"].values, float), np.asarray(ds["time"].values, float)
    if not np.all(np.isfinite(ts)) or np.any(np.diff(ts) <= 0):
        raise InputError(f"{path}: damaged result (its solid output times, solid_time, are not finite and increasing)")
    # the two time axes are accumulated apart: a 5 us run stores 5e-06 s and 4.9999999999999996e-06 s as its
    # last outputs; 1e-9 of the run's span is far above such rounding and far below an output interval
    slack = 1e-9 * max(t[-1] - t[0], abs(t[-1]))
    if ts[0] < t[0] - slack or ts[-1] > t[-1] + slack:
        raise InputError(f"{path}: damaged result (its solid outputs, {ts[0]:.6g}-{ts[-1]:.6g} s, lie outside its run, "
                         f"{t[0]:.6g}-{t[-1]:.6g} s)")
    return ds


def resolve_bands(options: WavefieldOptions, k_max: float, k, name) -> np.ndarray:
    """The bands' edges (nb, 2) [rad/m]: equal bands up to k_max, or the edges given; InputError
    if the edges given start at or beyond the record's largest wavenumber, or if a band holds none
    of the record's wavenumbers `k` (k_lo <= k < k_hi, as `analysis.wavefield.band_field` takes
    them: its field and energy would be zero by construction)."""
    from ..analysis.wavefield import default_bands

    k = np.asarray(k, float)
    if isinstance(options.bands, int):
        bands = default_bands(k_max, options.bands)
        upto = f"--k-max {k_max:.4g} rad/m" if options.k_max is not None else \
            f"the default --k-max, the elements' resolution limit {k_max:.4g} rad/m"
        given, remedy = f"--bands {options.bands} (equal bands up to {upto})", "give fewer bands or a larger --k-max"
    else:
        e = np.asarray(options.bands, float)
        given, remedy = f"--bands {','.join(f'{x:g}' for x in e)}", "give wider bands"
        if e[0] >= k[-1]:
            raise InputError(f"{given}: {name} holds wavenumbers up to {k[-1]:.4g} rad/m; give edges below that")
        bands = np.column_stack([e[:-1], e[1:]])
    for lo, hi in bands:
        if not np.any((k >= lo) & (k < hi)):
            raise InputError(f"{given}: the band {lo:.4g}-{hi:.4g} rad/m holds none of {name}'s wavenumbers "
                             f"({k[0]:.4g}, {k[1]:.4g}, ..., {k[-1]:.4g} rad/m); {remedy}")
    return bands


def check_window(options: WavefieldOptions, t, name) -> None:
    """InputError naming --fit unless its window (START, END] lies within the record's solid
    outputs `t` [s] (END at most half an output interval after the last: a time that rounds to
    it) and holds the 3 outputs `analysis.wavefield.growth_exponent` needs for a fit."""
    if options.fit is None:
        return
    t = np.asarray(t, float)
    t0, t1 = options.fit
    given = f"--fit {t0 * 1e3:.6g}ms:{t1 * 1e3:.6g}ms"
    if t1 > t[-1] + 0.5 * (t[-1] - t[-2]):
        raise InputError(f"{given}: END is after {name}'s last solid output at {t[-1] * 1e3:.6g} ms")
    inside = int(np.count_nonzero((t > t0) & (t <= t1)))
    if inside < 3:
        raise InputError(f"{given}: the window holds {inside} of {name}'s solid outputs ({t[0] * 1e3:.6g}-"
                         f"{t[-1] * 1e3:.6g} ms); the growth law needs 3 or more")


@dataclass(frozen=True)
class WavefieldReport:
    """What `wavefield_study` wrote (`files`) and found: the growth exponents of the kinetic and
    the modal energy spectra's variances (NaN without a modal state), the entropy at the end,
    the analysed and validated wavenumbers, and the seconds it took."""

    files: list[Path]
    exponent: float
    stderr: float
    modal_exponent: float
    modal_stderr: float
    fit: tuple[float, float]
    entropy_end: float
    k_max: float
    k_window: float
    k_resolved: float
    ridges: int
    seconds: float


def wavefield_dataset(wf, source: str = "") -> "xr.Dataset":
    """The analysis as a Dataset (units in each variable's attributes; docs/wavefield.md)."""
    import xarray as xr

    s, fk = wf.spectrum, wf.fk
    curves = wf.branches.curves()
    f32 = np.float32
    band_energy = np.stack([s.energy[(s.k >= lo) & (s.k < hi)].sum(axis=0) for lo, hi in wf.bands])
    data = {
        "energy_line": (("x", "k", "t"), s.energy_line.astype(f32),
                        {"units": "J", "long_name": "kinetic energy of each harmonic per line"}),
        "band_edges": (("band", "edge"), wf.bands, {"units": "rad/m"}),
        "band_energy": (("band", "t"), band_energy, {"units": "J", "long_name": "kinetic energy of each band"}),
        "band_density": (("band", "y", "t"), wf.band_density.astype(f32),
                         {"units": "J/m", "long_name": "kinetic energy per unit length of each band's field"}),
        "fk_power": (("k_map", "f"), fk.power.astype(f32),
                     {"units": "J s", "long_name": "frequency-wavenumber power (Hann windows in t and y)"}),
        "branch_frequency": (("branch", "k_branch"), np.array([curves[n] for n in curves]),
                             {"units": "Hz", "long_name": "analytic dispersion branches"}),
        "ridge_k": ("ridge", wf.ridges.k, {"units": "rad/m"}),
        "ridge_f": ("ridge", wf.ridges.f, {"units": "Hz"}),
        "ridge_power": ("ridge", wf.ridges.power, {"units": "J s"}),
    }
    attrs = {}
    for suffix, what, m in (("", "kinetic energy", wf.kinetic), ("_modal", "modal energy", wf.modal)):
        if m is None:
            continue
        mo, g = m.moments, m.growth
        data.update({
            f"energy{suffix}": (("k", "t"), m.energy.astype(f32), {"units": "J", "long_name": f"{what} of each "
                                                                                               "harmonic"}),
            f"total{suffix}": ("t", mo.total, {"units": "J", "long_name": f"{what} of the harmonics k <= k_max"}),
            f"centroid{suffix}": ("t", mo.centroid, {"units": "rad/m", "long_name": "spectral centroid sum k p"}),
            f"variance{suffix}": ("t", mo.variance, {"units": "(rad/m)^2", "long_name": "spectral variance "
                                                                                       "sum (k - mu)^2 p"}),
            f"entropy{suffix}": ("t", mo.entropy, {"units": "nats", "long_name": "Shannon entropy -sum p ln p"}),
        })
        attrs.update({f"growth{suffix}_exponent": g.exponent, f"growth{suffix}_stderr": g.stderr,
                      f"growth{suffix}_prefactor": g.prefactor})
    coords = {
        "t": ("t", s.t, {"units": "s", "long_name": "time of the stored solid outputs"}),
        "k": ("k", s.k, {"units": "rad/m", "long_name": f"wavenumber of the {wf.lines.basis.ends} basis"}),
        "x": ("x", wf.lines.x, {"units": "m", "long_name": "node line's position across the width"}),
        "y": ("y", wf.lines.basis.y, {"units": "m", "long_name": "sample position along the length"}),
        "band": ("band", np.arange(len(wf.bands))),
        "edge": ("edge", np.array(["low", "high"], dtype=object)),
        "k_map": ("k_map", fk.k, {"units": "rad/m", "long_name": "wavenumber of the map (Fourier, Hann window)"}),
        "f": ("f", fk.f, {"units": "Hz"}),
        "branch": ("branch", np.array(list(curves), dtype=object)),
        "k_branch": ("k_branch", wf.branches.k, {"units": "rad/m"}),
    }
    attrs.update({
        "source": str(source), "solid_kind": wf.lines.kind, "ends": wf.lines.basis.ends,
        "components": ",".join(wf.lines.components), "k_max": wf.moments.k_max, "k_resolved": wf.k_resolved,
        "k_window": wf.k_window, "arrival_s": wf.arrival, "fit_t0_s": wf.growth.t0, "fit_t_end_s": wf.growth.t_end,
        "fit_points": wf.growth.points, "map_pad": fk.pad, "kinetic_check": wf.kinetic_check,
        "definitions": "E(k,t): kinetic energy of the harmonic k (Parseval over the basis); *_modal: each mode's "
                       "energy shared over k by its shape; p = E / sum E over k <= k_max; variance = "
                       "A (t - t0)^growth_exponent, least squares in log-log; see docs/wavefield.md",
    })
    return xr.Dataset(data, coords=coords, attrs=attrs)


@dataclass(frozen=True)
class WavefieldPlan:
    """What a wavefield will be computed on, settled before any computation: the solid model,
    its node lines, the moments' k_max [rad/m] and the bands (nb, 2) [rad/m]."""

    model: object
    lines: object
    k_max: float
    bands: np.ndarray


def plan_wavefield(ds, options: WavefieldOptions, name="result") -> WavefieldPlan:
    """The solid of result `ds` (`analysis.result_model.result_solid`: exit 2 if it cannot be
    built), its node lines and the bands, checked against its wavenumbers, k_max against its
    first two and the fit window against its solid outputs (InputError naming the option, exit 2)."""
    from ..analysis.result_model import result_solid
    from ..analysis.wavefield import node_lines, resolved_wavenumber

    model = result_solid(ds, name)
    try:
        lines = node_lines(model)
    except ValueError as e:
        raise InputError(f"{name}: {e}") from None
    k_max = options.k_max if options.k_max is not None else resolved_wavenumber(lines)
    k = lines.basis.k
    if np.count_nonzero(k <= k_max) < 2:  # one wavenumber: variance and entropy 0 whatever the field
        default = "" if options.k_max is not None else " (the default, the elements' resolution limit)"
        raise InputError(f"--k-max {k_max:.4g}{default}: the moments need 2 or more of {name}'s wavenumbers, and its "
                         f"first two are {k[0]:.4g} and {k[1]:.4g} rad/m; give --k-max {k[1]:.4g} or more")
    require(ds, ["solid_time"], f"granel wavefield ({name})")
    check_window(options, ds["solid_time"].values, name)
    if "mode_omega" in ds:  # the modal energy takes the stored frequencies with the solid's own shapes
        from ..analysis.result_model import result_modes

        stored, own = np.asarray(ds["mode_omega"].values, float), np.asarray(result_modes(ds, name).omega, float)
        # the run stored its modes' frequencies: a new eigen-solve gave them bit for bit on the paper's plate, and
        # LAPACK's rounding elsewhere is about eps (w_max / w_min)^2 relative, 5e-9 there (w_max / w_min = 4616)
        if stored.shape != own.shape or not np.allclose(stored, own, rtol=1e-6, atol=0.0):
            raise InputError(f"{name}: damaged result (its mode_omega are not the modal frequencies of its solid)")
    return WavefieldPlan(model, lines, float(k_max), resolve_bands(options, k_max, k, name))


def stage_count(options: WavefieldOptions) -> int:
    """The progress stages of `wavefield_study`."""
    return 6 + len(FILES) + (1 if options.movie else 0)


def wavefield_study(ds, out: Path, options: WavefieldOptions = WavefieldOptions(), progress=None, name="result",
                    plan: WavefieldPlan | None = None) -> WavefieldReport:
    """The wavefield of result `ds` (`read_wavefield_result`) into folder `out`: FILES, and MOVIE
    with `options.movie`. progress(what, done, total) before each stage (`stage_count`)."""
    from ..analysis.result_model import result_modes
    from ..analysis.wavefield import WavefieldSettings, analyse_wavefield
    from ..guard.writing import save_figure, storable
    from ..io.results import write_netcdf
    from ..viz import wavefield as V

    start = time.perf_counter()
    stages, done = stage_count(options), [0]

    def say(what):
        if progress:
            progress(what, done[0], stages)
        done[0] += 1

    say("the solid and its modes")
    plan = plan or plan_wavefield(ds, options, name)
    modes = result_modes(ds, name) if "solid_eta" in ds else None
    settings = WavefieldSettings(bands=plan.bands, k_max=plan.k_max, fit=options.fit)
    wf = analyse_wavefield(ds, plan.model, modes, settings, progress=say, name=name)
    top = float(np.finfo(np.float32).max)  # wavefield.nc holds these in float32 (`wavefield_dataset`)
    held = [("E(k, t)", wf.spectrum.energy_line), ("the band fields' energy", wf.band_density),
            ("the map", wf.fk.power)]
    for what, values in held + ([("the modal energy", wf.modal.energy)] if wf.modal is not None else []):
        if not np.all(np.abs(values) <= top):  # NaN and inf fail it too
            raise InputError(f"{name}: damaged result (its solid state gives {what} beyond {top:.3g}, float32's "
                             "largest, or not finite)")
    out = Path(out)
    shown = storable(str(name))  # a name that is not UTF-8 with its bytes escaped: fonts and HDF5 take only text
    title = f"{Path(shown).name} ({wf.lines.kind})"
    say("wavefield.nc")
    write_netcdf(wavefield_dataset(wf, shown), out / "wavefield.nc")
    files = [out / "wavefield.nc"]
    for file, figure in (("kt.png", V.kt_figure), ("fk.png", V.fk_figure), ("moments.png", V.moments_figure),
                         ("bands.png", V.bands_figure)):
        say(file)
        files.append(save_figure(figure(wf, title=f"{title}: {FIGURE_TITLES[file]}"), out / file, dpi=110))
    if options.movie:
        from ..viz.encoding import write_movie

        say(MOVIE)
        files.append(write_movie(lambda: V.band_movie_frames(wf, options.frames), out / MOVIE, options.fps))
    modal = wf.modal.growth if wf.modal is not None else None
    return WavefieldReport(files, wf.growth.exponent, wf.growth.stderr, modal.exponent if modal else np.nan,
                           modal.stderr if modal else np.nan, (wf.growth.t0, wf.growth.t_end),
                           float(wf.moments.entropy[-1]), wf.moments.k_max, wf.k_window, wf.k_resolved,
                           len(wf.ridges.k), time.perf_counter() - start)


FIGURE_TITLES = {"kt.png": "kinetic energy over wavenumber and time", "fk.png": "frequency-wavenumber map",
                 "moments.png": "moments of the spectrum", "bands.png": "band-filtered fields"}


@dataclass(frozen=True)
class WavefieldRequest:
    """What `granel wavefield` was asked, checked: the result read, its options and their plan."""

    ds: object
    options: WavefieldOptions
    plan: WavefieldPlan


def wavefield_request(result: Path, out: Path, bands: str | None, k_max, fit: str | None, movie: bool, frames: int,
                      fps: int) -> WavefieldRequest:
    """`granel wavefield`'s options and files, checked before any computation (InputError or
    ResultFileError naming the option or the file), and its output folder made."""
    from ..guard.exits import option_value
    from ..guard.outputs import OutputPlan
    from ..guard.reading import check_file

    band_spec = option_value("--bands", bands, parse_bands)
    window = option_value("--fit", fit, parse_window)
    options = WavefieldOptions(band_spec, k_max, window, movie, frames, fps)
    check_options(options)
    check_file(result, "result file")
    plan = OutputPlan(inputs=[result])
    plan.folder(out, "-o", "wavefield", recognise=lambda p: (p / "wavefield.nc").exists())
    for name in FILES + ((MOVIE,) if movie else ()):
        plan.file(out / name, f"-o (its {name})")
    plan.check()
    ds = read_wavefield_result(result)
    settled = plan_wavefield(ds, options, result)
    plan.prepare()
    return WavefieldRequest(ds, options, settled)


def report_rows(report: WavefieldReport) -> list[tuple[str, str]]:
    """`granel wavefield`'s table of a `WavefieldReport`: (label, value) rows."""
    return [("variance growth exponent", f"kinetic {report.exponent:.3f} +- {report.stderr:.3f}, modal "
                                         f"{report.modal_exponent:.3f} +- {report.modal_stderr:.3f} (fit over "
                                         f"{report.fit[0] * 1e3:.4f}-{report.fit[1] * 1e3:.4f} ms)"),
            ("entropy at the end", f"{report.entropy_end:.3f} nats"),
            ("wavenumbers analysed", f"k <= {report.k_max:.1f} rad/m (elements resolve {report.k_resolved:.1f})"),
            ("ridges on the map", f"{report.ridges} (k >= {report.k_window:.1f} rad/m)"),
            ("time", f"{report.seconds:.2f} s")]
