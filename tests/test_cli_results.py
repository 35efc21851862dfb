"""The command line, result files and checkpoint/resume."""

import json
import os

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app
from granel.coupling.rigid import simulate_rigid
from granel.checkpoint import fingerprint
from granel.granular.system import Stepper
from granel.results import read_netcdf

runner = CliRunner()


def test_run_writes_netcdf_and_summary(tmp_path):
    out = tmp_path / "r.nc"
    res = runner.invoke(app, ["run", "paper", "--solid", "rigid", "--excite", "SSGM:C", "--shock", "weak",
                              "--duration", "0.05ms", "-o", str(out), "--json-summary"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout[res.stdout.index("{"): res.stdout.rindex("}") + 1])
    assert summary["steps"] == 1250
    assert summary["max_balance_error_rel"] < 1e-6
    ds = read_netcdf(out)
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
    res = runner.invoke(app, ["run", "paper", "--solid", "rigid", "--fmax", "100", "--duration", "2us", "-o", str(tmp_path / "f.nc")])
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
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', 'simulation.duration="0.1ms"'])
    fp = fingerprint(S.to_toml(sc))

    def fresh():
        system, state, _ = S.build_granular(sc)
        return Stepper(system), state

    stepper, state = fresh()
    full = simulate_rigid(stepper, state, 1e-4, 4e-8, 1e-6)

    ck = tmp_path / "run.ckpt"

    def killer(t, steps):
        if t > 0.063e-3:
            raise Killed

    stepper, state = fresh()
    with pytest.raises(Killed):
        simulate_rigid(stepper, state, 1e-4, 4e-8, 1e-6, killer, ck, 2e-5, None, fp)
    assert ck.exists()
    stepper, state = fresh()
    resumed = simulate_rigid(stepper, state, 1e-4, 4e-8, 1e-6, None, ck, 2e-5, ck, fp)
    assert len(resumed.times) == len(full.times) == 101
    assert np.array_equal(np.array(resumed.rec["vel"]), np.array(full.rec["vel"]))
    assert np.array_equal(np.array(resumed.rec["balance_error"]), np.array(full.rec["balance_error"]))
    with pytest.raises(RuntimeError, match="different scenario"):
        simulate_rigid(stepper, state, 1e-4, 4e-8, 1e-6, None, ck, 2e-5, ck, "other")


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
