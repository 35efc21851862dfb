"""Export a run's result (the NetCDF file of `granel run`) for ParaView, OVITO and spreadsheets:
VTK (VTU files with PVD time series), XDMF, extended XYZ and CSV (`FORMATS`), with the solid's
element stress from the plane-stress law of eq. (7) (plate) or the bending of eq. (9) (beam).
docs/analysis.md ("Exports") lists the files and their fields."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from ..guard.writing import fsync_path, staging_folder
from ..io.results import require, require_states
from ..solid.kinds import kind_of

FORMATS = ("vtk", "xdmf", "csv", "extxyz")
EXTXYZ_PROPERTIES = "species:S:1:pos:R:3:radius:R:1:velo:R:3:omega:R:1"
# the variables of energies.csv: the energy ledger of eq. (11)-(13), one value per output
LEDGER_PREFIXES = ("energy_", "dissipated_")
LEDGER_NAMES = ("input_work", "balance_error")
# stored solid outputs reconstructed at once (bounds the memory of q = Phi eta)
SOLID_CHUNK = 64


class ExportError(ValueError):
    """A wrong request (code 2) or a file that cannot be read or written (code 4); the message
    names the option or the file."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


def parse_formats(values: Iterable[str] | None) -> list[str]:
    """The --format values (repeatable, or comma separated) in a fixed order; all when none given.
    ExportError (code 2) naming an unknown one."""
    if not values:
        return list(FORMATS)
    asked = []
    for v in values:
        for f in str(v).split(","):
            f = f.strip().lower()
            if not f:
                continue
            if f not in FORMATS:
                raise ExportError(f"--format {f!r}: choose from {', '.join(FORMATS)}")
            asked.append(f)
    if not asked:
        raise ExportError(f"--format: give one of {', '.join(FORMATS)}")
    return [f for f in FORMATS if f in asked]


# --------------------------------------------------------------------------------------------
# what is exported


def _fmt(x) -> str:
    """A float as the shortest text that reads back to the same float64."""
    return repr(float(x))


def _vec3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.column_stack([a, b, np.zeros_like(a)])


def check_exportable(ds, formats, name="result") -> None:
    """ResultFileError (exit 2), before anything is written, when a format needs what the result
    does not store (simulation.outputs): every granule's state for VTK, XDMF and extended XYZ, the
    solid's state for VTK and XDMF of a plate or beam. CSV takes what is there."""
    formats = set(formats)
    if formats & {"vtk", "xdmf", "extxyz"}:
        require_states(ds, f"{name}: the {'/'.join(f for f in FORMATS if f in formats and f != 'csv')} export")
    if formats & {"vtk", "xdmf"} and ds.sizes.get("solid_node", 0):
        require(ds, ["solid_time"], f"{name}: the export of the solid")


def has_solid(ds, model) -> bool:
    """Whether the result stores the motion of an elastic solid with nodes to export."""
    return kind_of(model).elastic and "solid_time" in ds and model.nodes is not None


def granule_frame(ds, system, k: int) -> dict[str, np.ndarray]:
    """The granules at output k: centres (n, 3), and the point data."""
    require_states(ds, "the export of the granules")
    x, y = ds["x"].values[k].astype(float), ds["y"].values[k].astype(float)
    vx, vy = ds["v_x"].values[k].astype(float), ds["v_y"].values[k].astype(float)
    om = ds["omega"].values[k].astype(float)
    kin = 0.5 * system.mass * (vx**2 + vy**2) + 0.5 * system.inertia * om**2
    return {"points": _vec3(x, y), "radius": np.asarray(system.radius, float), "velocity": _vec3(vx, vy),
            "omega": om, "kinetic_energy": kin}


def solid_cells(model) -> list[tuple[str, np.ndarray]]:
    """The solid's cells for meshio, as its kind gives them (`SolidKind.export_cells`: a plate's
    quad8 elements in VTK's node order, a beam's two-node lines)."""
    return kind_of(model).export_cells(model)


def elastic_constants(model) -> tuple[float, float]:
    """(Young's modulus E [Pa], Poisson ratio nu) of a solid's material (from its recipe)."""
    return float(model.recipe.E), float(model.recipe.nu)


def solid_stress(model, E: float, nu: float, x: np.ndarray) -> dict[str, np.ndarray]:
    """The stress cell data [Pa] of a solid from its full nodal DOF vector x = T q, as its kind
    computes them (`SolidKind.stress`: a plate's element-mean plane stress and von Mises stress, a
    beam's outer-fibre bending stress); {} for a rigid solid."""
    return kind_of(model).stress(model, np.asarray(x, float), E, nu)


def solid_frames(ds, model, elastic: tuple[float, float]
                 ) -> Iterator[tuple[float, np.ndarray, np.ndarray, dict[str, np.ndarray]]]:
    """(time, nodal displacement (nn, 3), nodal velocity (nn, 3), cell data) at each stored solid
    output; the cell data: element energy density (ne,) and the stress (`solid_stress`) with
    elastic = (E, nu)."""
    from ..analysis.density import solid_energy_density
    from .animate import solid_states

    require(ds, ["solid_time"], "the export of the solid")
    ts = ds["solid_time"].values.astype(float)
    for a in range(0, len(ts), SOLID_CHUNK):
        Q, V = solid_states(ds, ts[a:a + SOLID_CHUNK])
        for t, q, v in zip(ts[a:a + SOLID_CHUNK], Q, V):
            u, w = model.full_displacement(q), model.full_displacement(v)
            cells = {"energy_density": np.asarray(solid_energy_density(model, q, v), float),
                     **solid_stress(model, *elastic, model.T @ q)}
            yield float(t), _vec3(u[:, 0], u[:, 1]), _vec3(w[:, 0], w[:, 1]), cells


def solid_points(model) -> np.ndarray:
    return _vec3(model.nodes[:, 0].astype(float), model.nodes[:, 1].astype(float))


def count_steps(ds, model, formats) -> int:
    """The number of progress ticks of `export_result`."""
    nt = ds.sizes["time"]
    nst = ds.sizes["solid_time"] if has_solid(ds, model) else 0
    per = {"vtk": nt + nst, "xdmf": nt + nst, "extxyz": nt, "csv": 4}
    return sum(per[f] for f in formats)


# bytes an exported value takes at most, over the formats (the CSV and XYZ text of a float64:
# repr's 17-24 characters and a separator)
BYTES_PER_VALUE = 26


def export_size(ds, model, formats) -> float:
    """An upper estimate of an export's bytes: every granule value (position, displacement,
    velocity, spin, energy, radius: 13 numbers) at every output, and the solid's nodal (6) and
    element (5) values at every stored solid output, in each format chosen, plus 64 KiB a file
    of headers. `guard.resources.check_disk` holds it against the free disk before anything is
    written, so that no writer (HDF5's above all) meets a full disk."""
    nt, n = ds.sizes["time"], ds.sizes["granule"]
    per_frame = 13 * n
    solid = 0
    if has_solid(ds, model):
        solid = ds.sizes["solid_time"] * (6 * len(solid_points(model)) + 5 * model.nelements)
    values = nt * per_frame + solid
    files = count_steps(ds, model, formats) + 8
    return float(len(formats) * values * BYTES_PER_VALUE + files * 65536)


# --------------------------------------------------------------------------------------------
# writers (into the staging folder)


def _pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    lines += [f'    <DataSet timestep="{_fmt(t)}" group="" part="0" file="{name}"/>' for t, name in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    path.write_text("\n".join(lines), encoding="utf-8")


def _vtu_series(stage: Path, name: str, frames, tick: Callable[[], None]) -> list[str]:
    """name/name_000000.vtu, ... from frames of (time, meshio.Mesh), and name.pvd over them."""
    import meshio

    (stage / name).mkdir(exist_ok=True)
    entries = []
    for k, (t, mesh) in enumerate(frames):
        path = f"{name}/{name}_{k:06d}.vtu"
        meshio.write(stage / path, mesh, file_format="vtu")
        entries.append((t, path))
        tick()
    _pvd(stage / f"{name}.pvd", entries)
    return [path for _, path in entries] + [f"{name}.pvd"]


def write_vtk(ds, system, model, elastic: tuple[float, float], stage: Path, tick: Callable[[], None]) -> list[str]:
    import meshio

    vertices = [("vertex", np.arange(system.n, dtype=np.int64)[:, None])]

    def granules():
        for k, t in enumerate(ds["time"].values.astype(float)):
            g = granule_frame(ds, system, k)
            yield t, meshio.Mesh(g.pop("points"), vertices, point_data=g)

    files = _vtu_series(stage, "granules", granules(), tick)
    if has_solid(ds, model):
        pts, cells = solid_points(model), solid_cells(model)
        frames = ((t, meshio.Mesh(pts, cells, point_data={"displacement": u, "velocity": v},
                                  cell_data={n: [a] for n, a in c.items()}))
                  for t, u, v, c in solid_frames(ds, model, elastic))
        files += _vtu_series(stage, "solid", frames, tick)
    return files


def _time_series_writer(path: Path):
    """meshio's XDMF TimeSeriesWriter with its HDF5 file beside the .xdmf file (meshio 5.3 opens
    it in the current folder), built in memory and written in one plain write: HDF5 never meets
    a full disk or a file-size limit, whose failures it reports only as it is collected."""
    from meshio.xdmf import TimeSeriesWriter

    class Writer(TimeSeriesWriter):
        def __enter__(self):
            import io

            import h5py

            self.h5_filename = str(self.filename.with_suffix(".h5"))
            self.h5_buffer = io.BytesIO()
            self.h5_file = h5py.File(self.h5_buffer, "w")
            return self

        def __exit__(self, *exc):
            super().__exit__(*exc)  # the .xdmf file, and the HDF5 image closed
            with open(self.h5_filename, "wb") as fh:
                fh.write(self.h5_buffer.getbuffer())

    return Writer(path)


def write_xdmf(ds, system, model, elastic: tuple[float, float], stage: Path, tick: Callable[[], None]) -> list[str]:
    times = ds["time"].values.astype(float)
    n = system.n
    p0 = granule_frame(ds, system, 0)["points"]
    with _time_series_writer(stage / "granules.xdmf") as w:
        w.write_points_cells(p0, [("vertex", np.arange(n, dtype=np.int64)[:, None])])
        for k, t in enumerate(times):
            g = granule_frame(ds, system, k)
            pts = g.pop("points")
            w.write_data(float(t), point_data={"position": pts, "displacement": pts - p0, **g})
            tick()
    files = ["granules.h5", "granules.xdmf"]
    if has_solid(ds, model):
        with _time_series_writer(stage / "solid.xdmf") as w:
            w.write_points_cells(solid_points(model), solid_cells(model))
            for t, u, v, c in solid_frames(ds, model, elastic):
                w.write_data(t, point_data={"displacement": u, "velocity": v}, cell_data={n: [a] for n, a in c.items()})
                tick()
        files += ["solid.h5", "solid.xdmf"]
    return files


def write_extxyz(ds, system, stage: Path, tick: Callable[[], None]) -> list[str]:
    species = [str(m) for m in ds["medium"].values] if "medium" in ds.coords else [lab.split(":")[0] for lab in system.labels]
    n = system.n
    with open(stage / "granules.extxyz", "w", encoding="utf-8") as f:
        for k, t in enumerate(ds["time"].values.astype(float)):
            g = granule_frame(ds, system, k)
            f.write(f"{n}\nProperties={EXTXYZ_PROPERTIES} Time={_fmt(t)} pbc=\"F F F\"\n")
            p, v = g["points"], g["velocity"]
            for i in range(n):
                f.write(" ".join([species[i], *(_fmt(c) for c in p[i]), _fmt(g["radius"][i]), *(_fmt(c) for c in v[i]),
                                  _fmt(g["omega"][i])]) + "\n")
            tick()
    return ["granules.extxyz"]


def _long_csv(path: Path, ds, key: str, names: list[str], columns: list[str]) -> bool:
    """A long-format table: one row per output and `key` entry (granule, wall, contact) the result
    stores (a reduced result's traced granules only); False, and no file, when it stores none."""
    import csv

    if not all(n in ds for n in names):
        return False
    times = ds["time"].values.astype(float)
    labels = [str(s) for s in ds[key].values] if key in ds.coords else []
    data = [ds[n].values.astype(float) for n in names]
    stored = [i for i in range(len(labels)) if not (len(times) and np.isnan(data[0][0, i]))]
    with open(path, "w", newline="", encoding="utf-8") as f:
        out = csv.writer(f)
        out.writerow(["time", key, *columns])
        for k, t in enumerate(times):
            ts = _fmt(t)
            for i in stored:
                out.writerow([ts, labels[i], *(_fmt(d[k, i]) for d in data)])
    return True


def ledger_names(ds) -> list[str]:
    return [n for n, v in ds.data_vars.items()
            if v.dims == ("time",) and (n.startswith(LEDGER_PREFIXES) or n in LEDGER_NAMES)]


def write_csv(ds, stage: Path, tick: Callable[[], None]) -> list[str]:
    import csv

    cols = ["x", "y", "v_x", "v_y", "omega"]
    written = []
    for name, key, names, columns in (
            ("traces.csv", "granule", cols, cols),
            ("walls.csv", "wall", ["wall_force_normal", "wall_force_tangential"], ["normal", "tangential"]),
            ("contacts.csv", "contact", ["contact_force_normal", "contact_force_tangential"], ["normal", "tangential"])):
        if _long_csv(stage / name, ds, key, names, columns):  # what a reduced result left out has no table
            written.append(name)
        tick()
    names = ledger_names(ds)
    data = [ds[n].values.astype(float) for n in names]
    with open(stage / "energies.csv", "w", newline="", encoding="utf-8") as f:
        out = csv.writer(f)
        out.writerow(["time", *names])
        for k, t in enumerate(ds["time"].values.astype(float)):
            out.writerow([_fmt(t), *(_fmt(d[k]) for d in data)])
    tick()
    return [*written, "energies.csv"]


# --------------------------------------------------------------------------------------------


def export_result(ds, out: str | Path, formats: Iterable[str] = FORMATS,
                  progress: Callable[[int, int], None] | None = None, name="result") -> list[Path]:
    """Write the chosen `formats` of result `ds` (named `name` in errors) into folder `out`
    (created if missing); returns the paths written. `progress(done, total)` is called before the
    first and after each frame or table written (`count_steps` of them). OSError when the folder
    cannot be written (what was already moved into place stays)."""
    from ..analysis.result_model import result_solid, result_system

    formats = [f for f in FORMATS if f in set(formats)]
    check_exportable(ds, formats, name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    system, model = result_system(ds, name), result_solid(ds, name)
    total, done = count_steps(ds, model, formats), 0
    progress = progress or (lambda done, total: None)
    progress(0, total)

    def tick():
        nonlocal done
        done += 1
        progress(done, total)

    from ..guard.resources import check_disk

    check_disk(export_size(ds, model, formats), out, f"the export to {out}")
    elastic = elastic_constants(model) if has_solid(ds, model) else (0.0, 0.0)
    stage = staging_folder(out)
    written = []
    try:
        files = []
        if "vtk" in formats:
            files += write_vtk(ds, system, model, elastic, stage, tick)
        if "xdmf" in formats:
            files += write_xdmf(ds, system, model, elastic, stage, tick)
        if "extxyz" in formats:
            files += write_extxyz(ds, system, stage, tick)
        if "csv" in formats:
            files += write_csv(ds, stage, tick)
        # data files before the indexes (.pvd, .xdmf) that name them
        for rel in sorted(files, key=lambda r: r.endswith((".pvd", ".xdmf"))):
            target = out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            fsync_path(stage / rel)
            os.replace(stage / rel, target)
            written.append(target)
        for folder in {t.parent for t in written}:
            fsync_path(folder)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return written


def plan_export(result: Path, out: Path, ds=None):
    """`granel export`'s output folder, checked against its input `result` (a readable file);
    made once `ds` (the result, read) is given. Exit 2 or 4 naming the option or the file."""
    from ..guard.outputs import OutputPlan
    from ..guard.reading import check_file

    check_file(result, "result file")
    plan = OutputPlan(inputs=[result])
    plan.folder(out, "-o", "export", recognise=lambda p: any(p.glob("*.pvd")) or (p / "traces.csv").exists())
    plan.check()
    if ds is not None:
        plan.prepare()
