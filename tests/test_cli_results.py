"""The command line, result files and checkpoint/resume."""

import json
import os

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app
from granel.io.results import read_netcdf
from granel.run import run_scenario

runner = CliRunner()


def test_run_writes_netcdf_and_summary(tmp_path):
    out = tmp_path / "r.nc"
    res = runner.invoke(app, ["run", "paper", "--solid", "rigid", "--excite", "SSGM:C", "--shock", "weak",
                              "--duration", "0.05ms", "-o", str(out), "--json-summary"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout[res.stdout.index("{"): res.stdout.rindex("}") + 1])
    assert summary["max_balance_error_rel"] < 1e-6
    ds = read_netcdf(out)
    assert summary["steps"] == ds.attrs["solver_steps"] == ds.sizes["step"] > 0
    assert ds.sizes["granule"] == 28 and ds.sizes["time"] == 51
    assert list(ds["granule"].values[:3]) == ["LSGM:1", "LSGM:2", "LSGM:3"]
    for v in ("x", "y", "theta", "v_x", "v_y", "omega", "energy_lsgm", "energy_ssgm", "energy_solid",
              "dissipated_viscous", "dissipated_friction", "input_work", "balance_error"):
        assert v in ds, v
    assert "SSGM:C" in ds.attrs["scenario"] and 'shock = "weak"' in ds.attrs["scenario"]
    assert ds.attrs["granel_version"]
    # the weak shock: J = 2 Fmax tau / pi on granule C
    assert float(ds["input_work"][-1]) > 0
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_bad_input_exits_with_named_field(tmp_path):
    res = runner.invoke(app, ["run", "paper", "--solid", "rigid", "--set", "media.0.radius=-1", "-o", str(tmp_path / "x.nc")])
    assert res.exit_code == 2
    assert "media.0.radius" in res.output
    res = runner.invoke(app, ["run", "paper", "--excite", "SSGM:Z", "-o", str(tmp_path / "x.nc")])
    assert res.exit_code == 2 and "SSGM:Z" in res.output
    res = runner.invoke(app, ["run", "paper", "--shock", "apocalyptic"])
    assert res.exit_code == 2
    assert not (tmp_path / "x.nc").exists()


def test_fmax_and_scenarios_and_show(tmp_path):
    res = runner.invoke(app, ["run", "paper", "--solid", "rigid", "--shock", "100", "--duration", "2us", "-o", str(tmp_path / "f.nc")])
    assert res.exit_code == 0, res.output
    assert "fmax = 100.0" in read_netcdf(tmp_path / "f.nc").attrs["scenario"]
    res = runner.invoke(app, ["scenarios"])
    assert res.exit_code == 0 and "paper" in res.output
    res = runner.invoke(app, ["show", "paper", "-o", str(tmp_path / "g.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "g.png").stat().st_size > 20_000


class Killed(Exception):
    pass


def test_resume_gives_the_uninterrupted_result(tmp_path):
    """A run killed after a checkpoint and resumed from it gives the same arrays, bit for bit;
    a checkpoint of another scenario is refused."""
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', 'simulation.duration="0.1ms"',
                          'simulation.checkpoint_every="0.02ms"'])
    full = run_scenario(sc)
    ck = tmp_path / "run.ckpt"

    def killer(t):
        if t > 0.063e-3:
            raise Killed

    with pytest.raises(Killed):
        run_scenario(sc, killer, ck)
    assert ck.exists()
    resumed = run_scenario(sc, None, ck, ck)
    assert resumed.sizes["time"] == full.sizes["time"] == 101
    for v in ("v_x", "balance_error", "contact_force_normal", "step_dt"):
        assert np.array_equal(resumed[v].values, full[v].values), v
    other = S.load("paper", ['solid.kind="rigid"', 'simulation.duration="0.1ms"', 'simulation.checkpoint_every="0.02ms"'])
    with pytest.raises(RuntimeError, match="different scenario"):
        run_scenario(other, None, ck, ck)


def test_modes_command_json_and_plot(tmp_path):
    res = runner.invoke(app, ["modes", "--solid", "beam", "--json", "--count", "5"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["dofs"] == 78 and out["elements"] == 40 and out["kinds"] == ["bending"] * 5
    assert out["periods_ms"][0] == pytest.approx(0.192735, rel=1e-4)
    res = runner.invoke(app, ["modes", "--solid", "plate", "--json", "--count", "7", "--plot", str(tmp_path / "m.png")])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout[: res.stdout.rindex("}") + 1])
    assert out["kinds"][3] == "axial" and out["kinds"][6] == "bulk"
    assert (tmp_path / "m.png").stat().st_size > 50_000
    res = runner.invoke(app, ["modes", "--solid", "rigid"])
    assert res.exit_code == 2


def test_animate_command(tmp_path):
    out = tmp_path / "r.nc"
    res = runner.invoke(app, ["run", "paper", "--solid", "beam", "--excite", "SSGM:C", "--duration", "0.01ms", "-o", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["animate", str(out), "-o", str(tmp_path / "m.mp4"), "--frames", "3", "--field", "energy-density"])
    assert res.exit_code == 0, res.output
    import imageio.v3 as iio

    assert iio.imread(tmp_path / "m.mp4").shape[0] == 3
    res = runner.invoke(app, ["animate", str(out), "--field", "sound"])
    assert res.exit_code == 2


def test_the_result_file_written_without_xarray_is_xarrays():
    """`granel run` writes its NetCDF from the result's variables with h5netcdf alone; read back,
    the file is identical (values, dtypes, coordinates, attributes) to the one xarray writes from
    the Dataset of the same variables."""
    import tempfile

    from granel.io.results import write_netcdf, write_spec_netcdf

    for solid in ("plate", "rigid"):
        spec = run_scenario(S.load("paper", [f'solid.kind="{solid}"', 'simulation.duration="3us"']), dataset=False)
        with tempfile.TemporaryDirectory() as d:
            a, b = write_spec_netcdf(spec, f"{d}/a.nc"), write_netcdf(spec.to_dataset(), f"{d}/b.nc")
            da, db = read_netcdf(a), read_netcdf(b)
        xr.testing.assert_identical(da, db)
        assert all(da[v].dtype == db[v].dtype for v in da.variables)


def test_the_command_line_imports_no_heavy_library_before_a_command_needs_it():
    """`import granel.cli` (what every command pays before it starts) imports none of xarray,
    pandas, h5netcdf, h5py, dask, distributed, optuna, matplotlib, scikit-fem or scipy.spatial."""
    import subprocess
    import sys

    heavy = ("xarray", "pandas", "h5netcdf", "h5py", "dask", "distributed", "optuna", "matplotlib", "skfem",
             "scipy.spatial")
    code = f"import sys, granel.cli\nprint(sorted(m for m in {heavy!r} if sys.modules.get(m) is not None))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_a_fresh_run_imports_only_what_it_needs(tmp_path):
    """A fresh `granel run` of a plate case (its assembly cached by an earlier run) imports
    neither xarray and pandas (the result is written with h5netcdf), nor scikit-fem, matplotlib,
    dask, optuna or scipy.spatial (a scenario's lattice pairs are found directly)."""
    import subprocess
    import sys

    code = ("import runpy, sys; sys.argv = ['granel', 'run', 'paper', '--duration', '2us', '-o', sys.argv[1]]\n"
            "try:\n    runpy.run_module('granel', run_name='__main__')\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
            "print(sorted(m for m in ('xarray', 'pandas', 'skfem', 'matplotlib', 'dask', 'distributed', 'optuna', "
            "'scipy.spatial') "
            "if sys.modules.get(m) is not None))")
    for k in range(2):  # the first may assemble the plate (and cache it)
        out = subprocess.run([sys.executable, "-c", code, str(tmp_path / f"r{k}.nc")], capture_output=True, text=True,
                             check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout
