"""Results as xarray Datasets <-> NetCDF files (h5netcdf engine), written atomically.

A run's variables are first laid out as a `ResultSpec` (names, dimensions, arrays, attributes);
`ResultSpec.to_dataset` makes the xarray Dataset, and `write_spec_netcdf` writes the same file
without xarray, which is imported lazily here (its import, with pandas, is a large part of a
fresh `granel run`)."""

from __future__ import annotations

import io
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .. import __version__
from ..guard.exits import GranelError
from ..guard.owners import process_token, token_state
from ..guard.writing import atomic_path  # noqa: F401 - the one atomic writer, used through here too
from ..guard.writing import remove_stale_temporaries as guard_remove_stale


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove the temporary files and staging folders that killed granel processes left beside
    `path` (`guard.writing.remove_stale_temporaries`), and those of the older naming
    (.NAME.PID.XXXX.tmp) whose process is gone. Returns the removed paths."""
    path = Path(path)
    removed = guard_remove_stale(path.parent)
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        pid = tmp.name[len(path.name) + 2:].split(".", 1)[0]
        if not pid.isdigit() or token_state(process_token(int(pid))) != "dead":
            continue
        try:
            tmp.unlink()
            removed.append(tmp)
        except OSError:
            pass
    return removed


def write_netcdf(ds, path: str | Path) -> Path:
    """Write atomically (temporary file in the same directory, then rename). The arrays are in
    memory, so dask (if this process has it) is told to write synchronously: xarray would
    otherwise hand the write to whatever dask client is current, even a broken one. Every file
    carries the `granel_version` attribute: granel's mark (`guard.owners.is_granel_file`)."""
    ds = ds.copy(deep=False)
    ds.attrs = storable_attrs({"granel_version": __version__, **ds.attrs})
    if "unlimited_dims" in ds.encoding:  # a file's empty dimensions come back unlimited, maybe since dropped
        ds.encoding = {**ds.encoding, "unlimited_dims": {d for d in ds.encoding["unlimited_dims"] if d in ds.dims}}
    buffer = io.BytesIO()
    with _synchronous_dask():
        ds.to_netcdf(buffer, engine="h5netcdf", invalid_netcdf=False)
    return _netcdf_to(path, buffer)


@contextmanager
def _synchronous_dask():
    dask = sys.modules.get("dask")
    if dask is None or not hasattr(dask, "config"):
        yield
        return
    with dask.config.set(scheduler="synchronous"):
        yield


class ResultFileError(GranelError, ValueError):
    """A file that cannot be used as a granel result or summary; the message names the file.
    `code` 4: it cannot be read as NetCDF (missing data, truncated, not HDF5); 2: it reads, but
    is not what the command takes (another kind of file, a variable missing or cut, NaN where a
    state must be finite)."""

    code = 4


def read_netcdf_or(path: str | Path, error=ResultFileError, what: str = "result file"):
    """`read_netcdf` for a file given by a user (`guard.reading.check_file` first): a file that
    cannot be read as NetCDF (truncated, foreign bytes) raises `error` (an exception class) with a
    message naming the file (exit code 4)."""
    from ..guard.reading import InputFileError, check_file

    path = Path(path)
    try:
        check_file(path, what)
    except InputFileError as e:
        raise _with_code(error(str(e)), e.code) from None
    try:
        import h5netcdf  # noqa: F401 - the backend, loaded first: xarray reports a failed load as "not installed"
    except ImportError as e:  # a library that cannot be loaded now (too many open files, ...)
        raise _with_code(error(f"{path}: cannot be read: the NetCDF library cannot be loaded ({e})"), 4) from None
    import gc

    previous = sys.unraisablehook
    sys.unraisablehook = _quiet_h5_finalisers(previous)
    try:
        try:
            return read_netcdf(path)
        except Exception as e:  # noqa: BLE001 - OSError (h5py), ValueError, ...: the file is the problem
            lines = str(e).strip().splitlines()
            failure = f"{type(e).__name__}{': ' + lines[0][:200] if lines else ''}"
        gc.collect()  # the half-opened file's finaliser runs now, silent
    finally:
        sys.unraisablehook = previous
    raise _with_code(error(f"{path}: cannot be read as NetCDF ({failure})"), 4) from None


def _quiet_h5_finalisers(previous):
    """An unraisable hook that drops h5netcdf's and h5py's: a file h5netcdf failed to open is half
    built, and its finaliser fails again when it is collected (Python prints that as an ignored
    exception with a traceback). Every other goes to `previous`."""
    def hook(unraisable):
        source = getattr(unraisable.object, "__module__", "") or ""
        if not source.startswith(("h5netcdf", "h5py")):
            previous(unraisable)

    return hook


def _with_code(e: Exception, code: int) -> Exception:
    try:
        e.code = code
    except AttributeError:  # pragma: no cover - an error type without attributes
        pass
    return e


# the dimensions of every variable a run's result may hold (README, "Results"); a result that
# holds one of these names with other dimensions is damaged
RESULT_DIMS = {
    "x": ("time", "granule"), "y": ("time", "granule"), "theta": ("time", "granule"),
    "v_x": ("time", "granule"), "v_y": ("time", "granule"), "omega": ("time", "granule"),
    "energy_solid": ("time",), "energy_gravity": ("time",), "energy_solid_kinetic": ("time",), "energy_solid_potential": ("time",),
    "dissipated_viscous": ("time",), "dissipated_friction": ("time",), "input_work": ("time",),
    "balance_error": ("time",),
    "contact_force_normal": ("time", "contact"), "contact_force_tangential": ("time", "contact"),
    "wall_force_normal": ("time", "wall"), "wall_force_tangential": ("time", "wall"),
    "step_size": ("time",), "iterations": ("time",), "lambda_max": ("time", "contact"),
    "step_time": ("step",), "step_dt": ("step",), "step_iterations": ("step",), "step_lambda": ("step", "contact"),
    "solid_time": ("solid_time",), "solid_eta": ("solid_time", "mode"), "solid_eta_dot": ("solid_time", "mode"),
    "mode_omega": ("mode",), "solid_x": ("solid_time", "dof"), "solid_v": ("solid_time", "dof"),
    "medium": ("granule",), "equilibrium_force": ("equilibrium_contact",),
    "equilibrium_overlap": ("equilibrium_contact",),
}
# the variables of the model a result carries (`io.model`)
RECORD_DIMS = {
    "granule_radius": ("granule",), "granule_mass": ("granule",), "granule_inertia": ("granule",),
    "granule_modulus": ("granule",), "granule_poisson": ("granule",), "granule_position0": ("granule", "xy"),
    "wall_p0": ("wall", "xy"), "wall_p1": ("wall", "xy"), "wall_normal": ("wall", "xy"), "wall_medium": ("wall",),
    "wall_drive": ("wall", "wall_drive_param"), "wall_damped": ("wall",),
    "contact_granule": ("contact",), "contact_position": ("contact", "xy"),
    "contact_normal": ("contact", "xy"), "contact_dofs": ("contact", "contact_dof"),
    "solid_node_position": ("solid_node", "xy"), "solid_element_nodes": ("solid_element", "element_node"),
    "load_granule": ("load",), "load_direction": ("load", "xy"), "load_kind": ("load",),
    "load_params": ("load", "load_param"), "load_table_size": ("load",), "load_table_time": ("load_table",),
    "load_table_value": ("load_table",), "load_toward": ("load",),
    "granule_toward_solid": ("granule", "xy"), "striker_granule": ("striker",),
}
RESULT_DIMS.update(RECORD_DIMS)
# the variables that hold names
TEXT_VARIABLES = ("medium", "wall_medium", "load_kind")
# the granules' states: along `granule` (every granule) or `traced` (a few, simulation.outputs.granules)
STATE_VARIABLES = ("x", "y", "theta", "v_x", "v_y", "omega")
# what every result holds, finite at every output
RESULT_REQUIRED = ("energy_solid", "dissipated_viscous", "dissipated_friction", "input_work", "balance_error")
# the groups of variables a run may leave out (simulation.outputs), by the setting that does
OPTIONAL_GROUPS = {
    "simulation.outputs.contacts": ("contact_force_normal", "contact_force_tangential", "lambda_max"),
    "simulation.outputs.walls": ("wall_force_normal", "wall_force_tangential"),
    "simulation.outputs.steps": ("step_time", "step_dt", "step_iterations", "step_lambda"),
    "simulation.outputs.solid": ("solid_time", "solid_eta", "solid_eta_dot", "mode_omega", "solid_x", "solid_v"),
}


def check_result_schema(ds, name) -> None:
    """ResultFileError (code 2) unless `ds` has a result's structure: the scenario and version
    attributes, every required variable with its dimensions and finite values, the known
    optional ones with theirs, a time axis that increases, unique granule labels, the solid's
    modal or reduced state complete, and one energy per medium."""
    def bad(why):
        return ResultFileError(f"{name}: {why}", 2)

    if not isinstance(ds.attrs.get("scenario"), str) or "granel_version" not in ds.attrs:
        raise bad("not a granel result (no scenario or granel_version attribute)")
    missing = [v for v in RESULT_REQUIRED if v not in ds.variables]
    if missing:
        raise bad(f"not a granel result (no {', '.join(missing)})")
    for v, dims in RESULT_DIMS.items():
        if v in ds.variables and tuple(ds[v].dims) != dims and not (v in STATE_VARIABLES and tuple(ds[v].dims) == ("time", "traced")):
            raise bad(f"damaged result ({v} has dimensions {tuple(ds[v].dims)}, a result's are {dims})")
    states = [v for v in STATE_VARIABLES if v in ds.variables]
    if states and len(states) != len(STATE_VARIABLES):
        raise bad(f"damaged result ({', '.join(states)} without {', '.join(v for v in STATE_VARIABLES if v not in states)})")
    if states and len({tuple(ds[v].dims) for v in states}) > 1:
        raise bad("damaged result (the granules' states have different dimensions)")
    if ds.sizes.get("time", 0) < 1 or ds.sizes.get("granule", 0) < 1:
        raise bad("damaged result (no output time or no granule)")
    for v in RESULT_DIMS:
        if v in ds.variables and ds[v].dtype.kind not in "fiu" and v not in TEXT_VARIABLES:
            raise bad(f"damaged result ({v} is not numeric: {ds[v].dtype})")
    for v in RESULT_REQUIRED + tuple(states) + ("time",):
        values = np.asarray(ds[v].values, float)
        if not np.all(np.isfinite(values)):
            k = int(np.argmax(~np.isfinite(values).reshape(values.shape[0], -1).all(axis=1)))
            raise bad(f"damaged result ({v} is not finite at output {k})")
    t = np.asarray(ds["time"].values, float)
    if np.any(np.diff(t) <= 0):
        raise bad("damaged result (its output times do not increase)")
    labels = [str(g) for g in ds["granule"].values]
    if len(set(labels)) != len(labels):
        raise bad("damaged result (a granule label repeats)")
    if "traced" in ds.dims:
        traced = [str(g) for g in ds["traced"].values] if "traced" in ds.variables else []
        if len(traced) != ds.sizes["traced"] or not set(traced) <= set(labels) or len(set(traced)) != len(traced):
            raise bad("damaged result (its traced granules are not distinct granules of the result)")
    for group in (("solid_eta", "solid_eta_dot", "mode_omega"), ("solid_x", "solid_v")):
        present = [v for v in group if v in ds.variables]
        if present and len(present) != len(group):
            raise bad(f"damaged result ({', '.join(present)} without {', '.join(v for v in group if v not in present)})")
    media = sorted({str(m) for m in ds["medium"].values}) if "medium" in ds.variables else []
    absent = [m for m in media if f"energy_{m.lower()}" not in ds.variables]
    if absent:
        raise bad(f"damaged result (no energy_{absent[0].lower()} for the medium {absent[0]})")


def read_netcdf(path: str | Path):
    """Load a result file fully into memory (the file is closed afterwards)."""
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


@dataclass
class ResultSpec:
    """A result's variables before they become a Dataset: data and coords map names to (dims,
    values[, attrs]) as xarray takes them; `ds[name].values` and `ds.attrs` work as on a Dataset."""

    data: dict
    coords: dict
    attrs: dict
    compression: int = 0  # gzip level of the file's large arrays (0: none)

    def __contains__(self, name) -> bool:
        return name in self.data or name in self.coords

    def __getitem__(self, name: str):
        dims, values = (self.data.get(name) or self.coords[name])[:2]
        return SimpleNamespace(values=np.asarray(values), dims=(dims,) if isinstance(dims, str) else tuple(dims))

    def to_dataset(self):
        """The Dataset, its large arrays encoded as `write_spec_netcdf` writes them (`write_netcdf`
        keeps the compression)."""
        import xarray as xr

        ds = xr.Dataset(self.data, coords=self.coords, attrs=self.attrs)
        if self.compression:
            for name, v in ds.data_vars.items():
                if v.dtype.kind in "fiu" and v.size >= COMPRESS_FROM:
                    v.encoding.update(zlib=True, complevel=self.compression, shuffle=True)
        return ds


# arrays smaller than this stay contiguous and uncompressed: a chunk index costs more than it saves
COMPRESS_FROM = 4096


def write_spec_netcdf(spec: ResultSpec, path: str | Path) -> Path:
    """Write a `ResultSpec` atomically as the NetCDF file xarray would write for its Dataset
    (dimension scales, NaN fill values of floating variables, the non-index coordinates named in
    each variable's `coordinates` attribute), with h5netcdf alone. Numeric arrays of at least
    `COMPRESS_FROM` values are chunked (h5netcdf's heuristic) and compressed at the spec's gzip
    level, bytes shuffled first (docs/performance.md, "Result files")."""
    import h5netcdf
    import h5py

    def entries(table):
        for name, spec_ in table.items():
            dims, values = spec_[0], np.asarray(spec_[1])
            attrs = dict(spec_[2]) if len(spec_) > 2 else {}
            yield name, ((dims,) if isinstance(dims, str) else tuple(dims)), values, attrs

    coords, data = list(entries(spec.coords)), list(entries(spec.data))
    index = {name for name, dims, _, _ in coords if dims == (name,)}
    aux = [(name, dims) for name, dims, _, _ in coords if name not in index]
    buffer = io.BytesIO()  # HDF5 writes into memory; the disk sees one plain, atomic write (`_netcdf_to`)
    with h5netcdf.File(buffer, "w") as f:
        for _, dims, values, _ in coords + data:
            for dim, size in zip(dims, values.shape):
                if dim not in f.dimensions:
                    f.dimensions[dim] = size
        for name, dims, values, attrs in coords + data:
            if values.dtype == object:
                v = f.create_variable(name, dims, dtype=h5py.string_dtype())
                v[...] = values.astype(str).astype(object)
            else:
                fill = {"fillvalue": np.array(np.nan, values.dtype)} if values.dtype.kind == "f" else {}
                packed = {}
                if spec.compression and values.size >= COMPRESS_FROM:
                    packed = {"compression": "gzip", "compression_opts": spec.compression, "shuffle": True}
                v = f.create_variable(name, dims, dtype=values.dtype, **fill, **packed)
                if values.size:
                    v[...] = values
                if fill:
                    v.attrs["_FillValue"] = np.array([np.nan], values.dtype)
            v.attrs.update(attrs)
            names = [c for c, cdims in aux if c != name and set(cdims) <= set(dims)]
            if names:
                v.attrs["coordinates"] = " ".join(names)
        f.attrs.update(storable_attrs(spec.attrs))
    return _netcdf_to(path, buffer)


def storable_attrs(attrs: dict) -> dict:
    """The attributes with every string `guard.writing.storable`."""
    from ..guard.writing import storable

    return {k: storable(v) if isinstance(v, str) else v for k, v in attrs.items()}


def _netcdf_to(path, buffer: io.BytesIO) -> Path:
    """A NetCDF file built in memory to `path`, atomically and synced. HDF5 never writes to the
    disk itself: a full disk is then one clean OSError of a plain write (exit 4, no partial
    file), never a failure inside HDF5, which can crash the process as it closes."""
    from ..guard.writing import write_bytes

    with buffer.getbuffer() as view:  # released even when the write fails (else the buffer cannot be freed)
        return write_bytes(path, view)


def wall_names(system) -> list[str]:
    """A name for each rigid wall: its own (e.g. SSGM:top), else wall k."""
    return [w.name or f"wall {k}" for k, w in enumerate(system.walls)]


def with_every_granule(ds):
    """A result Dataset whose granules' states are stored along `traced` (a few granules,
    simulation.outputs.granules), with them along `granule` as every reader indexes them: NaN for
    the granules not traced (in memory only). Any other result is returned as it is."""
    if "traced" not in ds.dims or "x" not in ds.variables:
        return ds
    labels = {str(g): k for k, g in enumerate(ds["granule"].values)}
    cols = [labels[str(g)] for g in ds["traced"].values]
    full = {}
    for v in STATE_VARIABLES:
        values = np.full((ds.sizes["time"], ds.sizes["granule"]), np.nan, ds[v].dtype)
        values[:, cols] = ds[v].values
        full[v] = (("time", "granule"), values, ds[v].attrs)
    return ds.drop_vars(list(STATE_VARIABLES) + ["traced"]).assign(full)


def require(ds, names, what: str) -> None:
    """ResultFileError (code 2) naming the first of `names` (variables) the result does not
    store, `what` needs it, and the setting that left it out (simulation.outputs)."""
    for name in names:
        if name in ds.variables:
            continue
        setting = next((s for s, group in OPTIONAL_GROUPS.items() if name in group), None)
        why = f"this result was run with {setting} = false" if setting else "this result does not store it"
        raise ResultFileError(f"{what} needs {name}: {why}", 2)


def require_states(ds, what: str, granules=None) -> None:
    """ResultFileError (code 2) unless the result stores the state (x, y, theta, v_x, v_y, omega)
    of the granules `granules` (indices; None: every granule), naming the first missing one and
    the setting (simulation.outputs.granules). A result read by `with_every_granule` holds NaN
    for the granules it did not trace."""
    if "v_x" not in ds.variables:  # the six are stored together (`check_result_schema`)
        raise ResultFileError(f"{what} needs the granules' states (x, y, v_x, ...): this result was run with "
                              "simulation.outputs.granules = \"none\"", 2)
    if "traced" in ds["v_x"].dims:
        raise ResultFileError(f"{what} needs the granules' states along `granule`: read the result with "
                              "io.results.with_every_granule", 2)
    stored = np.isfinite(np.asarray(ds["v_x"].values[0], float))
    wanted = np.arange(len(stored)) if granules is None else np.atleast_1d(np.asarray(granules, int))
    missing = [int(g) for g in wanted if not stored[g]]
    if missing:
        labels = ds["granule"].values
        traced = [str(labels[k]) for k in np.flatnonzero(stored)]
        shown = ", ".join(traced[:4]) + (", ..." if len(traced) > 4 else "")
        need = "every granule's state" if granules is None else f"the state of granule {labels[missing[0]]}"
        raise ResultFileError(f"{what} needs {need}: this result traces only {len(traced)} granule"
                              f"{'s' if len(traced) != 1 else ''} ({shown}; simulation.outputs.granules)", 2)


def granule_column(ds, label: str, what: str) -> int:
    """The index of granule `label` along `granule`, once `require_states` has found its state."""
    g = [str(x) for x in ds["granule"].values].index(str(label))
    require_states(ds, what, [g])
    return g
