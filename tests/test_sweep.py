"""Parameter sweeps on dask.distributed: equality with serial runs, resume, failures, the
symmetric control, and a real scheduler + worker started as separate processes."""

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from granel import scenario as S
from granel.studies.sweep import case_overrides, cases, load_sweep, run_case, run_sweep

SWEEP = """
name = "t"
base = "paper"
overrides = ['simulation.duration="0.2ms"', 'solid.kind="beam"', 'excitations.0.shock="strong"']
[[axes]]
field = "excitations.0.fmax"
values = [500.0, 1591.6]
[[axes]]
field = "media.1.radius"
values = [{radii}]
"""


def write_sweep(tmp_path, radii="0.005, 0.01"):
    p = tmp_path / "s.toml"
    p.write_text(SWEEP.format(radii=radii))
    return p


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sweep")
    path = write_sweep(tmp)
    ds = run_sweep(path, tmp / "out", workers=2)
    return tmp, path, ds


def test_sweep_equals_serial_runs(swept, tmp_path):
    tmp, path, ds = swept
    spec, base = load_sweep(path)
    assert ds["nonreciprocity_index"].shape == (2, 2)
    assert (ds["status"].values == "ok").all()
    for c in cases(spec):
        r = run_case(spec.model_dump_json(), str(base), c, str(tmp_path))
        for k, v in r["metrics"].items():
            got = float(ds[k].values[tuple(c["index"])])
            assert got == v or (np.isnan(got) and np.isnan(v)), (c["tag"], k)


def test_symmetric_control_is_reciprocal(swept):
    _, _, ds = swept
    nri = ds["nonreciprocity_index"]
    control = nri.sel(media_1_radius=0.01).values
    paper = nri.sel(media_1_radius=0.005).values
    assert np.all(control < 1e-6)  # mirror-symmetric interface: reciprocal by construction
    assert np.all(paper > 0.05)  # the paper's asymmetric interface


def test_resume_runs_only_missing_cases(swept):
    tmp, path, _ = swept
    out = tmp / "out" / "cases"
    jsons = sorted(out.glob("*.json"))
    assert len(jsons) == 4
    gone = jsons[:2]
    for j in gone:
        j.unlink()
        for nc in out.glob(j.stem + "__*.nc"):
            nc.unlink()
    kept = {j: j.stat().st_mtime_ns for j in jsons[2:]}
    time.sleep(0.05)
    ds = run_sweep(path, tmp / "out", workers=1)
    assert (ds["status"].values == "ok").all()
    for j, m in kept.items():
        assert j.stat().st_mtime_ns == m  # untouched
    for j in gone:
        assert j.exists()


def test_failing_case_is_recorded(tmp_path):
    # 0.006 m puts the SSGM contact heights off the beam's nodes: that case must fail alone
    path = write_sweep(tmp_path, radii="0.005, 0.006")
    ds = run_sweep(path, tmp_path / "out", workers=2)
    st = ds["status"].sel(media_1_radius=0.006).values
    assert all(s.startswith("error") and "not on a node" in s for s in st)
    assert (ds["status"].sel(media_1_radius=0.005).values == "ok").all()
    assert np.isnan(ds["nonreciprocity_index"].sel(media_1_radius=0.006).values).all()
    assert (tmp_path / "out" / "summary.nc").exists()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow  # a scheduler and a worker in their own processes (about 11 s)
def test_external_scheduler_and_worker(tmp_path):
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    bindir = Path(sys.executable).parent
    dask = str(bindir / "dask")
    env = dict(os.environ)
    sched = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = None
    try:
        time.sleep(2.0)
        worker = subprocess.Popen([dask, "worker", addr, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        path = tmp_path / "s.toml"
        path.write_text(SWEEP.format(radii="0.005").replace("values = [500.0, 1591.6]", "values = [1591.6]"))
        from dask.distributed import Client

        with Client(addr, timeout=30) as c:
            c.wait_for_workers(1, timeout=60)
        ds = run_sweep(path, tmp_path / "out", scheduler=addr)
        assert (ds["status"].values == "ok").all()
        assert float(ds["nonreciprocity_index"].values.ravel()[0]) > 0.05
    finally:
        for p in (worker, sched):
            if p is not None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()


def test_map_command(swept, tmp_path):
    from typer.testing import CliRunner

    from granel.cli import app

    tmp, _, _ = swept
    res = CliRunner().invoke(app, ["map", str(tmp / "out" / "summary.nc"), "-o", str(tmp_path / "m.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "m.png").stat().st_size > 10_000
    res = CliRunner().invoke(app, ["map", str(tmp / "out" / "summary.nc"), "-o", str(tmp_path / "m2.png"), "--metric", "nope"])
    assert res.exit_code == 2 and "unknown metric" in res.output


def test_invalid_sweep_file(tmp_path):
    from granel.scenario import ScenarioError

    p = tmp_path / "bad.toml"
    p.write_text('name = "x"\n[[axes]]\nfield = "contact.mu"\n')
    with pytest.raises(ScenarioError, match="exactly one of"):
        load_sweep(p)


@pytest.mark.parametrize("value", ["steel", 'say "hi"', True, 3, 0.1, 1e-300, [1.0, 2.0], ["a", "b"]])
def test_a_case_value_reads_back_as_itself(value):
    """A case's axis value becomes an override (`scenario.override`) that the scenario reads back
    as that value; "-" sets nothing."""
    ov = case_overrides({"overrides": {"a.b": value, "a.c": "-"}})
    assert S.apply_overrides({"a": {}}, ov) == {"a": {"b": value}}
