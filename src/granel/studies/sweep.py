"""Parameter sweeps over any scenario field, run on dask.distributed (a LocalCluster by
default, or an existing scheduler), with one NetCDF per run, resume, and a summary Dataset.
Cases are the Cartesian product of a sweep file's axes (at most MAX_CASES); what a case runs and
measures is its mode's (`modes.StudyMode`). docs/sweeps.md gives the sweep file and when a
rerun reuses a case or a run."""

from __future__ import annotations

import hashlib
import itertools
import json
import traceback
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .. import __version__
from .. import scenario as S
from ..io.results import ResultFileError, with_every_granule
from .modes import ModeName, study_mode
from .spectrum import SpectrumSpec

# a sweep larger than this is refused at load (a mistyped count would otherwise build millions of cases)
MAX_CASES = 100_000
# the version of the metric definitions, raised when one changes so that cached results are
# recomputed (docs/sweeps.md, "Running", gives each version)
METRIC_RULES = 6


class SweepFileError(S.ScenarioError):
    """A sweep file that exists but cannot be read (a directory, unreadable, not UTF-8 text)."""


class SchedulerError(RuntimeError):
    """The sweep's dask cluster cannot be used: `code` 2 for a malformed address, 4 for a
    scheduler that cannot be reached or has no worker."""

    def __init__(self, msg: str, code: int):
        super().__init__(msg)
        self.code = code


class SummaryFileError(ResultFileError):
    """A file that cannot be used as a sweep summary; the message names the file. `code` 4:
    it cannot be read as NetCDF; 2: a NetCDF file of something else, or damaged."""


class AxisSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    field: str | None = None
    name: str | None = None
    values: list[Any] | None = None
    linspace: tuple[float, float, int] | None = None
    logspace: tuple[float, float, int] | None = None
    zip: dict[str, list[Any]] | None = None

    @model_validator(mode="after")
    def _one_kind(self):
        kinds = [k for k in ("values", "linspace", "logspace", "zip") if getattr(self, k) is not None]
        if len(kinds) != 1:
            raise ValueError(f"an axis needs exactly one of values, linspace, logspace, zip (got {kinds or 'none'})")
        if self.zip is None and not self.field:
            raise ValueError("an axis needs 'field' (or 'zip' with 'name')")
        if self.values is not None and not self.values:
            raise ValueError("an axis needs at least one value, got values = []")
        if self.zip is not None:
            if not self.name:
                raise ValueError("a zipped axis needs a 'name'")
            lens = {len(v) for v in self.zip.values()}
            if len(lens) != 1 or 0 in lens:
                raise ValueError(f"zipped lists must be non-empty and of equal length, got {sorted(lens)}")
        for k in ("linspace", "logspace"):
            v = getattr(self, k)
            if v is not None and v[2] < 1:
                raise ValueError(f"{k} needs a positive count, got {v[2]}")
            if v is not None and not (np.isfinite(v[0]) and np.isfinite(v[1])):
                raise ValueError(f"{k} bounds must be finite, got {v[0]}, {v[1]}")
            if k == "logspace" and v is not None and (v[0] <= 0 or v[1] <= 0):
                raise ValueError("logspace bounds must be positive")
        return self

    @property
    def size(self) -> int:
        """The number of points of this axis."""
        if self.zip is not None:
            return len(next(iter(self.zip.values())))
        if self.values is not None:
            return len(self.values)
        return int((self.linspace or self.logspace)[2])

    @property
    def dim(self) -> str:
        return self.name or self.field.replace(".", "_")

    def points(self) -> list[dict[str, Any]]:
        """The overrides of each point of this axis: [{field: value, ...}, ...]."""
        if self.zip is not None:
            n = len(next(iter(self.zip.values())))
            return [{f: vals[i] for f, vals in self.zip.items()} for i in range(n)]
        if self.values is not None:
            vals = self.values
        elif self.linspace is not None:
            vals = list(np.linspace(*self.linspace[:2], int(self.linspace[2])))
        else:
            a, b, n = self.logspace
            vals = list(np.geomspace(a, b, int(n)))
        return [{self.field: (float(v) if isinstance(v, (np.floating, float)) else v)} for v in vals]

    def coordinate(self):
        if self.zip is not None:
            return np.arange(len(next(iter(self.zip.values()))))
        return np.array([list(p.values())[0] for p in self.points()])


class CaseSpec(BaseModel):
    """What one case runs and measures, shared by sweeps and designs: a base scenario and its
    overrides, the mode (one run, both directions of a shock, or a narrowband spectrum point) and
    the measured pair."""

    model_config = ConfigDict(extra="forbid")
    name: str = "sweep"
    description: str = ""
    base: str = "paper"
    overrides: list[str] = Field(default_factory=list)
    mode: ModeName = "reciprocity"
    pair: tuple[str, str] = ("LSGM:3", "SSGM:C")
    spectrum: SpectrumSpec | None = None

    @model_validator(mode="after")
    def _mode_settings(self):
        study_mode(self.mode).check_settings(self)
        return self

    @classmethod
    def of(cls, spec_json: str) -> "CaseSpec":
        """The case part of a sweep's or a design's JSON."""
        return cls.model_validate({k: v for k, v in json.loads(spec_json).items() if k in cls.model_fields})

    def base_path(self, base_dir: Path) -> str:
        """The base scenario as `scenario.load` takes it: a built-in name, or its file's path
        (relative to `base_dir`, the study file's folder)."""
        if self.base in S.builtin_names():
            return self.base
        p = Path(self.base)
        return str(p if p.is_absolute() else base_dir / p)


class SweepSpec(CaseSpec):
    axes: list[AxisSpec] = Field(min_length=1)

    @model_validator(mode="after")
    def _dims(self):
        dims = [a.dim for a in self.axes]
        if len(set(dims)) != len(dims):
            raise ValueError(f"axis names must be unique, got {dims}")
        study_mode(self.mode).check_axes({f for a in self.axes for f in ([a.field] if a.zip is None else list(a.zip))})
        n = 1
        for a in self.axes:
            n *= a.size
        if n > MAX_CASES:
            raise ValueError(f"{n} cases: more than {MAX_CASES}; split the sweep")
        return self


def load_sweep(path) -> tuple[SweepSpec, Path]:
    """A sweep file -> (SweepSpec, its folder); any problem reading, parsing or validating it
    names the file (and the line or field), with the reader's exit code."""
    from ..guard.reading import InputFileError, read_toml

    path = Path(path)
    try:
        raw = read_toml(path, "sweep")
    except InputFileError as e:
        raise SweepFileError(str(e), e.code) from None
    try:
        spec = SweepSpec.model_validate(raw)
    except ValidationError as e:
        raise S.ScenarioError(S._format_validation_error(e).replace("invalid scenario", f"invalid sweep {path}")) from None
    return spec, path.parent


# an axis value that leaves its field as the base has it (a zipped field that one case does not use)
UNSET = "-"


def case_overrides(case: dict) -> list[str]:
    """A case's `key=value` overrides (a value of "-" sets nothing)."""
    return [S.override(k, v) for k, v in case["overrides"].items() if not (isinstance(v, str) and v == UNSET)]


def cases(spec: SweepSpec) -> list[dict]:
    """Every case: its index tuple and the overrides it applies."""
    pts = [a.points() for a in spec.axes]
    out = []
    for idx in itertools.product(*[range(len(p)) for p in pts]):
        ov = {}
        for a, i in enumerate(idx):
            ov.update(pts[a][i])
        tag = "_".join(f"{spec.axes[a].dim}-{i}" for a, i in enumerate(idx))
        out.append({"index": idx, "overrides": ov, "tag": tag})
    return out


def sweep_inputs(spec: CaseSpec, base_dir: Path) -> list[Path]:
    """The files a sweep's or a design's cases read: the base scenario (unless a built-in), and
    every granule or load table it, its overrides or its axes name."""
    out = []
    base = spec.base_path(base_dir)
    if base not in S.builtin_names():
        out.append(Path(base))
    folder = Path(base).parent if base not in S.builtin_names() else base_dir
    names = S.referenced_names(base, spec.overrides)  # the base's own errors are reported by check_base
    for axis in getattr(spec, "axes", []) or []:
        fields = [axis.field] if axis.zip is None else list(axis.zip)
        for f in fields:
            if f and f.split(".")[-1] in ("granules_file", "file"):
                names += [p[f] for p in axis.points() if f in p]
    return out + [Path(n) if Path(n).is_absolute() else folder / n for n in names if isinstance(n, str) and n]


def check_base(spec: CaseSpec, base_dir: Path) -> None:
    """Fail early (ScenarioError) when the sweep's base scenario cannot be read or its overrides
    cannot be applied; whether each case's scenario is valid is each case's business."""
    base = spec.base_path(base_dir)
    try:
        S.check_source(base, spec.overrides)
    except S.ScenarioError as e:
        if str(e).startswith("cannot read"):
            raise S.ScenarioError(f"sweep base {spec.base!r}: {e}") from None
        raise


def check_mode(spec: CaseSpec, base_dir: Path, case: dict) -> None:
    """Fail early (ScenarioError naming the field) when the mode's settings do not fit `case`'s
    scenario (`StudyMode.check`)."""
    study_mode(spec.mode).check(spec, spec.base_path(base_dir), list(spec.overrides) + case_overrides(case),
                                case["overrides"])


def case_fingerprint(spec: CaseSpec, scenarios: list[tuple[str, S.Scenario]], case: dict) -> str:
    """What a case's cached result depends on: the full scenario text of each of its runs (with
    every solver setting of its [simulation] table) and the contents of the files they read, the
    sweep's and the case's overrides, the mode's settings (`StudyMode.fingerprint`), the granel
    version and the metric rules."""
    payload = {
        "granel_version": __version__,
        "metric_rules": METRIC_RULES,
        **study_mode(spec.mode).fingerprint(spec),
        "sweep_overrides": list(spec.overrides),
        "case_overrides": case["overrides"],
        "scenarios": {key: S.to_toml(sc) for key, sc in scenarios},
        "inputs": {key: S.input_digests(sc) for key, sc in scenarios if S.input_digests(sc)},
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()


def _cached_case(done: Path, fp: str, case: dict) -> dict | None:
    """A case's stored result, if it finished ok with fingerprint fp."""
    try:
        r = json.loads(done.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(r, dict) or r.get("status") != "ok" or r.get("fingerprint") != fp or not isinstance(r.get("metrics"), dict):
        return None
    r["index"] = list(case["index"])
    return r


def _cached_run(path: Path, sc: S.Scenario):
    """A run's stored Dataset, if it holds the run of scenario `sc` (its text and the contents of
    the files it reads) by this granel version, and is a sound result."""
    from ..guard.fingerprints import decode
    from ..io.results import check_result_schema, read_netcdf

    if not path.exists():
        return None
    try:
        ds = read_netcdf(path)
        check_result_schema(ds, path)
    except Exception:  # noqa: BLE001 - truncated, corrupt, foreign, damaged: run again
        return None
    if ds.attrs.get("scenario") != S.to_toml(sc) or ds.attrs.get("granel_version") != __version__:
        return None
    if decode(ds.attrs.get("input_files", "{}")) != S.input_digests(sc):
        return None
    return with_every_granule(ds)


def case_scenarios(spec: CaseSpec, base_dir: Path, case: dict, check_usage: bool = True) -> list[tuple[str, S.Scenario]]:
    """The runs of one case, (key, scenario) each, as its mode makes them (`StudyMode.scenarios`)."""
    return study_mode(spec.mode).scenarios(spec, spec.base_path(base_dir), list(spec.overrides) + case_overrides(case),
                                           case["overrides"], check_usage)


def run_case(spec_json: str, base_dir: str, case: dict, out_dir: str, keep_runs: bool = True) -> dict:
    """Run one case (a worker task): writes its NetCDF file(s) (unless `keep_runs` is false: a
    design's trials keep their metrics only), returns its metrics or its error, with `wall_s`
    (the case's time in the worker) and `solver_s` (its runs' time in the solver), and the
    parts of its time (`parts`: loading the scenarios, building, the solid's modes and the
    solver's set-up, the solver, the metrics).
    A stored result is returned instead only if it finished ok with this case's fingerprint
    (`case_fingerprint`); a failed case is run again. `spec_json` is a sweep's or a design's
    JSON (its `CaseSpec` part is used). The runs and the metrics are the mode's
    (`StudyMode.scenarios`, `StudyMode.measure`); a metric that is NaN has its reason under
    `notes`."""
    from ..io.results import write_netcdf
    from ..run import run_scenario

    import time

    start = time.perf_counter()
    spec = CaseSpec.of(spec_json)
    mode = study_mode(spec.mode)
    out = Path(out_dir) / "cases"
    done = out / f"{case['tag']}.json"
    res: dict = {"tag": case["tag"], "index": list(case["index"]), "overrides": case["overrides"]}
    try:
        scenarios = case_scenarios(spec, Path(base_dir), case)
        res["fingerprint"] = fp = case_fingerprint(spec, scenarios, case)
        cached = _cached_case(done, fp, case)
        if cached is not None:
            return cached
        res["parts"] = {"load_s": time.perf_counter() - start}  # the scenarios, validated, and the fingerprint
        runs = {}
        for key, sc in scenarios:
            path = out / f"{case['tag']}__{key}.nc"
            ds = _cached_run(path, sc) if keep_runs else None
            if ds is None:
                ds = run_scenario(sc)
                if keep_runs:
                    write_netcdf(ds, path)
            runs[key] = with_every_granule(ds)
        measuring = time.perf_counter()
        res["metrics"], notes = mode.measure(spec, scenarios, runs)
        if notes:
            res["notes"] = notes
        res["solver_s"] = sum(float(ds.attrs.get("solver_wall_time_s", np.nan)) for ds in runs.values())
        res["parts"].update(build_s=sum(float(ds.attrs.get("build_s", np.nan)) for ds in runs.values()),
                            modes_s=sum(float(ds.attrs.get("solver_setup_s", np.nan)) for ds in runs.values()),
                            solver_s=res["solver_s"], metrics_s=time.perf_counter() - measuring)
        res["status"] = "ok"
    except Exception as e:  # noqa: BLE001 - a failing case is recorded, the others go on
        res["status"] = f"error: {type(e).__name__}: {e}"
        res["traceback"] = traceback.format_exc(limit=3)
    res["wall_s"] = time.perf_counter() - start
    from ..guard.owners import MARK
    from ..guard.writing import write_text

    write_text(done, json.dumps({"written_by": f"{MARK} {__version__}", **res}, default=float))
    return res


def summary_dataset(spec: SweepSpec, results: list[dict]) -> xr.Dataset:
    """Axes as dimensions, metrics as variables (NaN where a case failed), `status` per case."""
    dims = [a.dim for a in spec.axes]
    shape = tuple(len(a.points()) for a in spec.axes)
    names = sorted({k for r in results if r.get("status") == "ok" for k in r["metrics"]})
    data = {k: np.full(shape, np.nan) for k in names}
    status = np.full(shape, "not run", dtype=object)
    for r in results:
        idx = tuple(r["index"])
        status[idx] = r.get("status", "?")
        for k, v in r.get("metrics", {}).items():
            if k in data:
                data[k][idx] = v
    coords = {}
    for a in spec.axes:
        coords[a.dim] = (a.dim, a.coordinate())
        if a.zip is not None:
            for f, vals in a.zip.items():
                coords[f.replace(".", "_")] = (a.dim, np.asarray(vals))
    ds = xr.Dataset({k: (dims, v) for k, v in data.items()}, coords=coords)
    ds["status"] = (dims, status.astype(str))
    ds.attrs["sweep"] = spec.model_dump_json()
    ds.attrs["name"] = spec.name
    return ds


def connect_scheduler(scheduler: str, timeout: float):
    """A Client of the scheduler at `scheduler` with at least one worker, or SchedulerError.
    A Client that fails to connect leaves dask's global `scheduler` setting pointing at it (it
    is never closed): that setting is put back, else xarray would later lock its file writes
    through the broken client."""
    import dask
    from dask.distributed import Client
    from distributed.comm.addressing import parse_address, parse_host_port

    example = "e.g. tcp://host:8786"
    try:
        scheme, loc = parse_address(scheduler)
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(loc)
    except (ValueError, TypeError) as e:
        raise SchedulerError(f"not a scheduler address ({e}); {example}", 2) from None
    before = {"scheduler": dask.config.get("scheduler", None)}
    try:
        client = Client(scheduler, timeout=timeout)
    except (ValueError, TypeError) as e:
        dask.config.set(before)
        raise SchedulerError(f"not a scheduler address ({e}); {example}", 2) from None
    except (OSError, TimeoutError) as e:
        dask.config.set(before)
        raise SchedulerError(f"cannot reach the scheduler ({e})", 4) from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (OSError, TimeoutError):
        client.close()
        raise SchedulerError(f"the scheduler has no worker after {timeout:g} s", 4) from None
    return client


def run_sweep(path, out_dir, workers: int = 2, scheduler: str | None = None, progress=None,
              timeout: float = 60.0) -> xr.Dataset:
    """Run the sweep file at `path` (`run_spec`)."""
    spec, base_dir = load_sweep(path)
    return run_spec(spec, base_dir, out_dir, workers, scheduler, progress, timeout)


def run_spec(spec: SweepSpec, base_dir: Path, out_dir, workers: int = 2, scheduler: str | None = None, progress=None,
             timeout: float = 60.0) -> xr.Dataset:
    """Run every case of `spec` (its base read relative to `base_dir`) on dask.distributed (a
    LocalCluster of `workers` >= 1 processes, or the scheduler at `scheduler`, which must have a
    worker within `timeout` seconds); reuses cases already finished in out_dir (see `run_case`).
    A case whose task fails (e.g. its worker dies) is recorded as failed; an OSError (out_dir not
    writable) propagates. Writes out_dir/summary.nc and returns it."""
    from dask.distributed import Client, as_completed

    from ..guard.signals import local_cluster

    from ..io.results import write_netcdf

    if not scheduler and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
    check_base(spec, base_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    todo = cases(spec)
    spec_json = spec.model_dump_json()
    cluster = None
    if scheduler:
        client = connect_scheduler(scheduler, timeout)
    else:
        cluster = local_cluster(workers)
        client = Client(cluster)
    results = []
    try:
        futures = {client.submit(run_case, spec_json, str(base_dir.resolve()), c, str(out.resolve()), key=f"granel-{_key(spec_json, c)}",
                                 pure=False): c for c in todo}
        for fut in as_completed(futures):
            c = futures[fut]
            try:
                r = fut.result()
            except OSError:
                raise
            except Exception as e:  # noqa: BLE001 - e.g. KilledWorker: the case failed, the others go on
                r = {"tag": c["tag"], "index": list(c["index"]), "overrides": c["overrides"],
                     "status": f"error: task failed: {type(e).__name__}: {e}"}
            results.append(r)
            if progress is not None:
                progress(r)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    ds = summary_dataset(spec, results)
    import dask

    with dask.config.set(scheduler="synchronous"):  # a plain file lock, whatever client is around
        write_netcdf(ds, out / "summary.nc")
    return ds


def sweep_study(spec: SweepSpec, base_dir: Path, out_dir, workers: int = 2, scheduler: str | None = None,
                progress=None) -> xr.Dataset:
    """`granel sweep`: every case of `spec` (`run_spec`, which writes out_dir/summary.nc) and, in
    spectrum mode, the spectrum beside the summary (`spectrum_report.write_spectrum`: spectrum.nc, .png
    and .md). Returns the summary; a failed write of the spectrum is `guard.exits.NotWritten`."""
    ds = run_spec(spec, base_dir, out_dir, workers, scheduler, progress)
    study_mode(spec.mode).finish_sweep(spec, ds, out_dir, cases(spec))
    return ds


def _key(spec_json: str, case: dict) -> str:
    return hashlib.sha1((spec_json + case["tag"]).encode()).hexdigest()[:16]


def read_summary(path) -> xr.Dataset:
    """A sweep's summary.nc, checked: raises SummaryFileError (naming the file) for a directory,
    an unreadable, truncated or non-NetCDF file, or a NetCDF file that is not a granel sweep
    summary (no `sweep` description, no `status`, dimensions other than the sweep's axes)."""
    from ..io.results import read_netcdf_or

    path = Path(path)
    ds = read_netcdf_or(path, SummaryFileError, "sweep summary file")
    if "sweep" not in ds.attrs or "status" not in ds:
        raise SummaryFileError(f"{path}: not a granel sweep summary (no sweep description or status)", 2)
    try:
        spec = SweepSpec.model_validate_json(ds.attrs["sweep"])
    except (ValidationError, ValueError, TypeError):
        raise SummaryFileError(f"{path}: not a granel sweep summary (its sweep description is invalid)", 2) from None
    dims = tuple(a.dim for a in spec.axes)
    shape = tuple(a.size for a in spec.axes)
    for name, v in ds.data_vars.items():
        if v.dims != dims or v.shape != shape:
            raise SummaryFileError(f"{path}: damaged sweep summary ({name} has dimensions {dict(v.sizes)}, "
                                   f"the sweep's axes are {dict(zip(dims, shape))})", 2)
    return ds


def plot_map(summary: xr.Dataset, output, metric: str = "nonreciprocity_index", x: str | None = None, y: str | None = None):
    """A metric over two sweep axes; remaining axes become panels (first index of any beyond).
    ValueError (naming the metric or axis) for an unknown metric or axis, or a metric without a
    finite value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..viz.plots import save

    if metric not in summary:
        raise ValueError(f"--metric {metric!r}: unknown metric; available: {', '.join(v for v in summary.data_vars if v != 'status')}")
    da = summary[metric]
    dims = list(da.dims)
    for opt, d in (("x", x), ("y", y)):
        if d is not None and d not in dims:
            raise ValueError(f"--{opt} {d!r}: not an axis of the sweep; axes: {', '.join(dims)}")
    if x is not None and x == y:
        raise ValueError(f"--x and --y are both {x!r}: choose two different axes")
    if da.dtype.kind not in "fiu":
        raise ValueError(f"--metric {metric!r}: not a numeric metric")
    if not np.isfinite(da.values).any():
        raise ValueError(f"--metric {metric!r}: no finite value in this sweep (its cases failed, or it never occurred)")
    x = x or next((d for d in dims if d != y), dims[0])
    y = y or next((d for d in dims if d != x), None)
    if x == y:
        raise ValueError(f"--x and --y are both {x!r}: the metric has one axis only")
    rest = [d for d in dims if d not in (x, y)]
    panels = [{}]
    if rest:
        panels = [{rest[0]: v} for v in da[rest[0]].values]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.8), squeeze=False)
    vmin, vmax = float(np.nanmin(da.values)), float(np.nanmax(da.values))
    for ax, sel in zip(axes[0], panels):
        sub = da.sel(sel)
        for d in rest[1:]:
            sub = sub.isel({d: 0})
        if y is None:
            ax.plot(sub[x].values, sub.values, "o-")
            ax.set_ylabel(metric)
        else:
            sub = sub.transpose(y, x)
            xv, yv = sub[x].values, sub[y].values
            xi = np.arange(len(xv)) if xv.dtype.kind not in "fi" else xv
            yi = np.arange(len(yv)) if yv.dtype.kind not in "fi" else yv
            m = ax.pcolormesh(xi, yi, sub.values, shading="nearest", vmin=vmin, vmax=vmax, cmap="viridis")
            if xv.dtype.kind == "f" and np.all(xv > 0) and xv.max() / xv.min() > 20:
                ax.set_xscale("log")
            if xv.dtype.kind not in "fi":
                ax.set_xticks(xi, xv)
            if yv.dtype.kind not in "fi":
                ax.set_yticks(yi, yv)
            ax.set_ylabel(y)
            fig.colorbar(m, ax=ax, label=metric)
        ax.set_xlabel(x)
        ax.set_title(", ".join(f"{k} = {v}" for k, v in sel.items()) or metric, fontsize=9)
    fig.tight_layout()
    return save(fig, output)


def plan_sweep(sweep_file: Path, spec: SweepSpec, base_dir: Path, out: Path) -> None:
    """`granel sweep`'s outputs (the folder, its summary.nc and the mode's `sweep_outputs`),
    checked before any computation and made."""
    from ..guard.outputs import OutputPlan
    from ..guard.owners import is_granel_file

    plan = OutputPlan(inputs=[sweep_file, *sweep_inputs(spec, base_dir)])
    plan.folder(out, "--out", "sweep", recognise=lambda p: (p / "cases").is_dir() or is_granel_file(p / "summary.nc"))
    for name in ("summary.nc", *study_mode(spec.mode).sweep_outputs(spec)):
        plan.file(out / name, f"--out (its {name})")
    plan.check().prepare()


def summary_statistics(ds: xr.Dataset) -> list[list[str]]:
    """Each metric of a sweep's summary with a finite value: [name, min, median, max]."""
    rows = []
    for m in (v for v in ds.data_vars if v != "status"):
        v = ds[m].values
        if np.isfinite(v).any():
            rows.append([m, f"{np.nanmin(v):.4g}", f"{np.nanmedian(v):.4g}", f"{np.nanmax(v):.4g}"])
    return rows
