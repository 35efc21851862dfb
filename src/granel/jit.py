"""numba's on-disk cache of granel's compiled kernels, keyed by all of their sources.

numba keys a cached function by the time stamp and size of its *own* source file only. A kernel
that inlines or calls a compiled function of another file keeps its cached machine code when only
that other file changes: `coupling/exact.py`'s step ran the right-hand side of `granular/kernels.py`
as it was when the cache was written. (That hid a sixfold slowdown of the right-hand side on every
machine that had compiled before the change, and it could as well hide a change of the physics.)

`cached_njit(sources)` gives a `numba.njit` whose cache sits in a folder named after a hash of
every listed source (and numba's version): any change to any of them starts a new folder, so no
compiled kernel outlives the code it was compiled from. The folder is `__pycache__/kernels-KEY`
beside this package when it can be written (as numba's own in-tree cache), else
`~/.cache/granel/numba/kernels-KEY`; with NUMBA_CACHE_DIR set, `NUMBA_CACHE_DIR/granel-kernels-KEY`.
Folders of this kind left by older sources are removed, the newest KEEP kept (a checkout that
switches branches reuses them)."""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numba
from numba.core import config

PACKAGE = Path(__file__).resolve().parent
# every module that defines compiled functions: they inline and call each other
KERNEL_SOURCES = tuple(PACKAGE / p for p in ("granular/bundles.py", "granular/contact.py", "granular/kernels.py",
                                              "solid/propagation.py", "coupling/core.py", "coupling/exact.py"))
PREFIX = "kernels-"
KEEP = 4


def sources_key(sources) -> str:
    """A hash of the sources' names and bytes and of numba's version (16 hex digits)."""
    h = hashlib.sha256(numba.__version__.encode())
    for p in sources:
        p = Path(p)
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".granel-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
        return True
    except OSError:
        return False


def cache_folder(sources, home: Path) -> Path:
    """Where the compiled code of `sources` is cached (made if missing), `home` being the folder
    whose `__pycache__` holds it when writable."""
    key = sources_key(sources)
    user = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    if user:
        return Path(user) / f"granel-{PREFIX}{key}"
    for base in (home / "__pycache__", Path.home() / ".cache" / "granel" / "numba"):
        if _writable(base):
            return base / f"{PREFIX}{key}"
    return home / "__pycache__" / f"{PREFIX}{key}"  # numba then warns that it cannot cache


def prune(folder: Path, keep: int = KEEP) -> list[Path]:
    """Remove the cache folders of older sources beside `folder` (only folders named as this
    module names them), keeping the `keep` most recently used and `folder` itself."""
    prefix = folder.name[: -16]
    try:
        others = [p for p in folder.parent.iterdir() if p.is_dir() and p != folder and p.name.startswith(prefix)
                  and len(p.name) == len(folder.name) and all(c in "0123456789abcdef" for c in p.name[-16:])]
    except OSError:
        return []
    others.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    removed = []
    for p in others[max(keep - 1, 0):]:
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


@contextmanager
def _cache_dir(folder: Path):
    """numba's CACHE_DIR set to `folder` while a function's cache is set up (its locator is
    chosen then), restored after: other numba code in the process keeps its own cache."""
    old = config.CACHE_DIR
    config.CACHE_DIR = str(folder)
    try:
        yield
    finally:
        config.CACHE_DIR = old


def cached_njit(sources, home: Path = PACKAGE):
    """`numba.njit` whose `cache=True` caches in the folder of `sources`' key (`cache_folder`)."""
    state = {}

    def folder() -> Path:
        if "folder" not in state:
            state["folder"] = f = cache_folder(sources, home)
            if f.parent.exists():
                prune(f)
        return state["folder"]

    def njit(*args, **options):
        if args and callable(args[0]):  # bare @njit
            return njit(**options)(args[0])
        deco = numba.njit(*args, **options)
        if not options.get("cache"):
            return deco

        def apply(fn):
            with _cache_dir(folder()):
                return deco(fn)
        return apply

    return njit


njit = cached_njit(KERNEL_SOURCES)
