"""Compiling ahead (`granel.guard.ahead`): a second process compiles the kernels a cold process
will call last, into the same cache, each kernel compiled once between the two (their compile
locks), and the plan's signatures are those the step loop calls its kernels with."""

import os
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _default_numba_cache(monkeypatch):
    """These tests compile into the default cache folder beside their package (NUMBA_CACHE_DIR
    unset): in this process, where they look for the files, as in the children they start."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)


KERNEL = """\
from pathlib import Path
from granel.guard.jit import cached_njit

here = Path(__file__).parent
njit = cached_njit((here / "kern.py",), home=here)


@njit(cache=True)
def inner(x, y):
    return x * y + 1.0


@njit(cache=True)
def outer(x, y):
    return inner(x, y) + 1.0
"""
PLAN = """\
import numpy as np
import kern


def plan(x, n):
    yield kern.inner, (x, float(n))


def broken(x, n):
    raise RuntimeError("a plan that fails")
    yield
"""
# starts compiling ahead with the plan named in argv[1], waits for it, then calls outer
PARENT = """\
import sys, time
import numpy as np
import kern
from granel.guard import ahead
proc = ahead.compile_ahead(kern.outer, sys.argv[1], (np.ones(3), 2))
print("started", proc is not None, flush=True)
if proc is not None:
    print("child", proc.wait(timeout=300), flush=True)
print("value", kern.outer(np.ones(3), 2.0).tolist(), "misses", sum(kern.inner.stats.cache_misses.values()),
      flush=True)
"""


def _package(tmp_path: Path, **env_extra) -> dict:
    for name, text in (("kern.py", KERNEL), ("plan.py", PLAN), ("parent.py", PARENT)):
        (tmp_path / name).write_text(text)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "GRANEL_COMPILE_AHEAD")}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), *sys.path])
    env.update(env_extra)
    return env


def _parent(tmp_path, env, plan="plan:plan") -> list[str]:
    out = subprocess.run([sys.executable, "parent.py", plan], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def _payloads() -> list[str]:
    import tempfile

    return sorted(p.name for p in Path(tempfile.gettempdir()).glob("granel-ahead-*.pickle"))


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="compiling ahead needs a second core")
def test_the_second_process_compiles_the_plan_and_the_first_loads_it(tmp_path):
    env = _package(tmp_path)
    before = _payloads()
    words = _parent(tmp_path, env)
    assert words[:4] == ["started", "True", "child", "0"], words
    assert words[4:] == ["value", "[4.0,", "4.0,", "4.0]", "misses", "0"], words  # inner: loaded, not compiled
    assert _payloads() == before  # the child removed its payload
    # the kernels are cached now: no second process
    assert _parent(tmp_path, env)[:2] == ["started", "False"]


def test_switched_off_or_a_failing_plan_changes_nothing_but_the_time(tmp_path):
    env = _package(tmp_path, GRANEL_COMPILE_AHEAD="0")
    words = _parent(tmp_path, env)
    assert words == ["started", "False", "value", "[4.0,", "4.0,", "4.0]", "misses", "1"], words
    (tmp_path / "again").mkdir()
    env = _package(tmp_path / "again")
    before = _payloads()
    words = _parent(tmp_path / "again", env, plan="plan:broken")
    if words[1] == "True":  # a machine with a second core: the child failed, the parent compiled inner itself
        assert words[2:4] == ["child", "1"], words
        assert words[-2:] == ["misses", "1"], words
    assert words[-6:-2] == ["value", "[4.0,", "4.0,", "4.0]"], words
    assert _payloads() == before


def test_one_process_compiles_ahead_into_a_cache_at_a_time(tmp_path):
    """A second cold process (a study's other worker) finds the ahead lock held and starts none."""
    import fcntl

    from granel.guard import ahead, jit

    env = _package(tmp_path)
    folder = jit.cache_folder((tmp_path / "kern.py",), tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / ahead.AHEAD_LOCK, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        words = _parent(tmp_path, env)
    finally:
        os.close(fd)
    assert words == ["started", "False", "value", "[4.0,", "4.0,", "4.0]", "misses", "1"], words


SPY = """\
import sys
import granel.coupling.exact.solver as solver
from granel.guard import ahead

seen = {}


def spy(entry, plan, args):
    seen["args"], seen["proc"] = args, ahead.compile_ahead(entry, plan, args)
    return seen["proc"]


solver.compile_ahead = spy
from granel.cli import app
try:
    app(sys.argv[1:])
except SystemExit as e:
    assert not e.code, e.code
print("ahead", seen["proc"] is not None, seen["proc"].wait(timeout=600) if seen["proc"] else None)
from granel.coupling.exact.loop import compile_plan
for kernel, args in compile_plan(*seen["args"]):
    index = kernel._cache._cache_file._load_index()
    print(kernel.py_func.__name__, len(index), ahead.signature(args) in [key[0] for key in index])
"""


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="compiling ahead needs a second core")
def test_the_plan_compiles_the_signatures_the_step_loop_calls(tmp_path):
    """A cold run of the paper's plate (a private, empty numba cache) compiles ahead; afterwards
    each kernel of the plan has exactly one compiled signature in the cache, the plan's: had the
    plan typed a call differently from the step loop, the first process would have compiled the
    loop's own signature beside it. The run's result equals one from the warm shared cache."""
    import xarray as xr

    (tmp_path / "spy.py").write_text(SPY)
    case = ["run", "paper", "--solid", "plate", "--excite", "SSGM:C", "--shock", "strong", "--duration", "20us"]
    env = {k: v for k, v in os.environ.items() if k != "GRANEL_COMPILE_AHEAD"}
    out = subprocess.run([sys.executable, "spy.py", *case, "-o", str(tmp_path / "cold.nc")], cwd=tmp_path,
                         env={**env, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}, capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = out.stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("ahead "))
    assert lines[start] == "ahead True 0", lines[start]
    plan = [line.split() for line in lines[start + 1:]]
    assert [p[0] for p in plan] == ["interface_solve", "accept", "friction_slopes", "state_ledger", "trial_step",
                                    "step_error"]
    assert all(p[1:] == ["1", "True"] for p in plan), plan
    warm = subprocess.run([sys.executable, "-m", "granel", *case, "-o", str(tmp_path / "warm.nc")], env=env,
                          capture_output=True, text=True, timeout=900)
    assert warm.returncode == 0, warm.stderr[-3000:]
    with xr.open_dataset(tmp_path / "cold.nc") as a, xr.open_dataset(tmp_path / "warm.nc") as b:
        for name in ("x", "y", "v_y", "solid_eta", "contact_force_normal", "balance_error"):
            assert (a[name].values == b[name].values).all(), name
