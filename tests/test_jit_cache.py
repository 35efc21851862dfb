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


@pytest.fixture(autouse=True)
def _default_numba_cache(monkeypatch):
    """These tests compile into the default cache folder beside their package (NUMBA_CACHE_DIR
    unset): in this process, where they look for the files, as in the children they start."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)


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


def test_an_unusable_numba_cache_dir_is_replaced_with_a_note(tmp_path, monkeypatch, capsys):
    """NUMBA_CACHE_DIR a file, or a folder below a file: granel's own folder instead, said in one
    note naming the variable; with no folder to write at all, none (`cached_njit` then compiles
    without a cache)."""
    src, plain, home = tmp_path / "kern.py", tmp_path / "plain.txt", tmp_path / "pkg"
    src.write_text("x = 1\n")
    plain.write_text("a file, not a folder\n")
    home.mkdir()
    monkeypatch.setenv("HOME", str(plain))  # no ~/.cache to fall back to
    for bad in (plain, plain / "numba"):
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(bad))
        monkeypatch.setattr(jit, "_ANNOUNCED", set())
        assert jit.cache_folder((src,), home) == home / "__pycache__" / f"{jit.PREFIX}{jit.sources_key((src,))}"
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("note: compiled-kernel cache: NUMBA_CACHE_DIR=") \
            and str(home / "__pycache__") in err, err
    assert jit.cache_folder((src,), plain) is None  # plain/__pycache__ is below a file too
    assert "compiles its kernels in every process" in capsys.readouterr().err


def test_no_writable_cache_compiles_without_one(tmp_path):
    """No folder granel can write (NUMBA_CACHE_DIR and HOME files, the package's folder below a
    file): the kernel compiles and runs, and no cache file is written, not even in numba's own
    folder beside the source (keyed by that file alone, it would keep stale kernels)."""
    plain = tmp_path / "plain.txt"
    plain.write_text("a file, not a folder\n")
    (tmp_path / "kern.py").write_text("from pathlib import Path\nfrom granel.guard.jit import cached_njit\n"
                                      "here = Path(__file__).parent\n"
                                      "njit = cached_njit((here / 'kern.py',), home=here / 'plain.txt')\n\n\n"
                                      "@njit(cache=True)\ndef f():\n    return 7\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(plain), "HOME": str(plain)}
    out = subprocess.run([sys.executable, "-c", "import kern; print(kern.f())"], cwd=tmp_path, env=env,
                         capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.split()[-1] == "7", out.stderr
    notes = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(notes) == 1 and "NUMBA_CACHE_DIR" in notes[0] and "every process" in notes[0], out.stderr
    written = [p for p in tmp_path.rglob("*") if p.suffix in (".nbi", ".nbc")]
    assert not written, written
