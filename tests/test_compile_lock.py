"""Processes that start at once compile granel's kernels once (`granel.guard.jit`): a process that
misses a kernel compiles it holding that kernel's compile lock, and the others wait for the lock
and load what it saved; a wait is bounded, with a message naming the holder."""

import os
import subprocess
import sys
import time
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
def f(x):
    return x + 1
"""
# holds the compile lock (as a compile in progress does) for HOLD s, then compiles f under it
HOLDER = """\
import sys, time
from pathlib import Path
import kern
from granel.guard import jit
cache = kern.f._cache
base = Path(cache._cache_file._index_path).name.removesuffix(".nbi")
path = jit.compile_lock_path(Path(cache._cache_path), base)
jit._COMPILING["held"][path] = (1, jit._compile_lock(path))
print("locked", flush=True)
time.sleep(float(sys.argv[1]))
if sys.argv[2] == "compile":
    print(kern.f(1), flush=True)
"""
WAITER = """\
import sys, time
import kern
from granel.guard import jit
jit.COMPILE_WAIT_S = float(sys.argv[1])
start = time.monotonic()
try:
    value = kern.f(1)
except jit.CompileWaitTimeout as e:
    print("timeout", time.monotonic() - start, e)
else:
    print("value", value, "waited", time.monotonic() - start, "misses", sum(kern.f.stats.cache_misses.values()),
          "hits", sum(kern.f.stats.cache_hits.values()))
"""


def _package(tmp_path: Path) -> dict:
    (tmp_path / "kern.py").write_text(KERNEL)
    (tmp_path / "holder.py").write_text(HOLDER)
    (tmp_path / "waiter.py").write_text(WAITER)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), *sys.path])
    return env


def _holder(tmp_path, env, hold: float, then: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "holder.py", str(hold), then], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_process_waits_for_the_compile_and_loads_it(tmp_path):
    env = _package(tmp_path)
    holder = _holder(tmp_path, env, 5.0, "compile")
    try:
        out = subprocess.run([sys.executable, "waiter.py", "120"], cwd=tmp_path, env=env, capture_output=True,
                             text=True, check=True, timeout=300)
    finally:
        holder_out, _ = holder.communicate(timeout=300)
    assert holder_out.split() == ["2"]  # the holder compiled f
    words = out.stdout.split()
    assert words[:2] == ["value", "2"], out.stdout
    assert float(words[3]) > 1.0  # it waited for the holder ...
    assert words[4:] == ["misses", "0", "hits", "1"], out.stdout  # ... and loaded its kernel
    assert "waiting for process" in out.stderr  # announced (a wait beyond COMPILE_NOTE_S)


def test_a_wait_beyond_the_bound_is_a_clear_error(tmp_path):
    env = _package(tmp_path)
    holder = _holder(tmp_path, env, 60.0, "hold")
    try:
        start = time.monotonic()
        out = subprocess.run([sys.executable, "waiter.py", "1"], cwd=tmp_path, env=env, capture_output=True,
                             text=True, check=True, timeout=120)
        assert time.monotonic() - start < 50
    finally:
        holder.kill()
        holder.communicate()
    assert out.stdout.startswith("timeout"), out.stdout + out.stderr
    assert f"-{holder.pid}-" in out.stdout and "NUMBA_CACHE_DIR" in out.stdout  # names the holder and a way out


def test_the_lock_is_released_when_a_compile_fails(tmp_path):
    """A compile that raises (a typing error) leaves no lock held: the next compile proceeds."""
    from granel.guard import jit

    env = _package(tmp_path)
    code = ("import kern\nfrom granel.guard import jit\n"
            "try:\n    kern.f('a', 'b')\nexcept Exception:\n    pass\n"
            "assert jit._COMPILING == {'depth': 0, 'held': {}}, jit._COMPILING\nprint(kern.f(2))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.split() == ["3"]
    locks = [p.name for p in jit.cache_folder((tmp_path / "kern.py",), tmp_path).rglob(".granel-compile-*.lock")]
    assert [name.startswith(".granel-compile-kern.f-") for name in locks] == [True], locks
