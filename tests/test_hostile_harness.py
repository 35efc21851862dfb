"""A hostile-input harness over every command and option of `granel` (issue 28, item 3).

Every case, whatever it feeds a command (hostile numbers, paths, files, a damaged cache, a full
disk, a Ctrl-C), must hold one property (`contract`):

* the exit code is 0, 2, 3, 4 or 130;
* an error is one line starting `error:`, the last line on standard error (notes, warnings,
  progress and tables may come before it), and no "Traceback" appears anywhere;
* no file outside the command's intended outputs changed (every other path in the case's folder
  is snapshotted, bytes and mtime, before and compared after);
* bounded time (in-process calls are timed, subprocesses run under a timeout);
* an exit 0 only with a result that a reference check confirms (`verify_*`: a run's result has
  the scenario's granule count, finite positions, the last output at the duration, and its energy
  balance within `simulation.balance_limit` of the input work; a picture opens; ...).

Commands that would start long work (`bench`, `paper`, `sweep`, `spectrum`, `design`) run with
their engine replaced by a stand-in that records the call and stops the command (`Accepted`):
their options are checked without a benchmark, a study or a cluster ever starting, and a hostile
value that reaches the stand-in is a value the command failed to refuse.

Most cases run in process (`typer.testing.CliRunner`) on tiny runs (the paper's interface
against a rigid solid for 0.005 ms; for `wavefield`, which takes a plate or a beam, a short plate
struck by one bead); FIFOs, non-UTF-8 names, signals and the full disk (a small
tmpfs, root only) run where they must, in subprocesses. Each finding the harness made, once
fixed, is kept as a case of its own (section 7). Hostile environments (section 8: cache folders
that cannot be used, TMPDIR, HOME, the terminal's size, an ASCII locale with non-ASCII names, a
umask, limits on open files and file size, a clock or files dated far off) meet every command in
a process, under the same contract."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import resource
import shlex
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import granel
import granel.studies.benchmark
import granel.studies.design_search
import granel.studies.paper
import granel.studies.sweep
from granel import scenario as S
from granel.cli import app
from granel.guard.exits import GranelError

RUNNER = CliRunner()
ALLOWED = {0, 2, 3, 4, 130}
IN_PROCESS_LIMIT = 60.0  # seconds: any in-process case (they take 0.01-2 s)
SUBPROCESS_TIMEOUT = 120.0
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
COUNT = {"cases": 0}
HYPOTHESIS = dict(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                  database=None)

# ------------------------------------------------------------------------------------------------
# stand-ins for the engines of the long commands


ACCEPTED = "hostile-harness: the options were accepted"


class Accepted(GranelError):
    """Raised by a stand-in: the command validated its options and was about to start its work."""

    code = 2


CALLS: list = []
ORIGINAL: dict = {}
LIVE: set = set()  # stand-ins that call the real engine (the full-disk sweep)
STAND_INS = [(granel.studies.benchmark, "run_bench"), (granel.studies.paper, "paper_study"), (granel.studies.sweep, "run_sweep"),
             (granel.studies.sweep, "run_spec"), (granel.studies.design_search, "run_design")]


def _stand_in(name):
    def stand_in(*args, **kwargs):
        if name in LIVE:
            return ORIGINAL[name](*args, **kwargs)
        CALLS.append((name, args, kwargs))
        raise Accepted(f"{ACCEPTED} ({name})")

    return stand_in


@pytest.fixture(scope="module", autouse=True)
def harness_env(tmp_path_factory):
    """A private GRANEL_CACHE for the module and the stand-ins; the case count at the end."""
    cache = tmp_path_factory.mktemp("granel-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GRANEL_CACHE", str(cache))
        mp.setattr(tempfile, "tempdir", str(tmp_path_factory.mktemp("tmp")))  # crash reports of the xfails
        for module, name in STAND_INS:
            ORIGINAL[name] = getattr(module, name)
            mp.setattr(module, name, _stand_in(name))
        yield cache


# ------------------------------------------------------------------------------------------------
# the inputs every case starts from (copied into a fresh folder per case)


PAPER_TEXT = (Path(S.__file__).parent / "builtin" / "paper.toml").read_text()
assert 'kind = "plate"' in PAPER_TEXT and 'duration = "0.8ms"' in PAPER_TEXT


def paper_text(kind: str) -> str:
    return PAPER_TEXT.replace('kind = "plate"', f'kind = "{kind}"').replace('duration = "0.8ms"', 'duration = "0.005ms"')


CHAIN = """name = "chain"
description = "four touching beads, a force table on the first"

[simulation]
duration = "0.005ms"
output_every = "1us"

[contact]
mu = 0.0
alpha_n = 0.0

[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0

[[media]]
name = "C"
side = "none"
granules_file = "beads.csv"
radius = 0.005

[[excitations]]
granule = "C:1"
kind = "table"
file = "force.csv"
direction = [1.0, 0.0]
"""
BEADS = "label,x,y,radius\n1,0.0,0.0,0.005\n2,0.01,0.0,0.005\n3,0.02,0.0,0.005\n4,0.03,0.0,0.005\n"
FORCE = "time,force\n0,0\n2e-6,10\n4e-6,0\n"
SWEEP = """name = "h"
base = "paper"
mode = "run"
overrides = ['simulation.duration="0.005ms"', 'solid.kind="rigid"']
[[axes]]
field = "contact.mu"
values = [0.1, 0.2]
"""
DESIGN = """name = "h"
base = "paper"
overrides = ['solid.kind="rigid"', 'simulation.duration="0.005ms"']
mode = "run"
trials = 2
[[variables]]
field = "contact.mu"
low = 0.0
high = 0.3
[[objectives]]
metric = "peak_velocity_m_s"
direction = "maximize"
"""
NARROWBAND = Path(__file__).resolve().parents[1] / "scenarios" / "narrowband"
# the cheapest plate result `granel wavefield` takes (it refuses rigid solids with exit 2): a 20 x 5 mm plate,
# two elements across and up to 5 mm along (527 DOFs), struck by one bead. Its modes took 2.5 s on an empty
# cache here (cached: 0 s), the paper's plate's (3584 DOFs) 16 s. Its wavenumbers are 157 rad/m apart and its
# elements resolve 721 rad/m: each of wavefield's default four bands (up to that limit) holds one of them.
PLATE = """name = "short-plate"
description = "a short plate struck by one bead (the hostile harness's wavefield input)"

[simulation]
duration = "0.005ms"
output_every = "1us"

[contact]
mu = 0.0
alpha_n = 0.0

[solid]
kind = "plate"
width = 0.005
length = 0.02

[solid.mesh]
nx = 2
max_size = 0.005

[[media]]
name = "G"
side = "left"
radii = [0.001]

[[excitations]]
granule = "G:1"
kind = "half_sine"
fmax = 50.0
tau = "1.5us"
direction = "toward_solid"
"""


def _invoke_raw(args, cwd):
    with _chdir(cwd):
        return RUNNER.invoke(app, [str(a) for a in args])


@contextlib.contextmanager
def _chdir(path):
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """scen.toml (the paper, rigid, 0.005 ms), beam.toml, chain.toml (+ beads.csv, force.csv),
    nb.toml (+ chain-20.csv), sweep.toml, design.toml, plate.toml (PLATE), plain.txt; good.nc (a run
    of scen.toml), beam.nc, plate.nc (a run of plate.toml, wavefield's input), g.png and g.gif
    (granel's picture and movie), summary.nc (a sweep summary) and run.ckpt (a checkpoint of
    scen.toml with --checkpoint-every 0.002ms)."""
    a = tmp_path_factory.mktemp("assets")
    (a / "scen.toml").write_text(paper_text("rigid"))
    (a / "beam.toml").write_text(paper_text("beam"))
    (a / "chain.toml").write_text(CHAIN)
    (a / "beads.csv").write_text(BEADS)
    (a / "force.csv").write_text(FORCE)
    (a / "sweep.toml").write_text(SWEEP)
    (a / "design.toml").write_text(DESIGN)
    (a / "plate.toml").write_text(PLATE)
    (a / "plain.txt").write_text("a plain file, not a folder\n")
    shutil.copy(NARROWBAND / "precompressed-chain.toml", a / "nb.toml")
    shutil.copy(NARROWBAND / "chain-20.csv", a / "chain-20.csv")
    for args in (["run", "scen.toml", "-o", "good.nc"], ["run", "beam.toml", "-o", "beam.nc"],
                 ["run", "plate.toml", "-o", "plate.nc"],
                 ["show", "scen.toml", "-o", "g.png"], ["animate", "good.nc", "-o", "g.gif", "--frames", "2", "--fps", "5"]):
        res = _invoke_raw(args, a)
        assert res.exit_code == 0, res.output
    from granel.io.results import write_netcdf
    from granel.studies.sweep import SweepSpec, cases, summary_dataset

    spec = SweepSpec.model_validate({"base": "paper", "mode": "run", "axes": [
        {"field": "contact.mu", "values": [0.1, 0.2]}, {"field": "media.0.radius", "values": [0.01, 0.011]}]})
    results = []
    for k, c in enumerate(cases(spec)):
        r = {"tag": c["tag"], "index": list(c["index"]), "overrides": c["overrides"], "status": "ok",
             "metrics": {"peak_velocity_m_s": 0.1 * (k + 1), "arrival_measured_s": float("nan")}}
        results.append(r)
    write_netcdf(summary_dataset(spec, results), a / "summary.nc")
    _make_checkpoint(a / "scen.toml", a / "run.ckpt")
    return a


def _make_checkpoint(scenario: Path, ckpt: Path):
    from granel.run import run_scenario

    sc = S.load(str(scenario), ['simulation.checkpoint_every="0.002ms"'])

    class Killed(Exception):
        pass

    def killer(t):
        if t > 0.0025e-3:
            raise Killed

    with pytest.raises(Killed):
        run_scenario(sc, killer, ckpt)
    assert ckpt.exists()


def new_box(assets: Path) -> Path:
    box = Path(tempfile.mkdtemp(prefix="box-", dir=assets.parent))
    shutil.copytree(assets, box, dirs_exist_ok=True, symlinks=True)
    return box


def _release(b: Path):
    """Undo what a case did to its folder that would keep pytest from removing it."""
    for dirpath, dirnames, _ in os.walk(b):
        for d in dirnames:
            with contextlib.suppress(OSError):
                os.chmod(os.path.join(dirpath, d), 0o755)


# ------------------------------------------------------------------------------------------------
# the property


def snapshot(root: Path) -> dict:
    """Every path under `root`: kind, and for files size, mtime, mode and content digest."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = os.path.join(dirpath, name)
            try:
                s = os.lstat(p)
            except OSError:
                continue
            if stat.S_ISLNK(s.st_mode):
                out[p] = ("link", os.readlink(p))
            elif stat.S_ISREG(s.st_mode):
                try:
                    with open(p, "rb") as fh:
                        digest = hashlib.sha1(fh.read()).hexdigest()
                except PermissionError:  # unreadable to a user who is not root: its stat stands for it
                    digest = None
                out[p] = ("file", s.st_size, s.st_mtime_ns, stat.S_IMODE(s.st_mode), digest)
            elif stat.S_ISDIR(s.st_mode):
                out[p] = ("dir", stat.S_IMODE(s.st_mode))
            else:  # a FIFO or device: never opened
                out[p] = ("special", stat.S_IFMT(s.st_mode), s.st_mtime_ns)
    return out


def _allowed_paths(root: Path, outputs, before: dict) -> list[str]:
    """The paths a command may change: its outputs, and where an output link points when nothing
    is there yet (a dangling link's target); never an existing file or folder a link reaches."""
    allowed = []
    for o in outputs:
        p = Path(o) if Path(o).is_absolute() else root / o
        allowed.append(os.path.abspath(p))
        real = os.path.realpath(p)
        if real != os.path.abspath(p) and not os.path.lexists(real):
            allowed.append(real)
    return allowed


def changed_outside(before: dict, after: dict, allowed: list[str]) -> list[str]:
    def inside(p):
        return any(p == a or p.startswith(a.rstrip(os.sep) + os.sep) for a in allowed)

    diffs = []
    for p in sorted(before.keys() | after.keys()):
        if inside(p) or before.get(p) == after.get(p):
            continue
        what = "new" if p not in before else "removed" if p not in after else "changed"
        diffs.append(f"{what}: {p}")
    return diffs


@dataclass
class Outcome:
    args: list
    code: int
    stdout: str
    stderr: str
    seconds: float
    where: Path

    @property
    def error(self) -> str:
        errs = [line for line in self.stderr.splitlines() if line.startswith("error:")]
        return errs[-1] if errs else ""

    @property
    def accepted(self) -> bool:
        return ACCEPTED in self.error

    @property
    def command(self) -> str:
        return "cd " + shlex.quote(str(self.where)) + " && granel " + " ".join(shlex.quote(str(a)) for a in self.args)

    def __str__(self):
        return f"{self.command}\n-> exit {self.code} in {self.seconds:.2f} s\nstdout: {self.stdout[-1500:]}\nstderr: {self.stderr[-2500:]}"


def contract(out: Outcome, diffs: list[str], limit: float = IN_PROCESS_LIMIT) -> Outcome:
    """The property every case must hold (see the module's docstring)."""
    COUNT["cases"] += 1
    assert out.code in ALLOWED, f"exit code {out.code} not in {sorted(ALLOWED)}\n{out}"
    assert "Traceback" not in out.stdout and "Traceback" not in out.stderr, f"a traceback\n{out}"
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error:")]
    if out.code == 0:
        assert not errors, f"exit 0 with an error line\n{out}"
    else:
        assert len(errors) == 1, f"exit {out.code} needs exactly one error line, got {len(errors)}\n{out}"
        after = lines[lines.index(errors[0]) + 1:]
        assert not after, f"the error is not the last line of standard error\n{out}"
        assert "internal error" not in errors[0], f"an internal error\n{out}"
    assert not diffs, "files outside the intended outputs changed: " + "; ".join(diffs[:5]) + f"\n{out}"
    assert out.seconds < limit, f"took {out.seconds:.1f} s (limit {limit} s)\n{out}"
    return out


@contextlib.contextmanager
def fifo_watchdog(fifos, seconds: float = 15.0):
    """In-process cases with FIFOs: if the command is still running after `seconds`, open the
    other end of each FIFO (unblocking a reader or a writer stuck in open) and drain it, and
    record the hang; yields the list of FIFOs found blocking."""
    import threading

    stop, hung = threading.Event(), []

    def watch():
        if stop.wait(seconds):
            return
        for f in fifos:
            hung.append(f)
            with contextlib.suppress(OSError):
                os.close(os.open(f, os.O_WRONLY | os.O_NONBLOCK))  # a blocked reader gets end-of-file
            try:
                fd = os.open(f, os.O_RDONLY | os.O_NONBLOCK)  # a blocked writer gets a reader
            except OSError:
                continue
            end = time.monotonic() + 5
            while time.monotonic() < end and not stop.is_set():
                with contextlib.suppress(BlockingIOError):
                    os.read(fd, 1 << 16)
                time.sleep(0.01)
            os.close(fd)

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    try:
        yield hung
    finally:
        stop.set()
        th.join()


def invoke(box: Path, args, outputs=(), env=None) -> Outcome:
    """`granel ARGS` in process, in `box`; the contract checked; `outputs` (relative to box or
    absolute) may change. A FIFO in the folder is watched (`fifo_watchdog`): blocking on one fails."""
    args = [str(a) for a in args]
    before = snapshot(box)
    allowed = _allowed_paths(box, outputs, before)
    fifos = [p for p, v in before.items() if v[0] == "special" and stat.S_ISFIFO(v[1])]
    CALLS.clear()
    unraisable, hook = [], sys.unraisablehook
    sys.unraisablehook = unraisable.append  # what a process prints as "Exception ignored in ...: Traceback"
    import gc

    gc.freeze()  # what lives now is out of the collection below, which then scans only the command's objects
    try:
        with _chdir(box), fifo_watchdog(fifos) as hung:
            t0 = time.perf_counter()
            res = RUNNER.invoke(app, args, env=env)
            seconds = time.perf_counter() - t0
            gc.collect()  # finalisers of what the command left half built (h5py, h5netcdf) run here
    finally:
        sys.unraisablehook = hook
    assert not hung, f"granel {shlex.join(args)} in {box} blocked on the FIFO {hung[0]} (a hang)"
    exc = res.exception
    stderr = res.stderr
    for u in unraisable:
        stderr += f"\nException ignored in: {u.object!r}\nTraceback (unraisable): {u.exc_type.__name__}: {u.exc_value}"
    if exc is not None and not isinstance(exc, SystemExit):
        import traceback

        stderr += "\nTraceback (escaped the command line):\n" + "".join(traceback.format_exception(exc))
    out = Outcome(args, res.exit_code, res.stdout, stderr, seconds, box)
    return contract(out, changed_outside(before, snapshot(box), allowed))


def _drain(proc):
    """Read a process's standard output and error in threads (so that it never blocks on a full
    pipe); returns a function giving (stdout, stderr) once it has ended."""
    import threading

    chunks = {"out": b"", "err": b""}

    def read(stream, key):
        chunks[key] = stream.read()

    threads = [threading.Thread(target=read, args=(proc.stdout, "out"), daemon=True),
               threading.Thread(target=read, args=(proc.stderr, "err"), daemon=True)]
    for th in threads:
        th.start()

    def result():
        for th in threads:
            th.join()
        return chunks["out"], chunks["err"]

    return result


def invoke_subprocess(box: Path, args, outputs=(), timeout=SUBPROCESS_TIMEOUT, signal_when=None, env=None,
                      preexec_fn=None) -> Outcome:
    """`python -m granel ARGS` in `box` (arguments may be bytes: names that are not UTF-8);
    `signal_when` = (condition(proc), signal): the signal is sent once the condition holds (polled);
    `env`: variables merged over this process's (None unsets one); `preexec_fn`: run in the child
    before Python starts (a umask, resource limits)."""
    before = snapshot(box)
    allowed = _allowed_paths(box, [os.fsdecode(o) if isinstance(o, bytes) else o for o in outputs], before)
    cmd = [sys.executable, "-m", "granel", *[a if isinstance(a, bytes) else str(a) for a in args]]
    t0 = time.perf_counter()
    merged = {**os.environ, "TMPDIR": tempfile.gettempdir(), **(env or {})}  # a crash report lands in the module's folder
    merged = {k: v for k, v in merged.items() if v is not None}
    proc = subprocess.Popen(cmd, cwd=box, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=merged,
                            preexec_fn=preexec_fn)
    try:
        if signal_when is not None:
            condition, sig = signal_when
            out_reader = _drain(proc)
            while proc.poll() is None and time.perf_counter() - t0 < timeout:
                if condition(proc):
                    if sig is not None:
                        proc.send_signal(sig)
                    break
                time.sleep(0.05)
            proc.wait(timeout=max(1.0, timeout - (time.perf_counter() - t0)))
            so, se = out_reader()
        else:
            so, se = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        so, se = proc.communicate()
        raise AssertionError(f"no end within {timeout} s (a hang): {shlex.join(map(os.fsdecode, cmd))} in {box}")
    seconds = time.perf_counter() - t0
    out = Outcome([os.fsdecode(a) if isinstance(a, bytes) else str(a) for a in args], proc.returncode,
                  so.decode(errors="replace"), se.decode(errors="replace"), seconds, box)
    return contract(out, changed_outside(before, snapshot(box), allowed), limit=timeout)


# ------------------------------------------------------------------------------------------------
# reference checks of an exit 0


def scenario_of(source: str, overrides: list[str], shock=None) -> S.Scenario:
    return S.load(source, overrides, shock=shock)


def verify_result(path: Path, sc: S.Scenario) -> None:
    """A run's result: it opens, has the scenario's granules, finite positions, its last output
    at the duration and its balance within balance_limit of the input work."""
    assert path.is_file(), f"{path}: no result"
    ds = xr.load_dataset(path, engine="h5netcdf")
    n = S.build_problem(sc).system.n
    assert ds.sizes["granule"] == n, f"{path}: {ds.sizes['granule']} granules, the scenario has {n}"
    for v in ("x", "y", "v_x", "v_y"):
        assert np.isfinite(ds[v].values).all(), f"{path}: {v} is not finite"
    t = ds["time"].values.astype(float)
    assert abs(t[-1] - sc.simulation.duration) <= 1e-9 * sc.simulation.duration, f"{path}: last output {t[-1]}"
    work, balance = np.abs(ds["input_work"].values), np.abs(ds["balance_error"].values)
    assert np.isfinite(work).all() and np.isfinite(balance).all(), f"{path}: non-finite energies"
    assert balance.max() <= sc.simulation.balance_limit * work.max() + 1e-300, \
        f"{path}: balance error {balance.max():.3e} J beyond {sc.simulation.balance_limit} of the input {work.max():.3e} J"


def verify_picture(path: Path) -> None:
    assert path.is_file(), f"{path}: no picture"
    head = path.read_bytes()[:8]
    if path.suffix.lower() == ".pdf":
        assert head.startswith(b"%PDF"), f"{path}: not a PDF"
        return
    if path.suffix.lower() == ".svg":
        assert b"<svg" in path.read_bytes()[:4000]
        return
    from PIL import Image

    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.size[0] > 50 and im.size[1] > 50, f"{path}: {im.size}"


def verify_movie(path: Path, frames: int) -> None:
    assert path.is_file(), f"{path}: no movie"
    data = path.read_bytes()
    if data[:6] in (b"GIF89a", b"GIF87a"):
        from PIL import Image

        with Image.open(path) as im:
            assert 1 <= im.n_frames <= frames, f"{path}: {im.n_frames} frames, asked for at most {frames}"
    else:
        assert data[4:8] == b"ftyp", f"{path}: neither a GIF nor an MP4"


def verify_export(folder: Path, result: Path, formats=("vtk", "xdmf", "csv", "extxyz")) -> None:
    ds = xr.load_dataset(result, engine="h5netcdf")
    if "csv" in formats:
        rows = (folder / "traces.csv").read_text().strip().splitlines()
        assert len(rows) >= ds.sizes["time"], f"{folder}/traces.csv: {len(rows)} lines for {ds.sizes['time']} outputs"
    if "vtk" in formats:
        assert (folder / "granules.pvd").is_file()
    if "extxyz" in formats:
        text = (folder / "granules.extxyz").read_text()
        assert text.splitlines()[0].strip() == str(ds.sizes["granule"])


WAVEFIELD_UNITS = {"k": "rad/m", "t": "s", "f": "Hz"}  # docs/wavefield.md, the table of files
WAVEFIELD_FIGURES = ("kt.png", "fk.png", "moments.png", "bands.png")


def verify_wavefield(folder: Path, result: Path, frames: int | None = None) -> None:
    """`granel wavefield`'s folder: wavefield.nc opens, with the coordinates k, t and f in their
    units (their attributes), a finite E(k, t) >= 0 (`energy`, a sum of squares) at each of the
    result's solid outputs; its four figures open as pictures; with `frames` (--movie) the movie,
    bands.mp4 or the GIF it falls back to, holds at most that many frames."""
    ds = xr.load_dataset(folder / "wavefield.nc", engine="h5netcdf")
    for name, units in WAVEFIELD_UNITS.items():
        assert name in ds.coords, f"{folder}/wavefield.nc: no coordinate {name}"
        assert ds[name].attrs.get("units") == units, f"{folder}/wavefield.nc: {name} in {ds[name].attrs.get('units')!r}"
    energy = ds["energy"]
    assert energy.dims == ("k", "t"), f"{folder}/wavefield.nc: energy over {energy.dims}"
    assert np.isfinite(energy.values).all() and (energy.values >= 0).all(), \
        f"{folder}/wavefield.nc: E(k, t) is not finite and >= 0"
    times = xr.load_dataset(result, engine="h5netcdf")["solid_time"].values
    assert np.array_equal(ds["t"].values, times), \
        f"{folder}/wavefield.nc: {ds.sizes['t']} times, the result has {len(times)} solid outputs"
    for name in WAVEFIELD_FIGURES:
        verify_picture(folder / name)
    if frames is not None:
        movie = folder / "bands.mp4"
        verify_movie(movie if movie.exists() else movie.with_suffix(".gif"), frames)


def verify_modes_json(stdout: str, count: int) -> None:
    data = json.loads(stdout)
    periods = np.array(data["periods_ms"])
    assert len(periods) == min(count, data["modes_computed"]) == len(data["kinds"])
    assert np.isfinite(periods).all() and (periods > 0).all() and (np.diff(periods) <= 1e-12).all()


def verify_scenario_file(path: Path, name=None) -> None:
    sc = S.load(str(path))
    if name is not None:
        assert sc.name == name


def verify_reciprocity(folder: Path, source: str, solid, duration, sets, shock, a="LSGM:3", b="SSGM:C") -> None:
    from granel.cli import _overrides

    level = S.shock_value(shock)
    for exc in (a, b):
        sc = scenario_of(source, _overrides(solid, exc, duration, sets=sets), level)
        verify_result(folder / f"shock-{exc.replace(':', '')}.nc", sc)
    verify_picture(folder / "fig3_velocities.png")


# ------------------------------------------------------------------------------------------------
# the commands, each with its base invocation in a case folder


@dataclass
class Base:
    """A command's valid invocation: arguments, its outputs, and the reference check of an exit 0
    (called with the case folder, the outcome and the arguments' extra options)."""

    args: list
    outputs: list
    verify: object = None
    long_work: bool = False  # reaches a stand-in when the options are valid


def _run_verify(scenario="scen.toml", out="out.nc"):
    def check(box, o, extra):
        from granel.cli import _overrides

        opts = _options(extra)
        sets = opts.pop("--set", [])
        dt = opts.get("--dt")
        implied = ["simulation.adaptive=false"] if dt and opts.get("--solver") != "paper" else []
        ov = _overrides(opts.get("--solid"), opts.get("--excite"), opts.get("--duration"), dt, opts.get("--solver"), sets)
        if opts.get("--checkpoint-every"):
            ov.append(f'simulation.checkpoint_every="{opts["--checkpoint-every"]}"')
        sc = S.load(scenario, ov, shock=S.shock_value(opts.get("--shock")), implied=implied)
        verify_result(box / out, sc)
        assert not (box / Path(out).with_suffix(".ckpt")).exists(), "a finished run left its checkpoint"
    return check


def _options(extra) -> dict:
    """The options of a list of arguments: {option: value} (--set collected in a list)."""
    opts, k = {"--set": []}, 0
    while k < len(extra):
        a = extra[k]
        if a.startswith("--") and k + 1 < len(extra) and not extra[k + 1].startswith("--") or a == "--set":
            if a == "--set":
                opts["--set"].append(extra[k + 1])
            else:
                opts[a] = extra[k + 1]
            k += 2
        else:
            opts[a] = True
            k += 1
    return opts


def base(command: str) -> Base:
    if command == "run":
        return Base(["run", "scen.toml", "-o", "out.nc", "--max-wall", "60s"], ["out.nc", "out.ckpt"], _run_verify())
    if command == "show":
        return Base(["show", "scen.toml", "-o", "pic.png"], ["pic.png"], lambda box, o, e: verify_picture(box / "pic.png"))
    if command == "modes":
        def check(box, o, extra):
            verify_modes_json(o.stdout, int(_options(extra).get("--count", 12)))
        return Base(["modes", "beam.toml", "--json"], [], check)
    if command == "init":
        return Base(["init", "mine", "-o", "new.toml"], ["new.toml"],
                    lambda box, o, e: verify_scenario_file(box / "new.toml"))
    if command == "reciprocity":
        def check(box, o, extra):
            opts = _options(extra)
            verify_reciprocity(box / "rec", "scen.toml", opts.get("--solid", "rigid"), opts.get("--duration", "0.005ms"),
                               opts["--set"], opts.get("--shock"))
        return Base(["reciprocity", "scen.toml", "--solid", "rigid", "--duration", "0.005ms", "--out", "rec"], ["rec"], check)
    if command == "animate":
        def check(box, o, extra):
            verify_movie(box / "m.gif", int(_options(extra).get("--frames", 3)))
        return Base(["animate", "good.nc", "-o", "m.gif", "--frames", "3", "--fps", "5"], ["m.gif"], check)
    if command == "export":
        def check(box, o, extra):
            fmts = _options(extra).get("--format", "csv")
            verify_export(box / "exp", box / "good.nc", fmts.split(","))
        return Base(["export", "good.nc", "-o", "exp", "--format", "csv"], ["exp"], check)
    if command == "wavefield":
        def check(box, o, extra):
            opts = _options(extra)
            frames = int(opts.get("--frames", 120)) if "--movie" in opts else None
            verify_wavefield(box / "wf", box / "plate.nc", frames)
        return Base(["wavefield", "plate.nc", "-o", "wf"], ["wf"], check)
    if command == "map":
        return Base(["map", "summary.nc", "-o", "map.png", "--metric", "peak_velocity_m_s"], ["map.png"],
                    lambda box, o, e: verify_picture(box / "map.png"))
    if command == "scenarios":
        return Base(["scenarios"], [], lambda box, o, e: assert_in("paper", o.stdout))
    if command == "--version":
        return Base(["--version"], [], lambda box, o, e: assert_in(f"granel {granel.__version__}", o.stdout))
    if command == "paper":
        return Base(["paper", "--out", "pout", "--no-animations", "--no-free-edge"], ["pout"], long_work=True)
    if command == "bench":
        return Base(["bench", "--quick", "--no-fresh"], [], long_work=True)
    if command == "sweep":
        return Base(["sweep", "sweep.toml", "-o", "sout"], ["sout"], long_work=True)
    if command == "spectrum":
        return Base(["spectrum", "nb.toml", "--drive", "C:1", "--measure", "C:20", "--frequencies", "5kHz:25kHz:3",
                     "--amplitudes", "0.1", "-o", "sp.nc"], ["sp.nc", "sp.png", "sp.md", "sp.cases"], long_work=True)
    if command == "design":
        return Base(["design", "design.toml", "-o", "dout"], ["dout"], long_work=True)
    raise KeyError(command)


def assert_in(needle, text):
    assert needle in text, f"{needle!r} not in {text[:300]!r}"


def check_case(box: Path, b: Base, extra=(), outputs=(), names=(), refuse=False, outcome=None) -> Outcome:
    """Run a base invocation with `extra` arguments and check the contract; `refuse`: the case
    must end with exit 2 before any work (never at a stand-in), its error naming one of `names`;
    an exit 0 (or a stand-in reached) must pass the base's reference check."""
    o = outcome or invoke(box, [*b.args, *extra], [*b.outputs, *outputs])
    if refuse:
        assert o.code == 2 and not o.accepted, f"a hostile value was not refused (exit 2){' but reached the work' if o.accepted else ''}\n{o}"
        if names:
            assert any(n in o.error for n in names), f"the error names none of {names}\n{o}"
    if o.code == 0:
        assert not b.long_work, f"a long command ended 0 without its work\n{o}"
        if b.verify is not None:
            try:
                with _chdir(box):
                    b.verify(box, o, list(extra))
            except Exception as e:
                raise AssertionError(f"exit 0, but the reference check fails: {e}\n{o}") from e
    return o


# ------------------------------------------------------------------------------------------------
# 1. hostile numbers and words for every option


NONFINITE = ["nan", "inf", "-inf"]
WRONG = ["word", "[1, 2]", "true", ""]
NEGATIVE = ["-1", "-1e300"]
ZERO = ["0"]
HUGE = ["1e300"]
TINY = ["1e-300"]
HUGE_INT = ["1" + "0" * 300]
NUMBERS = ZERO + NEGATIVE + NONFINITE + HUGE + TINY + WRONG + HUGE_INT
WORDS = ["word", "", "nan", "-1", "1e300", "true", "[1, 2]", "SSGM:ZZ", "LSGM:99", "é:ü", "a;b", "../x", " "]


def _all(*groups):
    return {v for g in groups for v in g}


COUNTS = _all(ZERO, NEGATIVE, NONFINITE, HUGE, TINY, WRONG)  # a whole number >= 1 refuses these
POSITIVE = _all(ZERO, NEGATIVE, NONFINITE, WRONG)  # a finite number > 0 refuses these

WAVEFIELD_BANDS = ["3", "0,1e300", "12", "5,3", "0,0", "-1,200", "0,nan", "0,inf", "1,,2", "0,", ",",
                   "0;200", "0,1e-300", "1e-300,2e-300", "1e300,1e301", ",".join(str(100 * k) for k in range(14))]
WAVEFIELD_FITS = ["1us:4us", "2us:4us", "0:1e-300", "1ms:2ms", "0:1e300", "4us:1us", "0ms:0ms",
                  "nan:1ms", "0:inf", "-1us:3us", "1us:2us:3us", ":", "a:b", "1us:", "0.1ms"]

# (command, option): (values to try, the values that must be refused)
OPTIONS = {
    ("run", "--shock"): (NUMBERS, _all(NONFINITE, WRONG, HUGE, HUGE_INT, ["-1e300"])),  # 0, -1: no or a reversed shock
    ("run", "--duration"): (NUMBERS, _all(NUMBERS)),
    ("run", "--dt"): (NUMBERS, _all(NUMBERS)),
    ("run", "--checkpoint-every"): (NUMBERS, _all(NONFINITE, WRONG, NEGATIVE)),
    ("run", "--max-wall"): (NUMBERS, _all(NONFINITE, WRONG, NEGATIVE, ZERO)),
    ("run", "--solid"): (WORDS, _all(WORDS)),
    ("run", "--excite"): (WORDS, _all(WORDS)),
    ("run", "--solver"): (WORDS, _all(WORDS)),
    ("show", "--solid"): (WORDS, _all(WORDS)),
    ("modes", "--count"): (NUMBERS, COUNTS),
    ("modes", "--solid"): (WORDS, _all(WORDS)),
    ("reciprocity", "--shock"): (NUMBERS, _all(NONFINITE, WRONG, HUGE, HUGE_INT, ["-1e300"])),
    ("reciprocity", "--duration"): (NUMBERS, _all(NUMBERS)),
    ("reciprocity", "--a"): (WORDS, _all(WORDS)),
    ("reciprocity", "--b"): (WORDS, _all(WORDS)),
    ("reciprocity", "--solid"): (WORDS, _all(WORDS)),
    ("animate", "--magnification"): (NUMBERS, POSITIVE),
    ("animate", "--frames"): (NUMBERS, COUNTS),
    ("animate", "--fps"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("animate", "--field"): (WORDS, _all(WORDS)),
    ("paper", "--workers"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("paper", "--solver"): (WORDS, _all(WORDS)),
    ("bench", "--duration"): (NUMBERS, _all(NUMBERS)),
    ("bench", "--cases"): (WORDS, _all(WORDS)),
    ("sweep", "--workers"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("spectrum", "--cycles"): (NUMBERS, _all(POSITIVE, HUGE, HUGE_INT)),
    ("spectrum", "--window-cycles"): (NUMBERS, _all(POSITIVE, HUGE, HUGE_INT)),
    ("spectrum", "--ramp-cycles"): (NUMBERS, _all(NONFINITE, WRONG, NEGATIVE, HUGE, HUGE_INT)),
    ("spectrum", "--samples"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("spectrum", "--workers"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("spectrum", "--frequencies"): (NUMBERS + ["1kHz:5kHz:0", "1kHz:5kHz:-3", "nan:5kHz:3", "1kHz:inf:3", "5kHz:1kHz:1e300",
                                              "0:1kHz:3", "1e-300:1e-299:2"], _all(NUMBERS) | {
        "1kHz:5kHz:0", "1kHz:5kHz:-3", "nan:5kHz:3", "1kHz:inf:3", "5kHz:1kHz:1e300", "0:1kHz:3", "1e-300:1e-299:2"}),
    ("spectrum", "--amplitudes"): (NUMBERS + ["1,nan", "1,,2", "1e300,1"], _all(NONFINITE, WRONG, NEGATIVE, ZERO, HUGE,
                                                                               HUGE_INT) | {"1,nan", "1e300,1"}),
    ("spectrum", "--drive"): (WORDS, _all(WORDS)),
    ("design", "--trials"): (NUMBERS, COUNTS),
    ("design", "--workers"): (NUMBERS, _all(COUNTS, HUGE_INT)),
    ("design", "--timeout"): (NUMBERS, _all(NONFINITE, WRONG, NEGATIVE, ZERO)),
    ("export", "--format"): (WORDS + ["csv,", "vtk,vtk", "CSV"], _all(WORDS) - {"", " "}),  # added to --format csv
    ("map", "--metric"): (WORDS + ["status", "arrival_measured_s"], _all(WORDS) | {"status", "arrival_measured_s"}),
    ("map", "--x"): (WORDS, _all(WORDS)),
    ("map", "--y"): (WORDS, _all(WORDS)),
    ("init", "NAME"): (WORDS + ["/abs", ".hidden", "a" * 300], {"", " ", "../x", "/abs", ".hidden"}),
    # wavefield on plate.nc (PLATE: wavenumbers every 157 rad/m, up to 6597; the default k_max 721 rad/m). --bands:
    # 1 to 12 bands or ascending edges >= 0, each band holding one of the result's wavenumbers (12 equal bands
    # up to 721 rad/m are 60 rad/m wide: the first holds none); --k-max: a positive number reaching the result's
    # second wavenumber (314 rad/m), its equal bands each holding one; --fit: START:END within the record, holding
    # 3 or more of its solid outputs (0, 1, ..., 5 us); --frames, --fps as animate's (with --movie)
    ("wavefield", "--bands"): (NUMBERS + WAVEFIELD_BANDS,
                               _all(NUMBERS) | (set(WAVEFIELD_BANDS) - {"3", "0,1e300"})),
    ("wavefield", "--k-max"): (NUMBERS + ["200", "320", "2000"], _all(NUMBERS) | {"200", "320"}),
    ("wavefield", "--fit"): (NUMBERS + WAVEFIELD_FITS,
                             _all(NUMBERS) | (set(WAVEFIELD_FITS) - {"1us:4us"})),
    ("wavefield", "--frames"): (NUMBERS, COUNTS),
    ("wavefield", "--fps"): (NUMBERS, _all(COUNTS, HUGE_INT)),
}

# (command, field, value) that once ended in an internal error while building or running (findings
# F6: LinAlgError in the exact integrator; F7: ZeroDivisionError, a singular factor, ARPACK, a
# contact on a clamped node): each is now a refusal naming the field or a confirmed result
FORMER_FINDINGS = {
    ("run", "simulation.max_step", "1e300"): "F6", ("reciprocity", "simulation.max_step", "1e300"): "F6",
    ("modes", "media.0.center_y", "1e-300"): "F7", ("modes", "solid.width", "1e-300"): "F7",
    ("modes", "solid.length", "1e-300"): "F7", ("modes", "solid.thickness", "1e300"): "F7",
    ("modes", "materials.steel.rho", "1e300"): "F7"}


def _option_case(command, option, value):
    b = base(command)
    if option == "NAME":  # init's argument
        b = Base(["init", value, "-o", "new.toml"], ["new.toml"], lambda box, o, e: verify_scenario_file(box / "new.toml"))
        return b, []
    if command == "wavefield" and option in ("--frames", "--fps"):
        return b, ["--movie", option, value]  # the movie's options, with the movie
    return b, [option, value]


# what an error may name for an option: the option, or the scenario field it sets (a resource
# refusal names the run's estimate: "this run (N granules, ...) needs about ...")
FIELD_OF = {"--shock": ("excitations.0",), "--duration": ("simulation.duration", "this run ("),
            "--dt": ("simulation.dt", "this run ("), "--checkpoint-every": ("simulation.checkpoint_every",),
            "--solid": ("solid.kind", "the solid is"), "--excite": ("excitations.0.granule",),
            "--solver": ("simulation.solver",), "--a": ("excitations.0.granule",), "--b": ("excitations.0.granule",),
            "--measure": ("spectrum.measure",),
            "--cycles": ("this run (",), "--window-cycles": ("this run (",), "--ramp-cycles": ("this run (",),
            "--frequencies": ("simulation.dt", "this run ("), "--amplitudes": ("excitations.0",)}


def _names(command, option):
    if option == "NAME":
        return ("NAME",)
    bare = option.lstrip("-")
    return (option, *([bare] if len(bare) > 3 else []), *FIELD_OF.get(option, ()))


OPTION_VALUES = [(c, o, v) for (c, o), (values, _) in OPTIONS.items() for v in values]


@settings(max_examples=130, **HYPOTHESIS)
@given(case=st.sampled_from(OPTION_VALUES))
def test_hostile_option_values(assets, case):
    """A hostile number or word for an option: refused (exit 2, naming the option) when it is
    no value of the option, else the contract and, on exit 0, the reference check."""
    command, option, value = case
    bad = value in OPTIONS[(command, option)][1]
    box = new_box(assets)
    try:
        b, extra = _option_case(command, option, value)
        check_case(box, b, extra, refuse=bad, names=_names(command, option))
    finally:
        _release(box)


COMMANDS = ["run", "show", "init", "modes", "paper", "reciprocity", "animate", "bench", "sweep", "spectrum", "design",
            "export", "map", "scenarios", "wavefield"]
USAGE = [[], ["scenarios"], ["--bogus"], ["nocommand"], ["--version"], ["--version", "--bogus"], ["scenarios", "extra"],
         ["run", "--output-every", "1us"], ["run", "paper", "--fmax", "5"], ["run", "paper", "--solid"],
         ["run", "paper", "--set"], ["run", "paper", "--set", "novalue"], ["run", "paper", "--set", "=1"],
         ["run", "paper", "--set", "media.9.radius=1"], ["run", "paper", "--set", "a.b.c.d=1"],
         ["show", "paper", "--set", "media.0=-", "--set", "media.0=-", "--set", "media.0=-", "--resolved"],
         ["animate", "good.nc", "--frames"], ["export"], ["map", "summary.nc", "--metric"],
         *[[c, "--help"] for c in COMMANDS], *[[c] for c in COMMANDS if c not in ("scenarios", "modes", "paper", "bench", "reciprocity")],
         *[[c, "--no-such-option"] for c in COMMANDS]]


@pytest.mark.parametrize("args", USAGE, ids=lambda a: " ".join(a) or "(nothing)")
def test_usage(assets, args):
    """Missing arguments, unknown options or commands, removed options, malformed --set: exit 2
    with one line (0 for --help and --version, which print and write nothing)."""
    box = new_box(assets)
    try:
        o = invoke(box, args)
        if "--help" in args or args[:1] == ["--version"] or not args:  # (--version --bogus: either)
            assert o.code in (0, 2) and not o.accepted, o
            if args == ["--version"]:
                assert o.code == 0 and o.stdout.strip() == f"granel {granel.__version__}", o
        elif args == ["scenarios"]:
            assert o.code == 0 and "paper" in o.stdout, o
        else:
            assert o.code == 2 and not o.accepted, f"expected a usage error (exit 2)\n{o}"
    finally:
        _release(box)


# a sample of scenario fields, set with --set on run (and show, modes, reciprocity)
FIELDS = ["media.0.radius", "media.1.radius", "media.0.gap", "media.0.columns.0", "media.0.center_y", "contact.mu",
          "contact.alpha_n", "contact.k_s", "solid.width", "solid.length", "solid.thickness", "solid.x0",
          "materials.steel.E", "materials.steel.rho", "materials.steel.nu", "excitations.0.fmax", "excitations.0.tau",
          "excitations.0.t0", "simulation.output_every", "simulation.rtol", "simulation.atol", "simulation.max_step",
          "simulation.ledger_tol", "simulation.balance_limit", "simulation.overlap_limit", "simulation.max_iterations",
          "simulation.abstol", "simulation.duration", "simulation.dt"]
SET_VALUES = ["0", "-1", "nan", "inf", "-inf", "1e300", "1e-300", "word", '"word"', "[1, 2]", "true", "{a = 1}", ""]
SET_BAD = {"nan", "inf", "-inf", "word", '"word"', "[1, 2]", "true", "{a = 1}", ""}


@settings(max_examples=70, **HYPOTHESIS)
@given(command=st.sampled_from(["run", "run", "run", "show", "modes", "reciprocity"]), path=st.sampled_from(FIELDS),
       value=st.sampled_from(SET_VALUES))
def test_hostile_scenario_fields(assets, command, path, value):
    """`--set FIELD=VALUE` with a hostile value: a non-number refused naming the field; any
    other value the contract, and an exit 0 a confirmed result."""
    if path == "excitations.0.fmax":
        extra = ["--set", "excitations.0.shock=-", "--set", f"{path}={value}"]
    else:
        extra = ["--set", f"{path}={value}"]
    box = new_box(assets)
    try:
        check_case(box, base(command), extra, refuse=value in SET_BAD, names=(path.rsplit(".", 1)[0],))
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# 2. hostile paths, as every command's inputs and outputs


def _run_base(scenario, out="out.nc", overrides=(), extra=(), outputs=None):
    """`granel run SCENARIO -o OUT EXTRA` (EXTRA setting `overrides`), checked against the scenario."""
    def check(box, o, _):
        verify_result(Path(os.fsdecode(out)), scenario_of(os.fsdecode(scenario), list(overrides)))
    stem = os.fsdecode(out).rsplit(".", 1)[0]
    return Base(["run", scenario, "-o", out, "--max-wall", "60s", *extra],
                outputs if outputs is not None else [out, stem + ".ckpt"], check)


def _input_role(role: str, p, kind: str = "") -> Base:
    """The command of `role` reading its input from `p` (a hostile path of `kind`)."""
    f = os.fsdecode(p)
    if role == "run scenario":
        return _run_base(p)
    if role == "show scenario":
        return Base(["show", p, "-o", "pic.png"], ["pic.png"], lambda box, o, e: verify_picture(Path("pic.png")))
    if role == "modes scenario":
        return Base(["modes", p, "--json", "--count", "3"], [], lambda box, o, e: verify_modes_json(o.stdout, 3))
    if role == "reciprocity scenario":
        return Base(["reciprocity", p, "--solid", "rigid", "--duration", "0.005ms", "--out", "rec"], ["rec"],
                    lambda box, o, e: verify_reciprocity(Path("rec"), f, "rigid", "0.005ms", [], "strong"))
    if role == "animate result":
        return Base(["animate", p, "-o", "m.gif", "--frames", "3", "--fps", "5"], ["m.gif"],
                    lambda box, o, e: verify_movie(Path("m.gif"), 3))
    if role == "export result":
        return Base(["export", p, "-o", "exp", "--format", "csv"], ["exp"],
                    lambda box, o, e: verify_export(Path("exp"), Path(f), ["csv"]))
    if role == "map summary":
        return Base(["map", p, "-o", "map.png", "--metric", "peak_velocity_m_s"], ["map.png"],
                    lambda box, o, e: verify_picture(Path("map.png")))
    if role == "wavefield result":
        return Base(["wavefield", p, "-o", "wf"], ["wf"], lambda box, o, e: verify_wavefield(Path("wf"), Path(f)))
    if role == "sweep file":
        return Base(["sweep", p, "-o", "sout"], ["sout"], long_work=True)
    if role == "design file":
        return Base(["design", p, "-o", "dout"], ["dout"], long_work=True)
    if role == "spectrum scenario":
        return Base(["spectrum", p, "--drive", "C:1", "--measure", "C:20", "--frequencies", "5kHz:25kHz:3", "--amplitudes",
                     "0.1", "-o", "sp.nc"], ["sp.nc", "sp.png", "sp.md", "sp.cases"], long_work=True)
    if role == "run --resume":
        # a checkpoint resumes the run whose result is its name with .nc: for a valid checkpoint, that
        # name; else another, so that the case folder's own run.ckpt does not stop the run first
        ov = ['simulation.checkpoint_every="0.002ms"']
        valid = kind in ("symlink", "readonly", "unreadable", "non_utf8")
        out = (p[: -len(b".ckpt")] + b".nc" if isinstance(p, bytes) else p[: -len(".ckpt")] + ".nc") if valid else "other.nc"
        ckpt = out[: -3] + (b".ckpt" if isinstance(out, bytes) else ".ckpt")
        # through a link, the checkpoint it points to is the one the run resumes from and replaces
        return _run_base("scen.toml", out, ov, ["--checkpoint-every", "0.002ms", "--resume", p],
                         outputs=[out, ckpt, *(["run.ckpt"] if kind == "symlink" else [])])
    if role == "granules_file":
        ov = [f'media.0.granules_file="{f}"']
        return _run_base("chain.toml", "out.nc", ov, ["--set", ov[0]])
    if role == "table file":
        ov = [f'excitations.0.file="{f}"']
        return _run_base("chain.toml", "out.nc", ov, ["--set", ov[0]])
    raise KeyError(role)


# role: the valid input it reads (in the case folder)
INPUT_ROLES = {"run scenario": "scen.toml", "show scenario": "scen.toml", "modes scenario": "beam.toml",
               "reciprocity scenario": "scen.toml", "animate result": "good.nc", "export result": "good.nc",
               "map summary": "summary.nc", "wavefield result": "plate.nc", "sweep file": "sweep.toml",
               "design file": "design.toml", "spectrum scenario": "nb.toml", "run --resume": "run.ckpt",
               "granules_file": "beads.csv", "table file": "force.csv"}
# kind: the exit codes reading.py documents (0: the input is read as the valid one)
INPUT_KINDS = {"missing": {2}, "folder": {4}, "under_file": {2}, "dangling": {2}, "long": {2}, "device": {4},
               "symlink": {0}, "readonly": {0}, "unreadable": {0, 4}, "fifo": {4}, "fifo (process)": {4}, "non_utf8": {0}}
# a run replaces its checkpoint as it goes: a read-only one is refused before the run (exit 4)
EXCEPTIONS = {("run --resume", "readonly"): {4}}
SUBPROCESS_KINDS = {"non_utf8", "fifo (process)"}
# the subprocess cases of the quick suite (each takes 1-6 s); the others are marked slow
QUICK_PROCESS = {("run scenario", "non_utf8"), ("run scenario", "fifo (process)"), ("granules_file", "non_utf8"),
                 ("export -o", "non_utf8")}
# in-process cases that end in a whole run (0.3-2 s each; a wavefield 2 s) and repeat what another case shows, slow
SLOW_IN_PROCESS = {(r, k) for r in ("show scenario", "modes scenario", "reciprocity scenario", "export result",
                                    "map summary", "wavefield result", "table file", "sweep file", "design file",
                                    "spectrum scenario")
                   for k in ("readonly", "unreadable")} | {
    (r, "unreadable") for r in INPUT_ROLES if IS_ROOT} | {  # root reads it anyway: as "readonly"
    (r, "readonly_dir") for r in ("show -o", "modes --plot", "init -o", "animate -o", "map -o", "spectrum -o",
                                  "export -o", "wavefield -o", "reciprocity --out", "sweep --out", "paper --out",
                                  "design -o")} | {
    ("reciprocity --out", "empty_folder"), ("modes --plot", "dangling")} | {  # as reciprocity-symlink, modes-own
    ("wavefield result", "symlink"), ("wavefield -o", "empty_folder")}  # as the wavefield of F21: an exit 0, confirmed


def hostile_input(box: Path, kind: str, valid: str):
    """The path (str, or bytes for a name that is not UTF-8) of a hostile input of `kind`."""
    suffix = Path(valid).suffix
    if kind == "missing":
        return "nothing" + suffix
    if kind == "folder":
        (box / f"adir{suffix}").mkdir()
        return f"adir{suffix}"
    if kind == "under_file":
        return f"plain.txt/x{suffix}"
    if kind == "dangling":
        os.symlink("nowhere" + suffix, box / f"dangling{suffix}")
        return f"dangling{suffix}"
    if kind == "long":
        return "a" * 300 + suffix
    if kind == "device":
        return "/dev/null"
    if kind == "symlink":
        os.symlink(valid, box / f"link{suffix}")
        return f"link{suffix}"
    if kind == "readonly":
        os.chmod(box / valid, 0o444)
        return valid
    if kind == "unreadable":
        os.chmod(box / valid, 0o000)
        return valid
    if kind in ("fifo", "fifo (process)"):
        os.mkfifo(box / f"pipe{suffix}")
        return f"pipe{suffix}"
    if kind == "non_utf8":
        name = b"\xff\xfe-" + os.fsencode(valid)
        shutil.copy(box / valid, os.path.join(os.fsencode(box), name))
        return name
    raise KeyError(kind)


def _input_case(assets, role, kind):
    box = new_box(assets)
    try:
        valid = INPUT_ROLES[role]
        if role == "run --resume" and kind in ("symlink", "non_utf8"):
            valid = "run.ckpt"
        p = hostile_input(box, kind, valid)
        b = _input_role(role, p, kind)
        if kind in SUBPROCESS_KINDS:
            o = invoke_subprocess(box, b.args, b.outputs)
        else:
            o = invoke(box, b.args, b.outputs)
        expected = EXCEPTIONS.get((role, kind), INPUT_KINDS[kind])
        if b.long_work and 0 in expected:  # valid options: the stand-in is reached
            assert o.accepted or o.code in expected - {0}, f"a valid input did not reach the work\n{o}"
        else:
            assert o.code in expected, f"{role} from a {kind} path: exit {o.code}, expected {sorted(expected)}\n{o}"
        if o.code in (2, 4) and not o.accepted and kind not in ("device", "long", "non_utf8"):
            name = os.fsdecode(p) if kind != "under_file" else "x"
            assert name in o.error or Path(name).name in o.error, f"the error does not name {name}\n{o}"
        return check_case(box, b, outcome=o)
    finally:
        _release(box)


def _slow_if(cond):
    return [pytest.mark.slow] if cond else []


@pytest.mark.parametrize("role,kind", [pytest.param(r, k, id=f"{r}-{k}", marks=_slow_if((r, k) in SLOW_IN_PROCESS))
                                       for r in INPUT_ROLES for k in INPUT_KINDS if k not in SUBPROCESS_KINDS])
def test_hostile_input_paths(assets, role, kind):
    _input_case(assets, role, kind)


def test_every_path_option_leaves_the_read_check_to_granel():
    """click's own check of a path refuses an unreadable file with exit 2 and its wording, and
    only to a user who is not root (root reads it anyway): no path option of any command asks
    for it, so that granel's reading (exit 4, naming the file) answers for every user."""
    from typer.main import get_command

    from granel.cli import app

    group = get_command(app)
    checked = 0
    for name, command in group.commands.items():
        for param in command.params:
            given = param.type_descriptor  # typer's record of the annotation and the options it was given
            if given.annotation is Path:
                checked += 1
                assert not given.parameter_info.readable, f"granel {name} {param.name}: click checks its readability"
    assert checked >= 15  # every input and output file of the commands (20 today)


def _process_cases():
    for role in ["run scenario", "show scenario", "animate result", "export result", "map summary", "wavefield result",
                 "sweep file", "design file", "spectrum scenario", "run --resume", "granules_file", "table file"]:
        for kind in sorted(SUBPROCESS_KINDS):
            marks = _slow_if((role, kind) not in QUICK_PROCESS)
            yield pytest.param(role, kind, marks=marks, id=f"{role}-{kind}")


@pytest.mark.parametrize("role,kind", list(_process_cases()))
def test_hostile_input_paths_in_a_process(assets, role, kind):
    """A FIFO (which would block a reader) and a name that is not UTF-8, in a real process."""
    if role in ("sweep file", "design file", "spectrum scenario") and kind == "non_utf8":
        pytest.skip("the stand-ins live in this process only: a valid input would start a study")
    _input_case(assets, role, kind)


def _mount_tmpfs(where: Path, size: str, readonly=False) -> bool:
    where.mkdir(parents=True, exist_ok=True)
    opts = f"size={size}" + (",ro" if readonly else "")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], capture_output=True, text=True)
    return res.returncode == 0


def _unmount(where: Path) -> None:
    subprocess.run(["umount", str(where)], capture_output=True)


@pytest.fixture(scope="module")
def readonly_fs(tmp_path_factory):
    """A read-only file system (a tmpfs mounted ro): what a read-only folder is even for root."""
    if not IS_ROOT:
        yield None
        return
    where = tmp_path_factory.mktemp("rofs")
    if not _mount_tmpfs(where, "64k", readonly=True):
        yield None
        return
    try:
        yield where
    finally:
        _unmount(where)


def _output_role(role: str, p):
    """(the command of `role` writing to `p`, the input it reads, whether the output is a folder)."""
    f = os.fsdecode(p)
    if role == "run -o":
        return _run_base("scen.toml", p), "scen.toml", False
    if role == "show -o":
        return Base(["show", "scen.toml", "-o", p], [p], lambda box, o, e: verify_picture(Path(f))), "scen.toml", False
    if role == "modes --plot":
        return Base(["modes", "beam.toml", "--count", "3", "--plot", p], [p],
                    lambda box, o, e: verify_picture(Path(f))), "beam.toml", False
    if role == "init -o":
        return Base(["init", "mine", "-o", p], [p], lambda box, o, e: verify_scenario_file(Path(f), "mine")), "scen.toml", False
    if role == "animate -o":
        return Base(["animate", "good.nc", "-o", p, "--frames", "3", "--fps", "5"], [p],
                    lambda box, o, e: verify_movie(Path(f), 3)), "good.nc", False
    if role == "map -o":
        return Base(["map", "summary.nc", "-o", p, "--metric", "peak_velocity_m_s"], [p],
                    lambda box, o, e: verify_picture(Path(f))), "summary.nc", False
    if role == "spectrum -o":
        stem = f[:-3] if f.endswith(".nc") else f
        return Base(["spectrum", "nb.toml", "--drive", "C:1", "--measure", "C:20", "--frequencies", "5kHz:25kHz:3",
                     "--amplitudes", "0.1", "-o", p], [p, stem + ".png", stem + ".md", stem + ".cases"], long_work=True), \
            "nb.toml", False
    if role == "export -o":
        return Base(["export", "good.nc", "-o", p, "--format", "csv"], [p],
                    lambda box, o, e: verify_export(Path(f), Path("good.nc"), ["csv"])), "good.nc", True
    if role == "wavefield -o":
        return Base(["wavefield", "plate.nc", "-o", p], [p],
                    lambda box, o, e: verify_wavefield(Path(f), Path("plate.nc"))), "plate.nc", True
    if role == "reciprocity --out":
        return Base(["reciprocity", "scen.toml", "--solid", "rigid", "--duration", "0.005ms", "--out", p], [p],
                    lambda box, o, e: verify_reciprocity(Path(f), "scen.toml", "rigid", "0.005ms", [], "strong")), \
            "scen.toml", True
    if role == "sweep --out":
        return Base(["sweep", "sweep.toml", "-o", p], [p], long_work=True), "sweep.toml", True
    if role == "paper --out":
        return Base(["paper", "--out", p, "--no-animations", "--no-free-edge"], [p], long_work=True), "scen.toml", True
    if role == "design -o":
        return Base(["design", "design.toml", "-o", p], [p], long_work=True), "design.toml", True
    raise KeyError(role)


OUTPUT_SUFFIX = {"run -o": ".nc", "show -o": ".png", "modes --plot": ".png", "init -o": ".toml", "animate -o": ".gif",
                 "map -o": ".png", "spectrum -o": ".nc", "export -o": "", "wavefield -o": "", "reciprocity --out": "",
                 "sweep --out": "", "paper --out": "", "design -o": ""}
OWN = {".nc": "good.nc", ".png": "g.png", ".gif": "g.gif", ".toml": None}  # a file granel wrote, by suffix
# kind: the exit codes the output rules (guard.outputs) give; None: any code of the contract
FILE_KINDS = {"folder": {2}, "foreign": {2}, "readonly_own": {2}, "own": {0}, "under_file": {2}, "symlink_to_input": {2},
              "same_as_input": {2}, "long": {2}, "dangling": {0}, "device": {2}, "readonly_fs": {4},
              "readonly_dir": None, "fifo": {2}, "fifo (process)": {2}, "non_utf8": {0}}
FOLDER_KINDS = {"file": {2}, "foreign_folder": {2}, "empty_folder": {0}, "under_file": {2}, "symlink_to_input": {2},
                "long": {2}, "device": {2}, "readonly_fs": {4}, "readonly_dir": None, "fifo": {2}, "fifo (process)": {2},
                "non_utf8": {0}}


def hostile_output(box: Path, kind: str, suffix: str, valid_input: str, rofs):
    name = "out" + suffix
    if kind == "folder":
        (box / name).mkdir()
    elif kind in ("foreign", "file"):
        (box / name).write_text("the user's own notes\n")
    elif kind in ("own", "readonly_own"):
        shutil.copy(box / OWN[suffix], box / name) if OWN.get(suffix) else (box / name).write_text('name = "x"\n')
        if kind == "readonly_own":
            os.chmod(box / name, 0o444)
    elif kind == "foreign_folder":
        (box / name).mkdir()
        (box / name / "notes.txt").write_text("the user's own notes\n")
    elif kind == "empty_folder":
        (box / name).mkdir()
    elif kind == "under_file":
        return f"plain.txt/{name}"
    elif kind == "symlink_to_input":
        os.symlink(valid_input if suffix else ".", box / f"link{suffix}")  # a folder output: the inputs' folder
        return f"link{suffix}"
    elif kind == "same_as_input":
        return valid_input
    elif kind == "long":
        return "o" * 300 + suffix
    elif kind == "dangling":
        os.symlink(f"target{suffix}", box / f"link{suffix}")
        return f"link{suffix}"
    elif kind == "device":
        return "/dev/null"
    elif kind == "readonly_fs":
        if rofs is None:
            pytest.skip("needs root and a tmpfs mount for a read-only file system")
        return str(rofs / name)
    elif kind == "readonly_dir":
        (box / "locked").mkdir()
        os.chmod(box / "locked", 0o555)
        return f"locked/{name}"
    elif kind in ("fifo", "fifo (process)"):
        os.mkfifo(box / name)
    elif kind == "non_utf8":
        return b"\xff\xfe-" + os.fsencode(name)
    return name


def _output_cases(subprocess_kinds: bool):
    for role, suffix in OUTPUT_SUFFIX.items():
        kinds = FOLDER_KINDS if not suffix else FILE_KINDS
        for kind in kinds:
            if (kind in SUBPROCESS_KINDS) != subprocess_kinds:
                continue
            if subprocess_kinds and kind == "non_utf8" and role in ("spectrum -o", "sweep --out", "paper --out", "design -o"):
                continue  # valid: would start a study in the subprocess (no stand-ins there)
            if role == "init -o" and kind in ("same_as_input", "symlink_to_input"):
                continue  # init reads nothing
            slow = (role, kind) not in QUICK_PROCESS if subprocess_kinds else (role, kind) in SLOW_IN_PROCESS
            yield pytest.param(role, kind, id=f"{role}-{kind}", marks=_slow_if(slow))


def _output_case(assets, rofs, role, kind):
    box = new_box(assets)
    try:
        suffix = OUTPUT_SUFFIX[role]
        _, valid_input, folder = _output_role(role, "x" + suffix)
        p = hostile_output(box, kind, suffix, valid_input, rofs)
        b, _, _ = _output_role(role, p)
        expected = (FOLDER_KINDS if folder else FILE_KINDS)[kind]
        if role == "init -o" and kind in ("own", "readonly_own"):
            expected = {2}  # init never replaces a file
        if kind == "dangling":
            b.outputs.append(f"target{suffix}")
        o = invoke_subprocess(box, b.args, b.outputs) if kind in SUBPROCESS_KINDS else invoke(box, b.args, b.outputs)
        if expected is not None:
            if b.long_work and 0 in expected:
                assert o.accepted, f"a valid output did not reach the work\n{o}"
            else:
                assert o.code in expected and not o.accepted, \
                    f"{role} to a {kind} path: exit {o.code}, expected {sorted(expected)}\n{o}"
        if o.code == 0 and kind == "dangling":
            assert (box / f"target{suffix}").exists(), f"the result is not where the link points\n{o}"
        return check_case(box, b, outcome=o)
    finally:
        _release(box)


@pytest.mark.parametrize("role,kind", list(_output_cases(False)))
def test_hostile_output_paths(assets, readonly_fs, role, kind):
    _output_case(assets, readonly_fs, role, kind)


@pytest.mark.parametrize("role,kind", list(_output_cases(True)))
def test_hostile_output_paths_in_a_process(assets, readonly_fs, role, kind):
    _output_case(assets, readonly_fs, role, kind)


# ------------------------------------------------------------------------------------------------
# 3. hostile files: empty, truncated, binary, of another kind, damaged


TEXT_READERS = {"run scenario": "scen.toml", "granules_file": "beads.csv", "table file": "force.csv",
                "sweep file": "sweep.toml", "design file": "design.toml", "spectrum scenario": "nb.toml"}
RESULT_READERS = {"animate result": "good.nc", "export result": "good.nc", "map summary": "summary.nc",
                  "wavefield result": "plate.nc"}
CONTENT_KINDS = {
    "run scenario": ["empty", "truncated", "binary", "netcdf", "nul"],
    "granules_file": ["empty", "truncated", "binary", "netcdf", "wrong_columns", "extra_column", "header_only"],
    "table file": ["empty", "truncated", "binary", "netcdf", "wrong_columns", "extra_column", "header_only"],
    "sweep file": ["empty", "truncated", "binary", "netcdf"],
    "design file": ["empty", "truncated", "binary", "netcdf"],
    "spectrum scenario": ["empty", "binary"],
    "animate result": ["empty", "truncated", "binary", "text", "other_kind", "dropped", "transposed", "nan"],
    "export result": ["empty", "truncated", "binary", "text", "other_kind", "dropped", "transposed", "nan"],
    "map summary": ["empty", "truncated", "binary", "text", "other_kind", "dropped", "transposed", "nan"],
    # and a result wavefield refuses as it is: a rigid solid's, one of 3 solid outputs (it needs 4)
    "wavefield result": ["empty", "truncated", "binary", "text", "other_kind", "dropped", "transposed", "nan", "rigid",
                         "short"],
    "run --resume": ["empty", "truncated", "binary", "netcdf", "flipped"],
}
BINARY = bytes(range(256)) * 4
# the variable a damage drops and the one it transposes or fills with NaN, by the file it damages
DROPPED = {"good.nc": "x", "summary.nc": "status", "plate.nc": "solid_eta_dot"}
DAMAGED = {"good.nc": "x", "summary.nc": "peak_velocity_m_s", "plate.nc": "solid_eta_dot"}


def damage(box: Path, role: str, kind: str) -> str:
    """Damage the input `role` reads, in place; returns its name."""
    valid = {**TEXT_READERS, **RESULT_READERS, "run --resume": "run.ckpt"}[role]
    path = box / valid
    raw = path.read_bytes()
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncated":
        path.write_bytes(raw[: len(raw) // 2])
    elif kind == "binary":
        path.write_bytes(BINARY)
    elif kind == "nul":
        path.write_bytes(raw[:40] + b"\x00" + raw[40:])
    elif kind == "text":
        path.write_text("this is not NetCDF\n")
    elif kind == "netcdf":
        path.write_bytes((box / "good.nc").read_bytes())
    elif kind == "wrong_columns":
        path.write_text(raw.decode().replace("radius", "r").replace("force", "f"))
    elif kind == "extra_column":
        lines = raw.decode().splitlines()
        path.write_text("\n".join([lines[0] + ",extra"] + [line + ",1" for line in lines[1:]]) + "\n")
    elif kind == "header_only":
        path.write_text(raw.decode().splitlines()[0] + "\n")
    elif kind == "flipped":
        b = bytearray(raw)
        for k in range(len(b) // 3, len(b) // 3 + 16):
            b[k] ^= 0xFF
        path.write_bytes(bytes(b))
    elif kind == "other_kind":  # a sweep summary given for a result, a result for a summary
        path.write_bytes((box / ("good.nc" if valid == "summary.nc" else "summary.nc")).read_bytes())
    elif kind == "rigid":  # a rigid solid's result for a plate's
        path.write_bytes((box / "good.nc").read_bytes())
    elif kind in ("dropped", "transposed", "nan", "short"):
        from granel.io.results import write_netcdf

        ds = xr.load_dataset(path, engine="h5netcdf")
        var = DAMAGED[valid]
        if kind == "short":
            ds = ds.isel(solid_time=slice(0, 3))
        elif kind == "dropped":
            ds = ds.drop_vars(DROPPED[valid])
        elif kind == "transposed":
            ds[var] = ds[var].transpose(*reversed(ds[var].dims))
        else:
            ds[var] = ds[var].where(False)
        path.unlink()
        write_netcdf(ds, path)
    else:
        raise KeyError(kind)
    return valid


# a damaged plate result that run.load_result refuses as it refuses animate's and export's (0.5 s each), slow
SLOW_CONTENT = {("wavefield result", k) for k in ("dropped", "transposed", "nan")}


def _content_cases():
    for role, kinds in CONTENT_KINDS.items():
        for kind in kinds:
            yield pytest.param(role, kind, id=f"{role}-{kind}", marks=_slow_if((role, kind) in SLOW_CONTENT))


@pytest.mark.parametrize("role,kind", list(_content_cases()))
def test_hostile_file_contents(assets, role, kind):
    """A damaged input: refused (exit 2 for content, 4 for a file that cannot be read as its
    format), naming the file; never an exit 0 with a result the reference check does not confirm."""
    box = new_box(assets)
    try:
        name = damage(box, role, kind)
        b = _input_role(role, name, "damaged")
        o = check_case(box, b)
        if kind != "transposed":  # a transposed variable is the same data: it may be read as it is
            assert o.code != 0 or (kind == "truncated" and role == "run scenario"), \
                f"a {kind} {role} was accepted\n{o}"
        if o.code in (2, 4) and not o.accepted:  # naming the file, or the option that asked for what it lacks
            assert name in o.error or Path(name).stem in o.error or (kind == "nan" and "--metric" in o.error), \
                f"the error does not name {name}\n{o}"
    finally:
        _release(box)


def test_a_damaged_summary_leaves_no_traceback(assets):
    """A summary whose HDF5 metadata is damaged (one byte inserted): exit 4, one line, and no
    traceback from the half-opened file's finaliser (it once printed h5netcdf's AttributeError)."""
    box = new_box(assets)
    try:
        raw = bytearray((box / "summary.nc").read_bytes())
        raw[len(raw) // 2:len(raw) // 2] = b"\x00"
        (box / "summary.nc").write_bytes(bytes(raw))
        o = invoke_subprocess(box, base("map").args, base("map").outputs)
        assert o.code == 4
    finally:
        _release(box)


@settings(max_examples=int(os.environ.get("HOSTILE_FUZZ", 40)), **HYPOTHESIS)
@given(role=st.sampled_from(sorted(CONTENT_KINDS)),
       how=st.sampled_from(["random", "flip", "cut", "splice"]),
       data=st.binary(min_size=0, max_size=512), where=st.floats(0.0, 1.0), count=st.integers(1, 64))
def test_fuzzed_file_contents(assets, role, how, data, where, count):
    """A valid input with random bytes (replaced, flipped, cut or spliced in): the contract, and an
    exit 0 only with a confirmed result."""
    box = new_box(assets)
    try:
        valid = {**TEXT_READERS, **RESULT_READERS, "run --resume": "run.ckpt"}[role]
        path = box / valid
        raw = bytearray(path.read_bytes())
        at = int(where * len(raw))
        if how == "random":
            raw = bytearray(data)
        elif how == "flip":
            for k in range(at, min(len(raw), at + count)):
                raw[k] ^= data[k % len(data)] if data else 0xFF
        elif how == "cut":
            raw = raw[:at]
        else:
            raw[at:at] = data
        path.write_bytes(bytes(raw))
        b = _input_role(role, valid, "damaged")
        b.args += ["--max-wall", "10s"] if b.args[0] == "run" else []  # a flipped digit may ask for a longer run
        check_case(box, b)
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# 4. granel's own cache, damaged (a private GRANEL_CACHE)


CACHE_RUN = ["run", "beam.toml", "--excite", "LSGM:12", "--duration", "0.01ms", "-o", "out.nc"]
SCALED = ["--set", "solid.thickness=0.0012"]  # a proportional beam: modes scaled from the cached record


@pytest.fixture(scope="module")
def pristine_cache(assets, tmp_path_factory):
    """A cache holding the beam's modes (and records), and the reference results of CACHE_RUN
    and of the scaled beam, each computed on a cache of its own."""
    refs = {}
    for name, extra in (("own", []), ("scaled", SCALED)):
        cache = tmp_path_factory.mktemp(f"cache-{name}")
        box = new_box(assets)
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("GRANEL_CACHE", str(cache))
            res = _invoke_raw([*CACHE_RUN, *extra], box)
        assert res.exit_code == 0, res.output
        refs[name] = xr.load_dataset(box / "out.nc", engine="h5netcdf")
        assert float(refs[name]["energy_solid"].max()) > 1e-3 * float(refs[name]["input_work"].max())  # the solid matters
        if name == "own":
            pristine = cache
    return pristine, refs


def _same_result(ds, ref) -> None:
    for v in ("x", "y", "v_x", "v_y", "energy_solid", "input_work"):
        a, b = ds[v].values, ref[v].values
        scale = max(float(np.abs(b).max()), 1e-300)
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-6 * scale, \
            f"{v} differs from the clean cache's run by {np.abs(a - b).max() / scale:.2e} of its scale"


CACHE_DAMAGE = ["truncated", "emptied", "zero_filled", "bit_flipped", "byte_flipped_run", "swapped"]


def damage_cache(folder: Path, name: str, kind: str, where: float, data: bytes = b"") -> None:
    path = folder / name
    raw = bytearray(path.read_bytes())
    at = min(int(where * len(raw)), max(len(raw) - 1, 0))
    if kind == "truncated":
        raw = raw[: len(raw) // 2]
    elif kind == "emptied":
        raw = bytearray()
    elif kind == "zero_filled":
        raw = bytearray(len(raw))
    elif kind == "bit_flipped":
        raw[at] ^= 0x01 << (len(data) % 8)
    elif kind == "byte_flipped_run":
        for k in range(at, min(len(raw), at + 64)):
            raw[k] ^= 0xFF
    elif kind == "swapped":  # another entry's bytes under this name
        others = sorted(p for p in folder.iterdir() if p.name != name and p.is_file())
        raw = bytearray(others[len(data) % len(others)].read_bytes()) if others else raw
    path.write_bytes(bytes(raw))


def _cache_case(assets, pristine_cache, tmp_path_factory, name, kind, where, data=b"", scaled=False):
    pristine, refs = pristine_cache
    cache = tmp_path_factory.mktemp("cache-case")
    shutil.copytree(pristine, cache, dirs_exist_ok=True)
    damage_cache(cache, name, kind, where, data)
    box = new_box(assets)
    try:
        extra = SCALED if scaled else []
        o = invoke(box, [*CACHE_RUN, *extra], ["out.nc", "out.ckpt"], env={"GRANEL_CACHE": str(cache)})
        if o.code == 0:
            ds = xr.load_dataset(box / "out.nc", engine="h5netcdf")
            try:
                _same_result(ds, refs["scaled" if scaled else "own"])
            except AssertionError as e:
                raise AssertionError(f"damaged cache entry {name} ({kind} at {where:.3f}): exit 0 with a wrong "
                                     f"result: {e}\n{o}") from None
            with _chdir(box):
                verify_result(box / "out.nc", scenario_of("beam.toml", ['excitations.0.granule="LSGM:12"',
                                                                       'simulation.duration="0.01ms"',
                                                                       *(["solid.thickness=0.0012"] if scaled else [])]))
        return o
    finally:
        _release(box)
        shutil.rmtree(cache, ignore_errors=True)


def _cache_names(pristine_cache):
    return sorted(p.name for p in pristine_cache[0].iterdir() if p.is_file() and not p.name.endswith(".lock"))


@settings(max_examples=int(os.environ.get("HOSTILE_CACHE", 5)), **HYPOTHESIS)
@given(pick=st.integers(0, 1000), kind=st.sampled_from(CACHE_DAMAGE), where=st.floats(0.0, 1.0),
       data=st.binary(max_size=8), scaled=st.booleans())
def test_damaged_cache_entries(assets, pristine_cache, tmp_path_factory, pick, kind, where, data, scaled):
    """A cache entry truncated, emptied, zero-filled, bit-flipped or swapped: the run recomputes
    (or refuses cleanly); an exit 0 has the clean cache's result."""
    names = _cache_names(pristine_cache)
    _cache_case(assets, pristine_cache, tmp_path_factory, names[pick % len(names)], kind, where, data, scaled)


# ------------------------------------------------------------------------------------------------
# 5. a full disk: a small tmpfs as the output folder (root only)


@contextlib.contextmanager
def small_disk(box: Path, free: int, size: str = "300k"):
    """A tmpfs of `size` mounted at BOX/disk, filled (by disk/filler, which must stay as it is)
    until about `free` bytes are left; always unmounted."""
    if not IS_ROOT:
        pytest.skip("mounting a small tmpfs needs root")
    where = box / "disk"
    if not _mount_tmpfs(where, size):
        pytest.skip("mount -t tmpfs failed here")
    try:
        avail = os.statvfs(where).f_bavail * os.statvfs(where).f_frsize
        with open(where / "filler", "wb") as fh:
            with contextlib.suppress(OSError):
                fh.write(b"\xa5" * max(avail - free, 0))
        yield where
    finally:
        _unmount(where)


def _disk_base(command: str, out: str) -> Base:
    if command == "run":
        return _run_base("scen.toml", out)
    if command == "show":
        return Base(["show", "scen.toml", "-o", out], [out], lambda box, o, e: verify_picture(Path(out)))
    if command == "animate":
        return Base(["animate", "good.nc", "-o", out, "--frames", "3", "--fps", "5"], [out],
                    lambda box, o, e: verify_movie(Path(out), 3))
    if command == "export":
        return Base(["export", "good.nc", "-o", out], [out], lambda box, o, e: verify_export(Path(out), Path("good.nc")))
    if command == "wavefield":
        return Base(["wavefield", "plate.nc", "-o", out], [out],
                    lambda box, o, e: verify_wavefield(Path(out), Path("plate.nc")))
    if command == "sweep":
        return Base(["sweep", "sweep.toml", "-o", out, "--workers", "1"], [out],
                    lambda box, o, e: verify_summary(Path(out) / "summary.nc", 2))
    raise KeyError(command)


def verify_summary(path: Path, cases: int) -> None:
    ds = xr.load_dataset(path, engine="h5netcdf")
    assert ds["status"].size == cases and all(str(s) == "ok" for s in ds["status"].values.ravel())


DISK_OUT = {"run": "disk/out.nc", "show": "disk/g.png", "animate": "disk/m.gif", "export": "disk/exp",
            "wavefield": "disk/wf", "sweep": "disk/sout"}


def _disk_cases():
    for command in DISK_OUT:
        for free in (0, 16 * 1024, 64 * 1024, 160 * 1024):
            marks = _slow_if(command in ("sweep", "wavefield") and free != 0)
            yield pytest.param(command, free, id=f"{command}-{free // 1024}k", marks=marks)


@pytest.mark.parametrize("command,free", list(_disk_cases()))
def test_full_disk(assets, command, free):
    """The output folder on a disk with `free` bytes left: exit 0 with a confirmed result, or
    exit 4 (no space) naming the file, with nothing left behind but the intended output."""
    box = new_box(assets)
    try:
        with small_disk(box, free):
            b = _disk_base(command, DISK_OUT[command])
            if command == "sweep":
                LIVE.update({"run_sweep", "run_spec"})
            try:
                if command == "export" and free == 64 * 1024:  # h5py's failure at exit shows only in a process
                    o = check_case(box, b, outcome=invoke_subprocess(box, b.args, b.outputs))
                else:
                    o = check_case(box, b)
            finally:
                LIVE.clear()
            assert o.code in (0, 3, 4), f"exit {o.code} on a full disk\n{o}"
            if o.code == 4:
                assert "space" in o.error, f"exit 4 without saying the disk is full\n{o}"
                assert "disk" in o.error, f"the error names no file or folder on the full disk\n{o}"
            leftovers = [p.name for p in (box / "disk").iterdir() if p.name.startswith(".granel-")]
            assert not leftovers, f"temporary files left on the full disk: {leftovers}\n{o}"
    finally:
        _release(box)


def test_disk_fills_during_a_run(assets, monkeypatch):
    """The disk fills after the checks, while the run computes (the run's last step fills it):
    exit 4 naming the result, no partial result and no temporary file."""
    import granel.run

    box = new_box(assets)
    try:
        with small_disk(box, 250 * 1024) as disk:
            real = granel.run.run_scenario

            def run_then_fill(*args, **kwargs):
                out = real(*args, **kwargs)
                with open(disk / "late-filler", "wb") as fh, contextlib.suppress(OSError):
                    fh.write(b"\x5a" * (300 * 1024))
                return out

            monkeypatch.setattr(granel.run, "run_scenario", run_then_fill)
            o = invoke(box, ["run", "scen.toml", "-o", "disk/out.nc"], ["disk/out.nc", "disk/out.ckpt", "disk/late-filler"])
            assert o.code == 4 and "space" in o.error and "out.nc" in o.error, f"expected exit 4 (no space)\n{o}"
            assert not (disk / "out.nc").exists()
            leftovers = [p.name for p in disk.iterdir() if p.name.startswith(".granel-")]
            assert not leftovers, f"temporary files left: {leftovers}\n{o}"
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# 6. Ctrl-C


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux /proc), 0 if unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


# long enough that a signal sent at 2.5 CPU seconds (about 1 s of start-up, then the run) lands mid-run on a fast
# machine too: uninterrupted, about 30 s of computing here (100 ms took 2.9 s and once ended before the signal)
LONG_RUN = ["run", "scen.toml", "--duration", "1000ms", "--set", "simulation.output_every=100us", "-o", "long.nc"]


def _sigint_as_at_a_terminal():
    """In the child: SIGINT at its default, as for a command typed at a terminal. A suite started
    in the background by a shell without job control (`make test &` in a script, nohup) hands its
    children SIGINT ignored, and granel keeps an ignored SIGINT ignored (guard.signals)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to see the run has started")
def test_ctrl_c_during_a_run(assets):
    """SIGINT once the run computes: exit 130, one error line, no result, no temporary."""
    box = new_box(assets)
    try:
        o = invoke_subprocess(box, LONG_RUN, ["long.nc"], preexec_fn=_sigint_as_at_a_terminal,
                              signal_when=(lambda proc: _cpu_seconds(proc.pid) > 2.5, signal.SIGINT))
        assert o.code == 130 and "interrupted" in o.error, f"expected exit 130\n{o}"
        assert not (box / "long.nc").exists()
    finally:
        _release(box)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to see the run has started")
def test_ctrl_c_keeps_the_checkpoint_and_resume_finishes(assets):
    """SIGINT after the first checkpoint: exit 130 with the checkpoint kept; --resume then
    finishes with a confirmed result and removes it."""
    box = new_box(assets)
    try:
        options = ["--duration", "20ms", "--set", "simulation.output_every=10us", "--checkpoint-every", "2ms"]
        args = ["run", "scen.toml", *options, "-o", "long.nc"]
        o = invoke_subprocess(box, args, ["long.nc", "long.ckpt"], preexec_fn=_sigint_as_at_a_terminal,
                              signal_when=(lambda proc: (box / "long.ckpt").exists(), signal.SIGINT))
        assert o.code in (0, 130), o
        if o.code == 130:
            assert (box / "long.ckpt").exists(), f"the checkpoint was not kept\n{o}"
            b = _run_base("scen.toml", "long.nc", ['simulation.duration="20ms"', "simulation.output_every=10us",
                                                    'simulation.checkpoint_every="2ms"'],
                          [*options, "--resume", "long.ckpt"], outputs=["long.nc", "long.ckpt"])
            r = check_case(box, b)
            assert r.code == 0 and not (box / "long.ckpt").exists(), r
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# 7. findings of this harness, fixed: each kept as a case of its own


def test_the_error_is_the_last_line_when_a_run_stops(assets):
    """A run that stops (exit 3, here on --max-wall) closes its progress bar before the error
    line (finding F4: the bar was drawn again after it)."""
    box = new_box(assets)
    try:
        o = invoke(box, ["run", "scen.toml", "-o", "out.nc", "--max-wall", "1e-300"], ["out.nc", "out.ckpt"])
        assert o.code == 3
        lines = [line for line in o.stderr.splitlines() if line.strip()]
        assert lines[-1].startswith("error:"), f"after the error line: {lines[lines.index(o.error) + 1:]}\n{o}"
    finally:
        _release(box)


@pytest.mark.parametrize("command,path,value", [pytest.param(*k, id=f"{v}: {k[0]} --set {k[1]}={k[2]}")
                                                for k, v in FORMER_FINDINGS.items()])
def test_former_internal_errors_of_scenario_fields(assets, command, path, value):
    """Extreme values that once ended in internal errors: now the contract holds."""
    box = new_box(assets)
    try:
        check_case(box, base(command), ["--set", f"{path}={value}"])
    finally:
        _release(box)


@pytest.mark.parametrize("measure", ["SSGM:ZZ", "C:99"])
def test_spectrum_refuses_an_unknown_measured_granule(assets, measure):
    """An unknown measured granule is refused before the study, in one direction too (finding
    F14: only --both-directions checked it)."""
    box = new_box(assets)
    try:
        b = base("spectrum")
        args = list(b.args)
        args[args.index("--measure") + 1] = measure
        check_case(box, Base(args, b.outputs, long_work=True), refuse=True, names=("--measure",))
    finally:
        _release(box)


def test_reciprocity_does_not_ignore_a_set_fmax(assets):
    """reciprocity keeps the scenario's own load unless --shock is given (finding F8: its default
    --shock strong silently replaced a --set fmax)."""
    box = new_box(assets)
    try:
        check_case(box, base("reciprocity"), ["--set", "excitations.0.shock=-", "--set", "excitations.0.fmax=nan"],
                   refuse=True, names=("excitations.0",))
        # both --shock and a --set of the same load: refused, naming both
        check_case(box, base("reciprocity"), ["--shock", "weak", "--set", "excitations.0.fmax=100"],
                   refuse=True, names=("--shock", "excitations.0.fmax"))
        # a --set peak force is the one both runs use
        check_case(box, base("reciprocity"), ["--set", "excitations.0.shock=-", "--set", "excitations.0.fmax=200"])
        for name in ("shock-LSGM3.nc", "shock-SSGMC.nc"):
            ds = xr.load_dataset(box / "rec" / name, engine="h5netcdf")
            assert tomllib.loads(ds.attrs["scenario"])["excitations"][0]["fmax"] == 200.0
    finally:
        _release(box)


# findings on `granel wavefield` (plate.nc: wavenumbers 157, 314, ... rad/m; solid outputs 0, 1, ..., 5 us), each
# now a refusal naming the option, before the output folder is made. F15: a --k-max below the result's second
# wavenumber (under the first: an internal error drawing kt.png; between: exit 0 with NaN moments). F16: a band
# holding none of the result's wavenumbers, given or equal bands up to --k-max (exit 0, the band's field zero by
# construction). F17: a --fit window past the record (exit 0, the moments figure's time axis to 1e303 ms) or
# holding fewer than the 3 solid outputs a fit needs (exit 0 with NaN exponents).
WAVEFIELD_OPTION_FINDINGS = [("F15", "--k-max", "1e-300"), ("F15", "--k-max", "200"), ("F16", "--bands", "0,1e-300"),
                             ("F16", "--k-max", "1e300"), ("F16", "--bands", "12"), ("F17", "--fit", "0:1e300"),
                             ("F17", "--fit", "2us:4us")]


@pytest.mark.parametrize("finding,option,value", [pytest.param(*c, id=f"{c[0]}: {c[1]} {c[2]}")
                                                  for c in WAVEFIELD_OPTION_FINDINGS])
def test_wavefield_refuses_what_its_result_cannot_serve(assets, finding, option, value):
    box = new_box(assets)
    try:
        check_case(box, base("wavefield"), [option, value], refuse=True, names=(option,))
        assert not (box / "wf").exists(), "a refused wavefield made its folder"
    finally:
        _release(box)


# F18: a plate result whose solid_time is not finite and increasing, lies outside its run, or comes without the
# solid's state (internal errors: pcolormesh's, an IndexError, an AttributeError); F19: a result whose mode_omega
# are not its solid's frequencies (here off by 1e-5, ten times the check's tolerance: exit 0 with a modal energy
# spectrum of the wrong frequencies); F22 (of the fuzz): a modal velocity finite but far beyond any run's (a flipped
# byte), whose energies overflow float32 in wavefield.nc (exit 0 with E(k, t) = inf). Each now a refusal naming
# the file, F18 and F19 before the folder is made, F22 once the spectrum is computed.
WAVEFIELD_DAMAGE = {
    "F18: solid_time not finite": lambda ds, t: ds.assign_coords(solid_time=np.where(t == t[2], np.nan, t)),
    "F18: solid_time decreasing": lambda ds, t: ds.assign_coords(solid_time=t[::-1].copy()),
    "F18: solid_time beyond the run": lambda ds, t: ds.assign_coords(solid_time=t * 1e300),
    "F18: solid_time without a state": lambda ds, t: ds.drop_vars(["solid_eta", "solid_eta_dot", "mode_omega"]),
    "F19: mode_omega not the solid's": lambda ds, t: ds.assign(mode_omega=ds["mode_omega"] * (1 + 1e-5)),
    "F22: a modal velocity of 1e30": lambda ds, t: ds.assign(solid_eta_dot=ds["solid_eta_dot"].where(
        (ds["solid_time"] < t[-1]) | (ds["mode"] > 0), np.float32(1e30))),
}


@pytest.mark.parametrize("damage", list(WAVEFIELD_DAMAGE))
def test_wavefield_refuses_a_damaged_plate_result(assets, damage):
    from granel.io.results import write_netcdf

    box = new_box(assets)
    try:
        ds = xr.load_dataset(box / "plate.nc", engine="h5netcdf")
        (box / "plate.nc").unlink()
        write_netcdf(WAVEFIELD_DAMAGE[damage](ds, ds["solid_time"].values), box / "plate.nc")
        o = check_case(box, base("wavefield"), refuse=True, names=("plate.nc",))
        assert "damaged result" in o.error, o
        assert damage.startswith("F22") or not (box / "wf").exists(), "a refused wavefield made its folder"
    finally:
        _release(box)


@pytest.mark.parametrize("args,given", [(["wavefield", "plate.nc", "-o", "wf", "--fit", "a:b"], "--fit a:b:"),
                                        (["wavefield", "x:smile:.nc", "-o", "wf"], "x:smile:.nc")])
def test_the_error_line_quotes_what_was_given(assets, args, given):
    """A value or a name holding an emoji code (":b:", ":smile:") is quoted as given (finding F20:
    the console printed the emoji in its place)."""
    box = new_box(assets)
    try:
        o = invoke(box, args, ["wf"])
        assert o.code == 2 and given in o.error, o
    finally:
        _release(box)


def test_wavefield_of_a_name_that_is_not_utf8(assets):
    """A result whose name is not UTF-8: its wavefield, confirmed (finding F21: the name, in the
    figures' titles, stopped matplotlib's font with an internal error, and in the table's title an
    output that takes only UTF-8, as the in-process runner's does; it is now escaped there and in
    wavefield.nc's `source`, as `guard.writing.storable` does)."""
    box = new_box(assets)
    try:
        name = os.fsdecode(b"\xff\xfe-plate.nc")
        shutil.copy(box / "plate.nc", box / name)
        o = invoke(box, ["wavefield", name, "-o", "wf"], ["wf"])
        assert o.code == 0, o
        with _chdir(box):
            verify_wavefield(Path("wf"), Path(name))
        assert xr.load_dataset(box / "wf" / "wavefield.nc", engine="h5netcdf").attrs["source"] == "\\xff\\xfe-plate.nc"
    finally:
        _release(box)


@pytest.mark.slow  # a movie: matplotlib frames and ffmpeg, about 3 s
def test_wavefield_movie(assets):
    """`--movie`: the wavefield's files and the movie, confirmed (`verify_wavefield`)."""
    box = new_box(assets)
    try:
        o = check_case(box, base("wavefield"), ["--movie", "--frames", "3", "--fps", "5"])
        assert o.code == 0, o
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# 8. hostile environments: caches, TMPDIR, HOME, the terminal, locale, umask, limits, clock (issue 37,
# item 4)
#
# An environment is a builder (one row of ENVIRONMENTS): it makes what it needs in the case's
# folder and returns a `Setting` (the child's variables, a function the child runs before Python
# starts, the names the inputs and outputs take); a command is one row of ENV_COMMANDS (arguments
# and outputs as templates over those names, and the reference check of an exit 0). Every
# environment meets every command, in a process; each environment's `quick` commands run in the
# quick suite, the others are slow. Besides the contract, a case holds: its exit code in the
# environment's set, the environment's note on standard error where it names one, no temporary
# left in the case's folder, no output on a failure (but an output folder holding only granel's
# stamp), and no compiled-kernel cache written into the package's own folders (numba's fallback,
# keyed by no source: `guard.jit`).

ENV_NAMES = {"scen": "scen.toml", "chain": "chain.toml", "plate": "plate.toml", "result": "good.nc", "out": "out",
             "name": "mine", "title": "paper"}  # title: the name field of the scenario `scen` names
DEAD_PID = 2**22 + 1  # beyond any pid_max: never a live process
PACKAGE_DIR = Path(granel.__file__).resolve().parent
YEAR = 365.25 * 86400
# a case may compile granel's kernels afresh (about a minute here): an environment whose kernel cache
# is another folder than this process's, or sources edited since the last compile
ENV_TIMEOUT = 300.0


@dataclass
class Setting:
    """What an environment gives a case."""

    env: dict = field(default_factory=dict)  # the child's variables over this process's (None unsets one)
    preexec: object = None  # run in the child before Python starts (a umask, resource limits)
    names: dict = field(default_factory=dict)  # over ENV_NAMES
    codes: dict = field(default_factory=lambda: {"*": {0}})  # exit codes by command ("*": any other)
    note: dict = field(default_factory=dict)  # text standard error must hold, by command ("*": every command)
    outputs: list = field(default_factory=list)  # paths the environment lets the command change (a cache)
    planted: list = field(default_factory=list)  # granel's own files of a dead process, put there (may go)
    check: object = None  # check(box, outcome, command, names): more on an exit 0
    failure: object = None  # failure(outcome, outputs): more on a failure (what its error line says)


@dataclass
class EnvCommand:
    args: list  # templates over the names: "{scen}", "{out}.nc"
    outputs: list
    verify: object  # verify(box, outcome, names): the reference check of an exit 0
    codes: set | None = None  # the exit codes in every environment (None: the environment's)
    error: str = ""  # what its error line names, in every environment


def _fill(templates, names) -> list[str]:
    return [t.format(**names) for t in templates]


def _verify_env_run(box, o, n):
    sc = scenario_of(str(box / n["scen"]), [])
    verify_result(box / f"{n['out']}.nc", sc)
    ds = xr.load_dataset(box / f"{n['out']}.nc", engine="h5netcdf")
    assert tomllib.loads(ds.attrs["scenario"])["name"] == n["title"], f"the result's scenario is not named {n['title']!r}"


def _verify_env_resolved(box, o, n):
    got = tomllib.loads(o.stdout)
    assert got == tomllib.loads(S.to_toml(scenario_of(str(box / n["scen"]), []))), "--resolved printed another scenario"
    assert got["name"] == n["title"]


def _verify_env_modes(box, o, n):
    verify_modes_json(o.stdout, 3)
    got = json.loads(o.stdout)["periods_ms"]
    assert np.allclose(got, PLATE_PERIODS_MS, rtol=1e-9, atol=0), f"periods {got}, the clean environment's {PLATE_PERIODS_MS}"


PLATE_PERIODS_MS: list = []  # the plate's three longest periods in a clean environment (`env_reference`)

ENV_COMMANDS = {
    "run": EnvCommand(["run", "{scen}", "-o", "{out}.nc"], ["{out}.nc", "{out}.ckpt"], _verify_env_run),
    "show": EnvCommand(["show", "{scen}", "-o", "{out}.png"], ["{out}.png"],
                       lambda box, o, n: verify_picture(box / f"{n['out']}.png")),
    "show --resolved": EnvCommand(["show", "{scen}", "--resolved"], [], _verify_env_resolved),
    "refused run": EnvCommand(["run", "{scen}", "--set", "contact.mu=nan", "-o", "{out}.nc"], ["{out}.nc", "{out}.ckpt"],
                              None, codes={2}, error="contact.mu"),
    "run chain": EnvCommand(["run", "{chain}", "-o", "{out}.nc"], ["{out}.nc", "{out}.ckpt"],
                            lambda box, o, n: verify_result(box / f"{n['out']}.nc", scenario_of(str(box / n["chain"]), []))),
    "modes": EnvCommand(["modes", "{plate}", "--json", "--count", "3"], [], _verify_env_modes),
    "export": EnvCommand(["export", "{result}", "-o", "{out}-exp"], ["{out}-exp"],
                         lambda box, o, n: verify_export(box / f"{n['out']}-exp", box / n["result"])),
    "animate": EnvCommand(["animate", "{result}", "-o", "{out}.gif", "--frames", "3", "--fps", "5"], ["{out}.gif"],
                          lambda box, o, n: verify_movie(box / f"{n['out']}.gif", 3)),
    "init": EnvCommand(["init", "{name}", "-o", "{out}.toml"], ["{out}.toml"],
                       lambda box, o, n: verify_scenario_file(box / f"{n['out']}.toml", n["name"])),
}


@dataclass
class Place:
    """Where an environment is built: the case's folder and the module's fixtures (asked for when
    a builder needs one)."""

    box: Path
    request: object

    def fixture(self, name: str):
        return self.request.getfixturevalue(name)


def _readonly_folder(place: Place) -> Path:
    """A folder this process cannot write: mode 555 for a user; for root, who writes through
    modes, the read-only tmpfs (`readonly_fs`), or a skip where it cannot be mounted."""
    if not IS_ROOT:
        folder = place.box / "locked"
        folder.mkdir()
        os.chmod(folder, 0o555)
        return folder
    rofs = place.fixture("readonly_fs")
    if rofs is None:
        pytest.skip("a folder root cannot write needs the read-only tmpfs (mount failed here)")
    return rofs


def _a_file(place: Place) -> Path:
    path = place.box / "plain.txt"
    assert path.is_file()
    return path


NUMBA_NOTE = "NUMBA_CACHE_DIR"  # the compiled-kernel cache's note names the variable it could not use
CACHE_NOTE = "cannot be written"  # the mode cache's note (solid.mode_cache.unwritable)


def _numba_cache(where):
    def build(place: Place) -> Setting:
        return Setting(env={"NUMBA_CACHE_DIR": str(where(place))}, note={"*": NUMBA_NOTE})
    return build


def _granel_cache(where):
    def build(place: Place) -> Setting:
        return Setting(env={"GRANEL_CACHE": str(where(place))}, note={"modes": CACHE_NOTE})
    return build


def _tmpdir(where):
    def build(place: Place) -> Setting:
        return Setting(env={"TMPDIR": str(where(place))})
    return build


ASCII_LOCALE = {"LC_ALL": "C", "LANG": "C", "LC_CTYPE": None, "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0",
                "PYTHONIOENCODING": None}


def _ascii_locale(place: Place) -> Setting:
    """The C locale without UTF-8 mode, where Python's file-system and console encodings are
    ASCII; the scenario, the chain and its tables, the plate, the result and every output with
    non-ASCII names, and the scenario and its result named "chaîne" (init's NAME too). A table
    whose name the locale cannot encode may be refused (exit 2)."""
    probe = subprocess.run([sys.executable, "-c", "import sys; print(sys.getfilesystemencoding())"],
                           env={k: v for k, v in {**os.environ, **ASCII_LOCALE}.items() if v is not None},
                           capture_output=True, text=True, timeout=60)
    if probe.stdout.strip().lower() not in ("ascii", "ansi_x3.4-1968"):
        pytest.skip(f"the C locale's file-system encoding is {probe.stdout.strip()!r} here, not ASCII")
    box, names = place.box, {"scen": "chaîne.toml", "chain": "collier.toml", "plate": "plaque-é.toml",
                             "result": "résultat.nc", "out": "sortie-ü", "name": "chaîne", "title": "chaîne"}
    text = (box / "scen.toml").read_text()
    assert text.count('name = "paper"') == 1
    (box / names["scen"]).write_text(text.replace('name = "paper"', 'name = "chaîne"'), encoding="utf-8")
    chain = CHAIN.replace('"beads.csv"', '"perles-é.csv"').replace('"force.csv"', '"force-é.csv"')
    assert chain != CHAIN and "perles-é.csv" in chain and "force-é.csv" in chain
    (box / names["chain"]).write_text(chain, encoding="utf-8")
    shutil.copy(box / "beads.csv", box / "perles-é.csv")
    shutil.copy(box / "force.csv", box / "force-é.csv")
    shutil.copy(box / "plate.toml", box / names["plate"])
    res = _invoke_raw(["run", names["scen"], "-o", names["result"]], box)  # a result named "chaîne"
    assert res.exit_code == 0, res.output
    return Setting(env=dict(ASCII_LOCALE), names=names, codes={"*": {0}, "run chain": {0, 2}},
                   failure=_says("file-name encoding"))


def _says(text: str, names_output: bool = False):
    """A failure's check: its error line holds `text` (and names one of the outputs)."""
    def failure(o, outputs):
        assert text in o.error, f"the error does not say {text!r}\n{o}"
        if names_output:
            assert any(Path(p).name in o.error for p in outputs), f"the error names none of the outputs {outputs}\n{o}"
    return failure


def _umask_modes(mask: int):
    def check(box, o, command, names):
        outs = [box / p for p in _fill(ENV_COMMANDS[command].outputs, names)]
        files = [f for p in outs if p.exists() for f in ([p] if p.is_file() else p.rglob("*")) if f.is_file()]
        for f in files:
            mode = stat.S_IMODE(f.stat().st_mode)
            assert mode == 0o666 & ~mask, f"{f}: mode {mode:o}, the umask {mask:03o} gives {0o666 & ~mask:o}"
    return check


def _umask(mask: int):
    """The umask `mask`: the outputs written with its modes; a user (not root) whose umask takes
    the owner's write permission away may be refused a folder granel makes (exit 4, naming it)."""
    def build(place: Place) -> Setting:
        closed = mask & 0o300 and not IS_ROOT
        return Setting(preexec=lambda: os.umask(mask), codes={"*": {0, 4} if closed else {0}}, check=_umask_modes(mask),
                       failure=_says("umask"))
    return build


def _limit(kind: int, value: int):
    def preexec():
        resource.setrlimit(kind, (value, value))
    return preexec


@pytest.fixture(scope="module")
def least_nofile(assets):
    """The least RLIMIT_NOFILE with which `granel --version` (Python, and every module granel
    imports to start) ends with exit 0 here; below it Python itself cannot start."""
    for n in range(3, 65):
        res = subprocess.run([sys.executable, "-m", "granel", "--version"], preexec_fn=_limit(resource.RLIMIT_NOFILE, n),
                             capture_output=True, timeout=60, cwd=assets)
        if res.returncode == 0:
            return n
    pytest.skip("granel did not start with up to 64 open files")


def _nofile(extra: int):
    def build(place: Place) -> Setting:
        n = place.fixture("least_nofile") + extra
        return Setting(preexec=_limit(resource.RLIMIT_NOFILE, n), codes={"*": {0, 4}}, failure=_says("open files"))
    return build


FSIZE = 16 * 1024  # bytes: more than init's scenario and export's CSV files, less than a result, a picture or a movie


def _fsize(place: Place) -> Setting:
    return Setting(preexec=_limit(resource.RLIMIT_FSIZE, FSIZE), codes={"*": {0, 4}, "run": {4}, "show": {4}},
                   failure=_says("file-size limit", names_output=True))


CLOCK_SITE = '''"""The hostile harness's clock: time.time and time.time_ns shifted by HOSTILE_CLOCK_SHIFT seconds."""
import os
import time

_shift = float(os.environ.get("HOSTILE_CLOCK_SHIFT", "0"))
_time, _time_ns = time.time, time.time_ns
time.time = lambda: _time() + _shift
time.time_ns = lambda: _time_ns() + int(_shift * 1e9)
'''


@pytest.fixture(scope="module")
def clock_site(tmp_path_factory):
    """A folder holding a sitecustomize.py that shifts the clock (outside the case folders, where
    Python may write its bytecode)."""
    folder = tmp_path_factory.mktemp("clock")
    (folder / "sitecustomize.py").write_text(CLOCK_SITE)
    return folder


def _clock_check(shift: float):
    def check(box, o, command, names):
        if command == "export":  # the folder's stamp records when it was made, by the child's clock
            made = json.loads((box / f"{names['out']}-exp" / ".granel-folder.json").read_text())["made"]
            assert abs(made - (time.time() + shift)) < 86400, f"the stamp says {made}: the clock was not shifted"
    return check


def _clock(years: float):
    def build(place: Place) -> Setting:
        shift = years * YEAR
        path = os.pathsep.join(p for p in (str(place.fixture("clock_site")), os.environ.get("PYTHONPATH")) if p)
        return Setting(env={"PYTHONPATH": path, "HOSTILE_CLOCK_SHIFT": repr(shift)}, check=_clock_check(shift))
    return build


def _dead_leftovers(folder: Path) -> list[Path]:
    """A temporary file and a staging folder of a dead granel process in `folder`, as guard.writing
    names them."""
    from granel.guard.owners import process_token
    from granel.guard.writing import PREFIX, STAGE, SUFFIX

    token = process_token(DEAD_PID)
    tmp = folder / f"{PREFIX}0123456789-{token}-abcdefgh{SUFFIX}"
    tmp.write_bytes(b"half a result")
    stage = folder / f"{STAGE}{token}-abcdefgh"
    stage.mkdir()
    (stage / "traces.csv").write_text("half an export\n")
    return [tmp, stage]


def _dated(when):
    """Every input, a private copy of the mode cache, and a dead process's temporary and staging
    folder, all dated `when(now)` (modification and access times)."""
    def build(place: Place) -> Setting:
        box = place.box
        cache = box / "cache"
        shutil.copytree(os.environ["GRANEL_CACHE"], cache)
        planted = _dead_leftovers(box)
        t = when(time.time())
        for p in [*box.rglob("*"), box]:
            os.utime(p, (t, t), follow_symlinks=False)
        return Setting(env={"GRANEL_CACHE": str(cache)}, outputs=["cache"], planted=planted)
    return build


def _variables(**values):
    def build(place: Place) -> Setting:
        return Setting(env={k: v(place) if callable(v) else v for k, v in values.items()})
    return build


def _home_a_file(place: Place) -> Setting:
    """HOME a file: no ~/.cache, no matplotlib configuration folder (granel's kernels are then
    cached beside the package, where this needs it writable: else every case compiles them)."""
    if not os.access(PACKAGE_DIR / "__pycache__", os.W_OK):
        pytest.skip("the package's __pycache__ is not writable here: without a home each case compiles for a minute")
    return Setting(env={"HOME": str(_a_file(place)), "XDG_CACHE_HOME": None, "XDG_CONFIG_HOME": None,
                        "MPLCONFIGDIR": None})


@dataclass
class Environment:
    build: object  # build(place) -> Setting
    quick: tuple = ()  # the commands of the quick suite


ENVIRONMENTS = {
    "NUMBA_CACHE_DIR read-only": Environment(_numba_cache(_readonly_folder), ("run",)),
    "NUMBA_CACHE_DIR a file": Environment(_numba_cache(_a_file), ("init",)),
    "NUMBA_CACHE_DIR below a file": Environment(_numba_cache(lambda p: _a_file(p) / "numba"), ("show --resolved",)),
    "GRANEL_CACHE read-only": Environment(_granel_cache(_readonly_folder), ("modes",)),
    "GRANEL_CACHE a file": Environment(_granel_cache(_a_file), ("modes",)),
    "GRANEL_CACHE below a file": Environment(_granel_cache(lambda p: _a_file(p) / "cache")),
    "TMPDIR missing": Environment(_tmpdir(lambda p: p.box / "no-such-folder"), ("init",)),
    "TMPDIR a file": Environment(_tmpdir(_a_file), ("show",)),
    "HOME a file": Environment(_home_a_file),
    "COLUMNS 0": Environment(_variables(COLUMNS="0"), ("refused run",)),
    "COLUMNS 1": Environment(_variables(COLUMNS="1")),
    "LINES 0": Environment(_variables(LINES="0")),
    "ASCII locale, non-ASCII names": Environment(_ascii_locale, ("run", "show --resolved", "init")),
    "umask 077": Environment(_umask(0o077), ("show",)),
    "umask 277": Environment(_umask(0o277), ("export",)),
    "RLIMIT_NOFILE the least to start": Environment(_nofile(0), ("show",)),
    "RLIMIT_NOFILE one more": Environment(_nofile(1), ("run",)),
    "RLIMIT_FSIZE 16 KiB": Environment(_fsize, ("run",)),
    "clock 60 years ahead": Environment(_clock(60), ("export",)),
    "clock 40 years behind": Environment(_clock(-40), ("init",)),
    "files dated 1970": Environment(_dated(lambda now: 0), ("modes",)),
    "files dated 60 years ahead": Environment(_dated(lambda now: now + 60 * YEAR), ("run",)),
}


@pytest.fixture(scope="module")
def env_reference(assets):
    """The plate's three longest periods in this process's environment (`modes` cases compare)."""
    res = _invoke_raw(["modes", "plate.toml", "--json", "--count", "3"], assets)
    assert res.exit_code == 0, res.output
    PLATE_PERIODS_MS[:] = json.loads(res.stdout)["periods_ms"]
    return PLATE_PERIODS_MS


KERNEL_CACHE_FILES = ("*.nbi", "*.nbc", "granel-manifest.json", ".granel-*.lock")


def kernel_files_in_the_package(since: float) -> list[Path]:
    """numba's cache files written in the package's own folders (not in a keyed `kernels-KEY`
    folder) since `since`: numba's fallback when granel's folder cannot be used."""
    found = []
    for pattern in KERNEL_CACHE_FILES:
        for p in PACKAGE_DIR.rglob(pattern):
            if any(part.startswith("kernels-") for part in p.relative_to(PACKAGE_DIR).parts):
                continue
            with contextlib.suppress(OSError):
                if p.stat().st_mtime >= since:
                    found.append(p)
    return found


def _leftovers(box: Path, planted) -> list[str]:
    """granel's temporaries and staging folders in the case's folder, but for those planted."""
    planted = {Path(p) for p in planted}
    return sorted(str(p.relative_to(box)) for p in box.rglob(".granel-*")
                  if p not in planted and not any(q in planted for q in p.parents) and p.name != ".granel-folder.json")


def _env_cases():
    for env, e in ENVIRONMENTS.items():
        for command in ENV_COMMANDS:
            yield pytest.param(env, command, id=f"{env}-{command}", marks=_slow_if(command not in e.quick))


@pytest.mark.parametrize("env,command", list(_env_cases()))
def test_hostile_environments(assets, env_reference, request, env, command):
    """A command in a hostile environment: the contract, and the checks the section's comment
    lists; an exit 0 with a confirmed result."""
    box = new_box(assets)
    try:
        s = ENVIRONMENTS[env].build(Place(box, request))
        names = {**ENV_NAMES, **s.names}
        c = ENV_COMMANDS[command]
        args, outputs = _fill(c.args, names), _fill(c.outputs, names)
        existed = {o for o in outputs if os.path.lexists(box / o)}
        since = time.time() - 1.0
        o = invoke_subprocess(box, args, [*outputs, *s.outputs, *s.planted], ENV_TIMEOUT, env=s.env, preexec_fn=s.preexec)
        codes = c.codes or s.codes.get(command, s.codes["*"])
        assert o.code in codes, f"{env}, {command}: exit {o.code}, expected {sorted(codes)}\n{o}"
        stray = kernel_files_in_the_package(since)
        assert not stray, f"{env}, {command}: compiled-kernel cache files written in the package: {stray[:3]}\n{o}"
        note = s.note.get(command, s.note.get("*"))
        if note:
            assert note in o.stderr, f"{env}, {command}: no note naming {note!r} on standard error\n{o}"
        left = _leftovers(box, s.planted)
        assert not left, f"{env}, {command}: temporaries left: {left}\n{o}"
        if o.code == 0:
            try:
                with _chdir(box):
                    c.verify(box, o, names)
                    if s.check is not None:
                        s.check(box, o, command, names)
            except AssertionError as e:
                raise AssertionError(f"{env}, {command}: exit 0, but the reference check fails: {e}\n{o}") from e
            if s.planted and any(Path(p).parent == Path(".") and (box / p).is_file() for p in outputs):
                # a file written beside the dead process's leftovers removed them
                assert not any(p.exists() for p in s.planted), f"{env}, {command}: a dead process's temporaries kept\n{o}"
        else:  # no output, but an output folder holding only granel's stamp (a rerun may use it)
            made = [p for p in outputs if p not in existed and os.path.lexists(box / p)
                    and not ((box / p).is_dir() and {q.name for q in (box / p).iterdir()} <= {".granel-folder.json"})]
            assert not made, f"{env}, {command}: exit {o.code} left outputs {made}\n{o}"
            if c.error:
                assert c.error in o.error, f"{env}, {command}: the error does not name {c.error!r}\n{o}"
            elif s.failure is not None:
                s.failure(o, outputs)
    finally:
        _release(box)


# ------------------------------------------------------------------------------------------------
# the count


def test_zz_at_least_200_hostile_cases(request, capsys):
    """Counts every case the contract checked in this run of the module (hypothesis examples
    included); asserts the issue's 200 when the module's quick tests all ran."""
    here = sys.modules[__name__]
    quick = {name for name, fn in vars(here).items() if name.startswith("test_") and callable(fn)
             and not any(m.name == "slow" for m in getattr(fn, "pytestmark", []))} - {"test_zz_at_least_200_hostile_cases"}
    ran = {item.originalname for item in request.session.items if item.module is here}
    with capsys.disabled():
        sys.stderr.write(f"\nhostile harness: {COUNT['cases']} cases checked by the contract\n")
    if quick <= ran:
        assert COUNT["cases"] >= 200, COUNT


CACHE_FILES = ["omega.npy", "shapes.npy", "scale.npz", "omega.npy.sum", "shapes.npy.sum", "scale.npz.sum"]


@pytest.mark.slow
@pytest.mark.parametrize("scaled", [False, True], ids=["own", "scaled"])
@pytest.mark.parametrize("kind", CACHE_DAMAGE)
@pytest.mark.parametrize("ending", CACHE_FILES)
def test_every_damaged_cache_file(assets, pristine_cache, tmp_path_factory, ending, kind, scaled):
    """Every file of the beam's cache entry under every damage, for its own beam and for a
    proportional one whose modes are scaled from the record."""
    names = [n for n in _cache_names(pristine_cache) if n.split(".", 1)[-1] == ending]
    if not names:
        pytest.skip(f"no cache file *.{ending} here (the cache's layout changed)")
    _cache_case(assets, pristine_cache, tmp_path_factory, names[0], kind, 0.5, b"\x03", scaled)


@pytest.mark.slow
@pytest.mark.parametrize("kind", CACHE_DAMAGE)
def test_damaged_plate_cache(assets, tmp_path_factory, kind):
    """The assembled plate (plate-*.npz, and its record) damaged: `granel modes` on the plate
    gives the clean cache's periods, or refuses cleanly."""
    cache = tmp_path_factory.mktemp("plate-cache")
    box = new_box(assets)
    try:
        (box / "plate.toml").write_text(paper_text("plate"))
        args = ["modes", "plate.toml", "--count", "4", "--json"]
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("GRANEL_CACHE", str(cache))
            res = _invoke_raw(args, box)
            assert res.exit_code == 0, res.output
        reference = json.loads(res.stdout)["periods_ms"]
        for name in sorted(p.name for p in cache.glob("plate-*")):
            damage_cache(cache, name, kind, 0.5, b"\x05")
        o = invoke(box, args, env={"GRANEL_CACHE": str(cache)})
        if o.code == 0:
            got = json.loads(o.stdout)["periods_ms"]
            assert np.allclose(got, reference, rtol=1e-9), f"periods {got} with a damaged plate cache, {reference} clean\n{o}"
    finally:
        _release(box)
        shutil.rmtree(cache, ignore_errors=True)
