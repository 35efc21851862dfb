"""The secondary commands on hostile input: `animate`, `map`, `sweep` and checkpoint loading give
a clean message naming the option or the file and the documented exit code (2 input or usage,
3 numerical or physical stop or failed cases, 4 a file that cannot be read or written), never a
traceback; sweep caches are reused only under a matching fingerprint; arrivals are relative to
the input."""

import json
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app
from granel.io.results import read_netcdf, write_netcdf

runner = CliRunner()

RIGID = ['solid.kind="rigid"', 'simulation.duration="0.005ms"']


def invoke(args):
    res = runner.invoke(app, [str(a) for a in args])
    out = " ".join(res.output.split())  # rich wraps long messages: compare with single spaces
    assert "Traceback" not in res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), repr(res.exception)
    return res.exit_code, out


# --------------------------------------------------------------------------------------------
# hostile files


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One small result (a 0.005 ms rigid run, written by `granel run`) and files that are not one."""
    d = tmp_path_factory.mktemp("hostile")
    good = d / "good.nc"
    # in a subprocess: `run` marks dask absent in its process (see cli._without_dask)
    res = subprocess.run([sys.executable, "-m", "granel", "run", "paper", "--solid", "rigid", "--duration", "0.005ms",
                          "-o", str(good)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    raw = good.read_bytes()
    f = {"good": good}
    f["text"] = d / "text.nc"
    f["text"].write_text("this is not NetCDF\n")
    f["empty"] = d / "empty.nc"
    f["empty"].write_bytes(b"")
    f["truncated"] = d / "truncated.nc"
    f["truncated"].write_bytes(raw[: len(raw) // 2])
    f["foreign"] = d / "foreign.nc"
    xr.Dataset({"temperature": ("x", np.arange(3.0))}).to_netcdf(f["foreign"], engine="h5netcdf")
    f["directory"] = d / "directory.nc"
    f["directory"].mkdir()
    ds = read_netcdf(good)
    bad = ds.copy()
    bad.attrs["scenario"] = "this = is [ not toml"
    f["badscenario"] = write_netcdf(bad, d / "badscenario.nc")
    f["fewer"] = write_netcdf(ds.isel(granule=slice(0, 5)), d / "fewer.nc")
    f["missing"] = d / "missing.nc"
    return f


# files that cannot be read as NetCDF (exit 4), and NetCDF files that are not what the command takes (exit 2)
UNREADABLE = ["text", "empty", "truncated", "directory"]
FOREIGN = ["foreign"]


@pytest.mark.parametrize("kind", UNREADABLE + FOREIGN + ["badscenario", "fewer"])
def test_animate_unusable_result_exits_4_or_2(files, tmp_path, kind):
    code, out = invoke(["animate", files[kind], "-o", tmp_path / "m.gif", "--frames", "2"])
    assert code == (4 if kind in UNREADABLE else 2), out
    assert f"error: {files[kind].name}" in out or files[kind].name in out
    assert not (tmp_path / "m.gif").exists()


def test_animate_missing_result_exits_2(files, tmp_path):
    code, out = invoke(["animate", files["missing"], "-o", tmp_path / "m.gif"])
    assert code == 2 and "missing.nc" in out and "no such file" in out


@pytest.mark.parametrize("option,value", [
    ("--fps", "0"), ("--fps", "-3"), ("--fps", "nan"), ("--fps", "fast"), ("--fps", "1000000"),
    ("--frames", "0"), ("--frames", "-1"), ("--frames", "many"),
    ("--magnification", "nan"), ("--magnification", "-2"), ("--magnification", "0"), ("--magnification", "inf"),
    ("--magnification", "big"),
    ("--field", "sound"),
])
def test_animate_bad_option_exits_2_before_reading(files, tmp_path, option, value):
    # the options are checked first: even with an unreadable result the option is what is reported
    code, out = invoke(["animate", files["truncated"], "-o", tmp_path / "m.gif", option, value])
    assert code == 2, out
    assert option in out


@pytest.mark.parametrize("output,code", [("movie.txt", 2), ("adir.gif", 2), ("afile/movie.gif", 2)])
def test_animate_bad_output(files, tmp_path, output, code):
    (tmp_path / "adir.gif").mkdir()
    (tmp_path / "afile").write_text("a file where a directory is expected")
    got, out = invoke(["animate", files["good"], "-o", tmp_path / output, "--frames", "2", "--fps", "5"])
    assert got == code, out
    assert "--output" in out


def test_animate_good_result_still_works(files, tmp_path):
    code, out = invoke(["animate", files["good"], "-o", tmp_path / "m.gif", "--frames", "2", "--fps", "5"])
    assert code == 0, out
    assert (tmp_path / "m.gif").stat().st_size > 1000


# --------------------------------------------------------------------------------------------
# map


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    """A sweep summary written without a cluster: 2 x 2 cases, one failed."""
    from granel.studies.sweep import SweepSpec, cases, summary_dataset

    spec = SweepSpec.model_validate({"base": "paper", "mode": "run", "axes": [
        {"field": "contact.mu", "values": [0.1, 0.2]}, {"field": "media.0.radius", "values": [0.01, 0.011]}]})
    results = []
    for k, c in enumerate(cases(spec)):
        r = {"tag": c["tag"], "index": list(c["index"]), "overrides": c["overrides"]}
        if k == 3:
            r["status"] = "error: ScenarioError: invented"
        else:
            r.update(status="ok", metrics={"peak_velocity_m_s": 0.1 * (k + 1), "arrival_measured_s": float("nan")})
        results.append(r)
    return write_netcdf(summary_dataset(spec, results), tmp_path_factory.mktemp("summary") / "summary.nc")


@pytest.mark.parametrize("kind", UNREADABLE + FOREIGN + ["good"])
def test_map_unusable_summary_exits_4_or_2(files, tmp_path, kind):
    # "good" is a run's result: a valid NetCDF file, but not a sweep summary
    code, out = invoke(["map", files[kind], "-o", tmp_path / "m.png"])
    assert code == (4 if kind in UNREADABLE else 2), out
    assert files[kind].name in out
    assert not (tmp_path / "m.png").exists()


@pytest.mark.parametrize("args,names", [
    (["--metric", "nope"], "--metric"),
    (["--metric", "status"], "--metric"),
    (["--metric", "arrival_measured_s"], "--metric"),  # NaN everywhere: nothing to draw
    (["--metric", "peak_velocity_m_s", "--x", "nope"], "--x"),
    (["--metric", "peak_velocity_m_s", "--x", "contact_mu", "--y", "contact_mu"], "--x"),
    (["--metric", "peak_velocity_m_s", "-o", "map.xyz"], "--output"),
    (["--metric", "peak_velocity_m_s", "-o", "adir.png"], "--output"),
])
def test_map_bad_option_exits_2(summary, tmp_path, args, names):
    (tmp_path / "adir.png").mkdir()
    args = [str(tmp_path / a) if a.endswith((".xyz", ".png")) else a for a in args]
    code, out = invoke(["map", summary, "-o", tmp_path / "m.png", *args])
    assert code == 2, out
    assert names in out


def test_map_missing_summary_exits_2(tmp_path):
    code, out = invoke(["map", tmp_path / "nothing.nc"])
    assert code == 2 and "nothing.nc" in out


def test_map_good_summary(summary, tmp_path):
    code, out = invoke(["map", summary, "-o", tmp_path / "m.png", "--metric", "peak_velocity_m_s"])
    assert code == 0, out
    assert (tmp_path / "m.png").stat().st_size > 5000


# --------------------------------------------------------------------------------------------
# sweep: options and files (no cluster starts)


SWEEP = """
name = "h"
base = "paper"
mode = "run"
overrides = ['simulation.duration="0.005ms"', 'solid.kind="rigid"']
[[axes]]
field = "excitations.0.granule"
values = ["SSGM:C", "SSGM:Z"]
"""


@pytest.fixture
def sweep_file(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SWEEP)
    return p


@pytest.mark.parametrize("workers", ["0", "-1"])
def test_sweep_workers_below_one_exits_2(sweep_file, tmp_path, workers):
    code, out = invoke(["sweep", sweep_file, "-o", tmp_path / "out", "--workers", workers])
    assert code == 2 and "--workers" in out
    assert not (tmp_path / "out").exists()  # nothing started


def test_run_sweep_refuses_zero_workers(sweep_file, tmp_path):
    from granel.studies.sweep import run_sweep

    with pytest.raises(ValueError, match="workers"):
        run_sweep(sweep_file, tmp_path / "out", workers=0)


@pytest.mark.parametrize("text,code,needle", [
    (None, 2, "nothing.toml"),  # missing
    ("name = [unclosed", 2, "not valid TOML"),
    ('name = "x"\n[[axes]]\nfield = "contact.mu"\nvalues = []\n', 2, "at least one value"),
    ('name = "x"\n[[axes]]\nfield = "contact.mu"\nlinspace = [0.1, 0.2, 1000]\n[[axes]]\nfield = "contact.k_s"\n'
     'linspace = [1.0, 2.0, 1000]\n', 2, "more than"),
    ('name = "x"\n[[axes]]\nfield = "contact.mu"\nlinspace = [0.1, nan, 3]\n', 2, "finite"),
    ('base = "no-such-scenario.toml"\n[[axes]]\nfield = "contact.mu"\nvalues = [0.1]\n', 2, "no-such-scenario"),
    (b"\xff\xfe\x00binary", 2, "s.toml"),  # not text: bad content, as the one reader has it
    ("DIR", 4, "s.toml"),
])
def test_sweep_bad_file(tmp_path, text, code, needle):
    p = tmp_path / ("nothing.toml" if text is None else "s.toml")
    if text == "DIR":
        p.mkdir()
    elif isinstance(text, bytes):
        p.write_bytes(text)
    elif text is not None:
        p.write_text(text)
    got, out = invoke(["sweep", p, "-o", tmp_path / "out", "--workers", "1"])
    assert got == code, out
    assert needle in out


def test_sweep_out_is_a_file_exits_2(sweep_file, tmp_path):
    (tmp_path / "out").write_text("not a directory")
    code, out = invoke(["sweep", sweep_file, "-o", tmp_path / "out"])
    assert code == 2 and "--out" in out


@pytest.mark.parametrize("address", ["nonsense", "foo://bar:1", "tcp://"])
def test_sweep_bad_scheduler_address_exits_2(sweep_file, tmp_path, address):
    code, out = invoke(["sweep", sweep_file, "-o", tmp_path / "out", "--scheduler", address])
    assert code == 2 and "--scheduler" in out


def test_unreachable_scheduler_is_an_io_error_and_leaves_dask_as_it_was():
    import dask

    from granel.studies.sweep import SchedulerError, connect_scheduler

    before = dask.config.get("scheduler", None)
    with pytest.raises(SchedulerError, match="cannot reach") as e:
        connect_scheduler("tcp://127.0.0.1:1", timeout=1.0)
    assert e.value.code == 4
    assert dask.config.get("scheduler", None) == before


# --------------------------------------------------------------------------------------------
# sweep: failed cases, fingerprints, arrivals


def test_sweep_with_a_failed_case_exits_3_and_counts_it(sweep_file, tmp_path):
    """One LocalCluster run: SSGM:Z is not a granule, that case fails, the other is ok."""
    out = tmp_path / "out"
    code, text = invoke(["sweep", sweep_file, "-o", out, "--workers", "1"])
    assert code == 3, text
    assert "1 of 2 cases failed" in text and "SSGM:Z" in text
    ds = read_netcdf(out / "summary.nc")
    assert sorted(s.split(":")[0] for s in ds["status"].values) == ["error", "ok"]


@pytest.fixture
def one_case(tmp_path):
    """A single valid reciprocity case (rigid, 0.005 ms) and its run_case arguments."""
    from granel.studies.sweep import SweepSpec, cases

    spec = SweepSpec.model_validate({"base": "paper", "overrides": RIGID + ['excitations.0.shock="strong"'],
                                     "axes": [{"field": "contact.mu", "values": [0.099]}]})
    return spec, cases(spec)[0], tmp_path


def _fp(spec, case, base_dir="."):
    from pathlib import Path

    from granel.studies.sweep import case_fingerprint, case_scenarios

    return case_fingerprint(spec, case_scenarios(spec, Path(base_dir), case), case)


def test_failed_case_is_retried(one_case):
    from granel.studies.sweep import run_case

    spec, case, tmp = one_case
    done = tmp / "cases" / f"{case['tag']}.json"
    done.parent.mkdir()
    done.write_text(json.dumps({"tag": case["tag"], "index": [0], "overrides": case["overrides"],
                                "status": "error: RuntimeError: transient", "fingerprint": _fp(spec, case)}))
    r = run_case(spec.model_dump_json(), ".", case, str(tmp))
    assert r["status"] == "ok"
    assert json.loads(done.read_text())["status"] == "ok"


def test_cached_case_reused_only_with_its_fingerprint(one_case):
    from granel.studies.sweep import run_case

    spec, case, tmp = one_case
    done = tmp / "cases" / f"{case['tag']}.json"
    done.parent.mkdir()
    fake = {"tag": case["tag"], "index": [0], "overrides": case["overrides"], "status": "ok", "metrics": {"nonreciprocity_index": 42.0}}
    done.write_text(json.dumps({**fake, "fingerprint": _fp(spec, case)}))
    assert run_case(spec.model_dump_json(), ".", case, str(tmp))["metrics"]["nonreciprocity_index"] == 42.0  # reused
    done.write_text(json.dumps({**fake, "fingerprint": "stale"}))
    r = run_case(spec.model_dump_json(), ".", case, str(tmp))
    assert r["status"] == "ok" and r["metrics"]["nonreciprocity_index"] != 42.0  # recomputed
    done.write_text(json.dumps({k: v for k, v in fake.items()}))  # a result of an older granel: no fingerprint
    assert run_case(spec.model_dump_json(), ".", case, str(tmp))["metrics"]["nonreciprocity_index"] != 42.0


@pytest.mark.parametrize("change", ["scenario", "solver", "dt", "case_override", "mode", "pair", "version"])
def test_fingerprint_covers(one_case, monkeypatch, change):
    import granel.studies.sweep as SW

    spec, case, _ = one_case
    before = _fp(spec, case)
    if change == "scenario":
        spec = spec.model_copy(update={"overrides": spec.overrides + ["contact.k_s=50.0"]})
    elif change == "solver":
        spec = spec.model_copy(update={"overrides": spec.overrides + ['simulation.solver="paper"']})
    elif change == "dt":
        spec = spec.model_copy(update={"overrides": spec.overrides + ["simulation.dt=2e-8"]})
    elif change == "case_override":
        case = {**case, "overrides": {"contact.mu": 0.2}}
    elif change == "mode":
        spec = spec.model_copy(update={"mode": "run"})
    elif change == "pair":
        spec = spec.model_copy(update={"pair": ("LSGM:2", "SSGM:C")})
    else:
        monkeypatch.setattr(SW, "__version__", "0.0.0-other")
    assert _fp(spec, case) != before


def test_sweep_arrival_is_nan_when_nothing_arrives(one_case):
    """Behind a rigid wall the measured granule only sees round-off (~1e-19 m/s): no arrival."""
    from granel.studies.sweep import run_case

    spec, case, tmp = one_case
    r = run_case(spec.model_dump_json(), ".", case, str(tmp))
    assert r["status"] == "ok"
    m = r["metrics"]
    assert m["peak_velocity_fwd"] < 1e-12 or m["peak_velocity_bwd"] < 1e-12  # noise only, at least one way
    assert np.isnan(m["arrival_fwd_s"]) and np.isnan(m["arrival_bwd_s"])


def test_pulse_arrival_is_relative_to_the_input():
    from granel.analysis.reciprocity import pulse_arrival

    t = np.linspace(0.0, 1e-3, 1001)
    s = np.where(t > 4e-4, np.sin(np.pi * (t - 4e-4) / 2e-4) ** 2, 0.0)
    a = pulse_arrival(t, 0.2 * s, 1.0)
    assert 4e-4 < a < 4.5e-4
    assert pulse_arrival(t, 0.2e-9 * s, 1e-9) == a  # scale-free
    assert np.isnan(pulse_arrival(t, 1e-19 * s, 1.0))  # round-off is no arrival
    assert np.isnan(pulse_arrival(t, s, 0.0))  # nothing driven


# --------------------------------------------------------------------------------------------
# reciprocity: refused before anything runs


@pytest.mark.parametrize("args,code,needle", [
    (["--a", "SSGM:C", "--b", "SSGM:C"], 2, "--a"),
    (["--a", "SSGM:Q"], 2, "SSGM:Q"),
    (["--shock", "nan"], 2, "--shock"),
    (["--out", "FILE"], 2, "--out"),
])
def test_reciprocity_bad_input(tmp_path, args, code, needle):
    (tmp_path / "FILE").write_text("a file, not a folder")
    args = [str(tmp_path / a) if a == "FILE" else a for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "rec")]
    got, out = invoke(["reciprocity", "paper", "--solid", "rigid", "--duration", "0.005ms", *args])
    assert got == code, out
    assert needle in out
    assert not (tmp_path / "rec").exists()


# --------------------------------------------------------------------------------------------
# checkpoints


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A checkpoint written at 0.004 ms of a 0.01 ms rigid run killed at 0.006 ms, and its fingerprint."""
    from granel.io.checkpoint import fingerprint
    from granel.run import run_scenario

    sc = S.load("paper", ['solid.kind="rigid"', 'simulation.duration="0.01ms"', 'simulation.checkpoint_every="0.004ms"'])
    ck = tmp_path_factory.mktemp("ckpt") / "run.ckpt"

    class Killed(Exception):
        pass

    def killer(t):
        if t > 0.006e-3:
            raise Killed

    with pytest.raises(Killed):
        run_scenario(sc, killer, ck)
    problem = S.build_problem(sc)
    return ck, fingerprint(problem.source + problem.settings.method)


def _damaged(ck, tmp, kind):
    raw = ck.read_bytes()
    p = tmp / f"{kind}.ckpt"
    if kind == "missing":
        return p
    if kind == "directory":
        p.mkdir()
    elif kind == "text":
        p.write_text("not a checkpoint\n")
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "truncated":
        p.write_bytes(raw[: len(raw) // 2])
    elif kind == "flipped":  # a damaged member: bad CRC
        b = bytearray(raw)
        b[len(b) // 3] ^= 0xFF
        p.write_bytes(bytes(b))
    elif kind == "npy":
        with open(p, "wb") as fh:
            np.save(fh, np.arange(3))
    elif kind == "foreign":
        with open(p, "wb") as fh:
            np.savez(fh, weights=np.ones(3))
    elif kind == "pickled":
        with open(p, "wb") as fh:
            z = dict(np.load(ck))
            z["__fingerprint"] = np.array([{"a": 1}], dtype=object)
            np.savez(fh, **z)
    elif kind == "inconsistent":  # the output counter disagrees with the records
        with open(p, "wb") as fh:
            z = dict(np.load(ck))
            z["state:k"] = np.array(int(z["state:k"]) + 3)
            np.savez(fh, **z)
    return p


@pytest.mark.parametrize("kind", ["missing", "directory", "text", "empty", "truncated", "flipped", "npy", "foreign",
                                  "pickled", "inconsistent"])
def test_bad_checkpoint_raises_checkpoint_error_naming_the_file(checkpoint, tmp_path, kind):
    from granel.io.checkpoint import CheckpointError, load_checkpoint

    ck, fp = checkpoint
    p = _damaged(ck, tmp_path, kind)
    with pytest.raises(CheckpointError) as e:
        load_checkpoint(p, fp)
    assert str(p) in str(e.value)
    assert e.value.code == (2 if kind == "missing" else 4)


def test_checkpoint_of_another_scenario_is_refused(checkpoint):
    from granel.io.checkpoint import CheckpointError, load_checkpoint

    ck, fp = checkpoint
    with pytest.raises(CheckpointError, match="different scenario") as e:
        load_checkpoint(ck, "0" * 16)
    assert str(ck) in str(e.value)
    assert e.value.code == 2
    assert isinstance(e.value, RuntimeError)  # what load_checkpoint always raised


def test_good_checkpoint_loads_and_resume_path_raises_the_same(checkpoint, tmp_path):
    from granel.io.checkpoint import CheckpointError, load_checkpoint
    from granel.run import run_scenario

    ck, fp = checkpoint
    state, rec, times = load_checkpoint(ck, fp)
    assert int(state["k"]) + 1 == len(times) == len(rec["times"])
    sc = S.load("paper", ['solid.kind="rigid"', 'simulation.duration="0.01ms"', 'simulation.checkpoint_every="0.004ms"'])
    bad = _damaged(ck, tmp_path, "truncated")
    with pytest.raises(CheckpointError, match="truncated.ckpt"):
        run_scenario(sc, None, None, bad)
