"""Compile ahead in a second process: `compile_ahead` starts `python -m granel.guard.ahead FILE`,
which compiles the kernels a cold process will call last (the (kernel, arguments) pairs of a
plan) into the same cache while that process compiles the others. docs/architecture.md ("The
compiled-code cache") says when it starts; docs/performance.md what it saves."""

from __future__ import annotations

import importlib
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

from .jit import HELPERS, _kernel_files

AHEAD_LOCK = ".granel-ahead.lock"
ENABLE = "GRANEL_COMPILE_AHEAD"  # "0" turns compiling ahead off


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def kernel_files(dispatcher) -> list[Path]:
    """The disk-cache files of a cached kernel (none for a kernel without a disk cache)."""
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if index is None:
        return []
    return _kernel_files(Path(cache._cache_path), Path(index).name.removesuffix(".nbi"))


def compile_ahead(entry, plan: str, args: tuple) -> subprocess.Popen | None:
    """Start the process that compiles `plan(*args)`'s kernels, if `entry` (the kernel whose
    compile includes them) is not cached yet; the process, or None when none was started."""
    if os.environ.get(ENABLE, "1").strip() == "0" or _cores() < 2 or kernel_files(entry):
        return None
    cache = getattr(entry, "_cache", None)
    root = getattr(cache, "_cache_path", None)
    if root is None:
        return None
    try:
        import fcntl
    except ImportError:
        return None
    folder = Path(root).parent  # the kernels-KEY folder, shared by every kernel of granel
    try:
        fd = os.open(folder / AHEAD_LOCK, os.O_CREAT | os.O_RDWR, 0o644)
    except OSError:
        return None
    path = None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return None  # another process compiles ahead into this cache
        with tempfile.NamedTemporaryFile("wb", prefix="granel-ahead-", suffix=".pickle", delete=False) as f:
            path = f.name
            pickle.dump((plan, args), f, protocol=pickle.HIGHEST_PROTOCOL)
        proc = subprocess.Popen([sys.executable, "-m", "granel.guard.ahead", path, str(fd)], pass_fds=(fd,),
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        path = None  # the child removes it
        HELPERS.add(proc.pid)
        return proc
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        return None
    finally:
        os.close(fd)  # the child holds the lock through its own copy of the descriptor
        if path is not None:
            os.unlink(path)


def signature(args: tuple) -> tuple:
    """The numba types of `args`, as a kernel called with them is compiled for."""
    import numba

    return tuple(numba.typeof(a) for a in args)


def run(path: str) -> int:
    """The child: compile each kernel the plan in `path` yields, for its arguments' types."""
    try:
        with open(path, "rb") as f:
            plan, args = pickle.load(f)
    finally:
        os.unlink(path)
    module, _, name = plan.partition(":")
    for kernel, kernel_args in getattr(importlib.import_module(module), name)(*args):
        kernel.compile(signature(kernel_args))
    return 0


if __name__ == "__main__":  # pragma: no cover (run as a process by compile_ahead)
    sys.exit(run(sys.argv[1]))
