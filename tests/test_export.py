"""`granel export`: every format read back (meshio for VTU and XDMF, plain parsing for extended XYZ
and CSV) equals the result file (granules) or the solid reconstruction the movies use (plate and
beam nodal displacements, their stress); the stress meets closed forms (a plane-stress patch test,
a beam in pure bending); hostile input gives a clean message and the documented exit code."""

import csv
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest
from typer.testing import CliRunner

from granel.viz.animate import solid_states
from granel.cli import app
from granel.viz.export import EXTXYZ_PROPERTIES, ExportError, elastic_constants, parse_formats, solid_stress
from granel.analysis.result_model import result_solid, result_system
from granel.io.results import read_netcdf
from granel.solid.base import Material, Slab
from granel.solid.beam import build_beam
from granel.solid.plate import LayerSpec, PlateMesh, assemble_plate, plane_stress_forms

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
    # 0.04 ms: the shock's wave has reached the walls and the solid, so that the force tables hold real forces
    res = subprocess.run([sys.executable, "-m", "granel", "run", "paper", "--solid", solid, "--duration", "0.04ms",
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
    model = result_solid(ds)
    Q, V = solid_states(ds, ds["solid_time"].values)
    return model, np.stack([model.full_displacement(q) for q in Q]), np.stack([model.full_displacement(v) for v in V])


# --------------------------------------------------------------------------------------------
# granules


@pytest.mark.parametrize("solid", ["plate", "rigid"])
def test_granules_vtu_round_trip(runs, solid):
    ds, folder = runs[solid]
    system = result_system(ds)
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
    system = result_system(ds)
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
    system = result_system(ds)
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


# --------------------------------------------------------------------------------------------
# the solid's stress

E_STEEL, NU_STEEL, RHO_STEEL = 200e9, 0.3, 7850.0
PLATE_STRESS = ("stress_xx", "stress_yy", "stress_xy", "von_mises")


def test_plate_stress_patch_test():
    """A uniform strain u = exx x, v = eyy y + gxy x imposed on every node of a Q8 plate with rigid
    layers gives, in every cell (the two under each layer included), the plane-stress law
    sigma = E / (1 - nu^2) [[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]] (exx, eyy, gxy) and its
    von Mises stress; the strain energy of the plate's own form is 1/2 sigma . eps per volume."""
    layers = [LayerSpec("A", "left", 0.05, 1e-3), LayerSpec("B", "right", 0.04, 5e-4)]
    h = 1e-3
    m = assemble_plate(Slab(0.0, 0.0, 0.01, 0.1, h), Material(E_STEEL, RHO_STEEL, NU_STEEL), layers, PlateMesh(4, 2.0, 5e-3))
    assert m.info["rigid_layers"]
    # the cells under a layer: three of their nodes on the layer's edge segment
    X, Y = m.nodes.T
    on_layer = np.zeros(len(X), bool)
    for lay in layers:
        on_layer |= (np.abs(X - (0.0 if lay.edge == "left" else 0.01)) < 1e-12) & (np.abs(Y - lay.y) <= lay.length / 2 + 1e-12)
    under = on_layer[m.elements].sum(axis=1) == 3
    assert under.sum() == 2 * len(layers)
    D = E_STEEL / (1 - NU_STEEL**2) * np.array([[1, NU_STEEL, 0], [NU_STEEL, 1, 0], [0, 0, (1 - NU_STEEL) / 2]])
    strain_energy = plane_stress_forms(E_STEEL, NU_STEEL, RHO_STEEL, h)[2]
    for exx, eyy, gxy in ((1e-4, -3e-4, 2e-4), (-2e-5, 5e-5, -7e-5)):
        x = np.zeros(m.T.shape[0])
        x[m.node_dofs[0]] = exx * X
        x[m.node_dofs[1]] = eyy * Y + gxy * X
        s = solid_stress(m, E_STEEL, NU_STEEL, x)
        assert sorted(s) == sorted(PLATE_STRESS) and all(a.shape == (m.nelements,) for a in s.values())
        sxx, syy, sxy = D @ [exx, eyy, gxy]
        vm = np.sqrt(sxx**2 - sxx * syy + syy**2 + 3 * sxy**2)
        for name, want in zip(PLATE_STRESS, (sxx, syy, sxy, vm)):
            np.testing.assert_allclose(s[name], want, rtol=1e-9, atol=0, err_msg=name)
        w = strain_energy.elemental(m.basis, u=m.basis.interpolate(x))
        np.testing.assert_allclose(w, 0.5 * (sxx * exx + syy * eyy + sxy * gxy) * m.element_volume, rtol=1e-9, atol=0)


def test_beam_bending_stress_pure_bending():
    """w = a y^2 (rotations 2 a y) on every node: the outer-fibre stress E (h/2) |2a| in every
    element, h the section depth (the beam's width); a rigid motion w = b + c y: no stress."""
    W, L, H = 0.01, 0.1, 0.001
    beam = build_beam(Slab(0.0, 0.02, W, L, H), Material(E_STEEL, RHO_STEEL, 0.3), [("c", "left", 0.07)], 40)
    y = beam.nodes[:, 1]
    for a in (0.37, -2.5):
        x = np.zeros(beam.T.shape[0])
        x[0::2], x[1::2] = a * y**2, 2 * a * y
        s = solid_stress(beam, E_STEEL, NU_STEEL, x)
        assert list(s) == ["bending_stress"] and s["bending_stress"].shape == (beam.nelements,)
        np.testing.assert_allclose(s["bending_stress"], E_STEEL * W / 2 * abs(2 * a), rtol=1e-9, atol=0)
    x[0::2], x[1::2] = 3e-4 + 0.02 * y, 0.02
    assert np.all(solid_stress(beam, E_STEEL, NU_STEEL, x)["bending_stress"] == 0)


def solid_outputs(ds):
    n = ds.sizes["solid_time"]
    return sorted({0, n // 2, n - 1})


@pytest.mark.parametrize("solid,names", [("plate", PLATE_STRESS), ("beam", ("bending_stress",))])
def test_solid_stress_round_trip(runs, solid, names):
    """The stress read back from the VTU series and the XDMF file equals `solid_stress` on the
    movies' reconstruction of the same output."""
    ds, folder = runs[solid]
    model = result_solid(ds)
    ks = solid_outputs(ds)
    Q, _ = solid_states(ds, ds["solid_time"].values[ks])
    want = [solid_stress(model, *elastic_constants(model), model.T @ q) for q in Q]
    assert max(np.abs(w[names[0]]).max() for w in want) > 0  # the shock has loaded the solid
    entries = pvd_entries(folder / "solid.pvd")
    with meshio.xdmf.TimeSeriesReader(folder / "solid.xdmf") as r:
        r.read_points_cells()
        for k, w in zip(ks, want):
            vtu = meshio.read(folder / entries[k][1]).cell_data
            _, _, xdmf = r.read_data(k)
            for name in names:
                close(vtu[name][0], w[name])
                close(xdmf[name][0], w[name])


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
    assert np.abs(ds["wall_force_normal"].values).max() > 0 and np.abs(ds["contact_force_normal"].values).max() > 1e-3
    head, rows = read_csv(folder / "energies.csv")
    assert head[0] == "time" and {"energy_solid", "input_work", "balance_error", "dissipated_viscous"} <= set(head)
    assert all(ds[h].dims == ("time",) for h in head[1:])
    for j, name in enumerate(head):
        close([float(r[j]) for r in rows], ds[name].values)


def test_no_staging_left_and_other_files_kept(runs):
    _, folder = runs["plate"]
    from granel.guard.owners import STAMP

    assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == [STAMP]  # the folder's owner, no staging


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


def test_a_folder_of_the_users_files_is_refused(runs, tmp_path):
    """An output folder that holds files granel did not write is refused before anything is
    written (issue 28): the user's file is untouched and nothing is added."""
    folder = tmp_path / "shared"
    folder.mkdir()
    (folder / "mine.txt").write_text("keep me")
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", folder, "--format", "csv"])
    assert code == 2 and "mine.txt" in out and "did not write" in out, out
    assert (folder / "mine.txt").read_text() == "keep me"
    assert sorted(p.name for p in folder.iterdir()) == ["mine.txt"]


def test_a_rerun_replaces_its_own_export(runs, tmp_path):
    nc = runs["rigid"][1].parent / "rigid.nc"
    for _ in range(2):
        code, out = invoke(["export", nc, "-o", tmp_path / "again", "--format", "csv"])
        assert code == 0, out
    assert sorted(p.name for p in (tmp_path / "again").iterdir() if not p.name.startswith(".")) == \
        ["contacts.csv", "energies.csv", "traces.csv", "walls.csv"]


def test_foreign_netcdf_exits_2(tmp_path):
    """A NetCDF file that reads but is not a result is refused as bad content (exit 2)."""
    import xarray as xr

    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"temperature": ("x", np.arange(3.0))}).to_netcdf(foreign, engine="h5netcdf")
    code, out = invoke(["export", foreign, "-o", tmp_path / "out"])
    assert code == 2 and "foreign.nc" in out and "not a granel result" in out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc, where no folder can be made")
def test_unwritable_out_exits_4(runs):
    nc = runs["rigid"][1].parent / "rigid.nc"
    code, out = invoke(["export", nc, "-o", "/proc/granel-export-test", "--format", "csv"])
    assert code == 4 and "/proc/granel-export-test" in out
