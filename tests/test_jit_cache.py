"""granel's compiled-code cache is keyed by every kernel source (`granel.guard.jit`): a kernel that
inlines a function of another file is recompiled when only that file changes. numba's own cache,
keyed by each function's own file, keeps the stale machine code: the control below shows it."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from granel.guard import jit

CALLER = """\
{import_njit}
from helper import g


@njit(cache=True)
def f():
    return g() + 1
"""
HELPER = """\
{import_njit}


@njit(cache=True, inline="always")
def g():
    return {value}
"""
KEYED = ("from pathlib import Path\nfrom granel.guard.jit import cached_njit\n"
         "here = Path(__file__).parent\nnjit = cached_njit((here / 'caller.py', here / 'helper.py'), home=here)")
PLAIN = "from numba import njit"


def _package(tmp_path: Path, import_njit: str, value: int) -> None:
    (tmp_path / "caller.py").write_text(CALLER.format(import_njit=import_njit))
    (tmp_path / "helper.py").write_text(HELPER.format(import_njit=import_njit, value=value))


def _run(tmp_path: Path) -> int:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    out = subprocess.run([sys.executable, "-c", "import caller; print(caller.f())"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


def _edit_helper(tmp_path: Path, import_njit: str, value: int) -> None:
    # the same size and a later time stamp: only the helper's own cache entries would notice
    (tmp_path / "helper.py").write_text(HELPER.format(import_njit=import_njit, value=value))


@pytest.mark.parametrize("keyed", [True, False], ids=["granel", "numba-control"])
def test_an_inlined_helper_edited_alone_is_recompiled(tmp_path, keyed):
    imp = KEYED if keyed else PLAIN
    _package(tmp_path, imp, 1)
    assert _run(tmp_path) == 2  # compiled and cached
    assert _run(tmp_path) == 2  # from the cache
    _edit_helper(tmp_path, imp, 5)
    if keyed:
        assert _run(tmp_path) == 6
        folders = sorted(p.name for p in (tmp_path / "__pycache__").iterdir() if p.name.startswith(jit.PREFIX))
        assert len(folders) == 2  # the old sources' folder is kept (KEEP), a new one made
    else:
        assert _run(tmp_path) == 2  # numba alone runs the stale inlined helper


def test_the_key_follows_every_source_and_prune_keeps_the_newest(tmp_path):
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("y = 2\n")
    k0 = jit.sources_key((a, b))
    assert k0 == jit.sources_key((a, b)) and len(k0) == 16
    b.write_text("y = 3\n")
    assert jit.sources_key((a, b)) != k0
    base = tmp_path / "cache"
    names = [f"{jit.PREFIX}{i:016x}" for i in range(7)]
    for i, n in enumerate(names):
        (base / n).mkdir(parents=True)
        os.utime(base / n, (1000 + i, 1000 + i))
    (base / "kernels-notahash").mkdir()
    (base / "other").mkdir()
    removed = jit.prune(base / names[-1], keep=3)
    left = sorted(p.name for p in base.iterdir())
    assert sorted(p.name for p in removed) == names[:4]
    assert left == sorted(names[4:] + ["kernels-notahash", "other"])  # only its own kind of folder goes


def test_granel_kernels_cache_under_their_key():
    from granel.coupling import exact
    from granel.granular import kernels

    key = jit.sources_key(jit.KERNEL_SOURCES)
    for fn in (kernels.rhs, exact.accept):
        assert f"{jit.PREFIX}{key}" in str(fn._cache._cache_path)
