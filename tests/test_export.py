"""`granel export`: every format read back (meshio for VTU and XDMF, plain parsing for extended XYZ
and CSV) equals the result file (granules) or the solid reconstruction the movies use (plate and
beam nodal displacements); hostile input gives a clean message and the documented exit code."""

import csv
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest
from typer.testing import CliRunner

from granel.animate import solid_states
from granel.cli import app
from granel.export import EXTXYZ_PROPERTIES, ExportError, parse_formats
from granel.figures import model_of
from granel.results import read_netcdf

runner = CliRunner()
RTOL = 1e-12


def invoke(args):
    res = runner.invoke(app, [str(a) for a in args])
    out = " ".join(res.output.split())
    assert "Traceback" not in res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), repr(res.exception)
    return res.exit_code, out


def close(a, b):
    np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=RTOL, atol=0)


def _run(path, solid):
    # in a subprocess: `run` marks dask absent in its process (see cli._without_dask)
    res = subprocess.run([sys.executable, "-m", "granel", "run", "paper", "--solid", solid, "--duration", "0.01ms",
                          "-o", str(path)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Results of short plate, beam and rigid runs, each exported (plate and beam: all formats)."""
    d = tmp_path_factory.mktemp("export")
    out = {}
    for solid in ("plate", "beam", "rigid"):
        nc = d / f"{solid}.nc"
        _run(nc, solid)
        folder = d / f"{solid}-out"
        args = ["export", nc, "-o", folder] + (["--format", "vtk", "--format", "csv"] if solid == "rigid" else [])
        code, msg = invoke(args)
        assert code == 0, msg
        out[solid] = (read_netcdf(nc), folder)
    return out


def outputs(ds):
    n = ds.sizes["time"]
    return sorted({0, n // 2, n - 1})


def pvd_entries(path):
    return [(float(e.get("timestep")), e.get("file")) for e in ET.parse(path).getroot().iter("DataSet")]


def reconstruction(ds):
    """The nodal displacement and velocity at every stored solid output, as the movies compute them."""
    model = model_of(ds)[2]
    Q, V = solid_states(ds, ds["solid_time"].values)
    return model, np.stack([model.full_displacement(q) for q in Q]), np.stack([model.full_displacement(v) for v in V])


# --------------------------------------------------------------------------------------------
# granules


@pytest.mark.parametrize("solid", ["plate", "rigid"])
def test_granules_vtu_round_trip(runs, solid):
    ds, folder = runs[solid]
    system = model_of(ds)[1]
    entries = pvd_entries(folder / "granules.pvd")
    close([t for t, _ in entries], ds["time"].values)
    for k in outputs(ds):
        m = meshio.read(folder / entries[k][1])
        assert m.points.dtype == np.float64
        close(m.points[:, 0], ds["x"].values[k])
        close(m.points[:, 1], ds["y"].values[k])
        assert np.all(m.points[:, 2] == 0)
        close(m.point_data["radius"], system.radius)
        close(m.point_data["velocity"][:, 0], ds["v_x"].values[k])
        close(m.point_data["velocity"][:, 1], ds["v_y"].values[k])
        close(m.point_data["omega"], ds["omega"].values[k])
        kin = 0.5 * system.mass * (ds["v_x"].values[k] ** 2 + ds["v_y"].values[k] ** 2) + 0.5 * system.inertia * ds["omega"].values[k] ** 2
        close(m.point_data["kinetic_energy"], kin)
        assert m.cells[0].type == "vertex" and len(m.cells[0].data) == ds.sizes["granule"]


def test_granules_xdmf_round_trip(runs):
    ds, folder = runs["plate"]
    system = model_of(ds)[1]
    with meshio.xdmf.TimeSeriesReader(folder / "granules.xdmf") as r:
        points, _ = r.read_points_cells()
        close(points[:, 0], ds["x"].values[0])
        assert r.num_steps == ds.sizes["time"]
        for k in outputs(ds):
            t, pd, _ = r.read_data(k)
            close(t, ds["time"].values[k])
            close(pd["position"][:, 0], ds["x"].values[k])
            close(pd["position"][:, 1], ds["y"].values[k])
            close(pd["displacement"][:, 1], ds["y"].values[k] - ds["y"].values[0])
            close(pd["velocity"][:, 0], ds["v_x"].values[k])
            close(pd["velocity"][:, 1], ds["v_y"].values[k])
            close(pd["radius"], system.radius)
            close(pd["omega"], ds["omega"].values[k])


def read_extxyz(path):
    frames = []
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        n = int(lines[i])
        comment = lines[i + 1]
        props = re.search(r"Properties=(\S+)", comment).group(1)
        t = float(re.search(r"Time=(\S+)", comment).group(1))
        rows = [ln.split() for ln in lines[i + 2: i + 2 + n]]
        frames.append((props, t, [r[0] for r in rows], np.array([[float(v) for v in r[1:]] for r in rows])))
        i += 2 + n
    return frames


def test_extxyz_round_trip(runs):
    ds, folder = runs["plate"]
    system = model_of(ds)[1]
    frames = read_extxyz(folder / "granules.extxyz")
    assert len(frames) == ds.sizes["time"]
    for k in outputs(ds):
        props, t, species, a = frames[k]
        assert props == EXTXYZ_PROPERTIES
        close(t, ds["time"].values[k])
        assert species == [str(m) for m in ds["medium"].values]
        close(a[:, 0], ds["x"].values[k])
        close(a[:, 1], ds["y"].values[k])
        assert np.all(a[:, 2] == 0)
        close(a[:, 3], system.radius)
        close(a[:, 4], ds["v_x"].values[k])
        close(a[:, 5], ds["v_y"].values[k])
        close(a[:, 7], ds["omega"].values[k])


# --------------------------------------------------------------------------------------------
# the solid


@pytest.mark.parametrize("solid,cell", [("plate", "quad8"), ("beam", "line")])
def test_solid_vtu_round_trip(runs, solid, cell):
    ds, folder = runs[solid]
    model, U, V = reconstruction(ds)
    assert np.abs(U).max() > 0  # the shock has reached the solid
    entries = pvd_entries(folder / "solid.pvd")
    close([t for t, _ in entries], ds["solid_time"].values)
    for k in outputs(ds):
        m = meshio.read(folder / entries[k][1])
        close(m.points[:, :2], model.nodes)
        assert m.cells[0].type == cell
        assert np.array_equal(m.cells[0].data, model.elements)
        close(m.point_data["displacement"][:, :2], U[k])
        close(m.point_data["velocity"][:, :2], V[k])
        assert m.cell_data["energy_density"][0].shape == (model.nelements,)


@pytest.mark.parametrize("solid", ["plate", "beam"])
def test_solid_xdmf_round_trip(runs, solid):
    ds, folder = runs[solid]
    model, U, V = reconstruction(ds)
    with meshio.xdmf.TimeSeriesReader(folder / "solid.xdmf") as r:
        points, cells = r.read_points_cells()
        close(points[:, :2], model.nodes)
        assert np.array_equal(cells[0].data, model.elements)
        for k in outputs(ds):
            t, pd, _ = r.read_data(k)
            close(t, ds["solid_time"].values[k])
            close(pd["displacement"][:, :2], U[k])
            close(pd["velocity"][:, :2], V[k])


def test_rigid_solid_has_no_solid_files(runs):
    _, folder = runs["rigid"]
    assert not (folder / "solid.pvd").exists() and not (folder / "solid").exists()
    assert not (folder / "granules.xdmf").exists() and not (folder / "granules.extxyz").exists()  # not asked for
    assert (folder / "traces.csv").exists()


# --------------------------------------------------------------------------------------------
# CSV


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


@pytest.mark.parametrize("solid", ["plate", "rigid"])
def test_csv_round_trip(runs, solid):
    ds, folder = runs[solid]
    nt, n = ds.sizes["time"], ds.sizes["granule"]
    head, rows = read_csv(folder / "traces.csv")
    assert head == ["time", "granule", "x", "y", "v_x", "v_y", "omega"]
    assert len(rows) == nt * n
    close([float(r[0]) for r in rows], np.repeat(ds["time"].values, n))
    assert [r[1] for r in rows[:n]] == [str(g) for g in ds["granule"].values]
    for j, name in enumerate(head[2:]):
        close([float(r[2 + j]) for r in rows], ds[name].values.ravel())
    for table, key, prefix in (("walls", "wall", "wall_force"), ("contacts", "contact", "contact_force")):
        head, rows = read_csv(folder / f"{table}.csv")
        assert head == ["time", key, "normal", "tangential"]
        m = ds.sizes[key]
        assert len(rows) == nt * m and [r[1] for r in rows[:m]] == [str(w) for w in ds[key].values]
        close([float(r[2]) for r in rows], ds[f"{prefix}_normal"].values.ravel())
        close([float(r[3]) for r in rows], ds[f"{prefix}_tangential"].values.ravel())
    assert np.abs(ds["wall_force_normal"].values).max() > 0
    head, rows = read_csv(folder / "energies.csv")
    assert head[0] == "time" and {"energy_solid", "input_work", "balance_error", "dissipated_viscous"} <= set(head)
    assert all(ds[h].dims == ("time",) for h in head[1:])
    for j, name in enumerate(head):
        close([float(r[j]) for r in rows], ds[name].values)


def test_no_staging_left_and_other_files_kept(runs):
    _, folder = runs["plate"]
    assert not [p for p in folder.iterdir() if p.name.startswith(".")]


# --------------------------------------------------------------------------------------------
# options and hostile input


def test_parse_formats():
    assert parse_formats(None) == ["vtk", "xdmf", "csv", "extxyz"]
    assert parse_formats(["csv", "VTK"]) == ["vtk", "csv"]
    assert parse_formats(["extxyz,csv"]) == ["csv", "extxyz"]
    with pytest.raises(ExportError):
        parse_formats(["stl"])


def test_not_netcdf_exits_4(tmp_path):
    bad = tmp_path / "notes.nc"
    bad.write_text("this is not NetCDF\n")
    code, out = invoke(["export", bad, "-o", tmp_path / "out"])
    assert code == 4 and "notes.nc" in out
    assert not (tmp_path / "out").exists()


def test_unknown_format_exits_2(runs, tmp_path):
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", tmp_path / "out", "--format", "stl"])
    assert code == 2 and "stl" in out and "vtk" in out
    assert not (tmp_path / "out").exists()


def test_missing_result_exits_2(tmp_path):
    code, out = invoke(["export", tmp_path / "missing.nc", "-o", tmp_path / "out"])
    assert code == 2 and "missing.nc" in out and "no such file" in out


def test_out_is_a_file(runs, tmp_path):
    target = tmp_path / "taken"
    target.write_text("keep me")
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", target, "--format", "csv"])
    assert code in (2, 4) and "taken" in out and "not a folder" in out
    assert target.read_text() == "keep me"


def test_existing_files_in_out_are_kept(runs, tmp_path):
    folder = tmp_path / "shared"
    folder.mkdir()
    (folder / "mine.txt").write_text("keep me")
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", folder, "--format", "csv"])
    assert code == 0, out
    assert (folder / "mine.txt").read_text() == "keep me"
    assert sorted(p.name for p in folder.iterdir()) == ["contacts.csv", "energies.csv", "mine.txt", "traces.csv", "walls.csv"]


def test_foreign_netcdf_exits_4(tmp_path):
    import xarray as xr

    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"temperature": ("x", np.arange(3.0))}).to_netcdf(foreign, engine="h5netcdf")
    code, out = invoke(["export", foreign, "-o", tmp_path / "out"])
    assert code == 4 and "foreign.nc" in out and "not a granel result" in out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc, where no folder can be made")
def test_unwritable_out_exits_4(runs):
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", "/proc/granel-export-test", "--format", "csv"])
    assert code == 4 and "/proc/granel-export-test" in out
