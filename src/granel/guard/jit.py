"""numba's on-disk cache of granel's compiled kernels, keyed by all of their sources:
`cached_njit(sources)` gives a `numba.njit` whose cache folder is named after a hash of every
listed source and numba's version (`cache_folder`), with a manifest of the folder's files checked
before a kernel is loaded, and one compile lock per kernel, so that processes starting at once
compile each kernel once. docs/architecture.md ("The compiled-code cache") describes the folders,
the manifest and the locks."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numba
from numba.core import config

from .exits import STOPPED, GranelError

PACKAGE = Path(__file__).resolve().parent.parent  # granel/


def kernel_sources(package: Path = PACKAGE) -> tuple[Path, ...]:
    """Every module of the package that compiles functions (it imports `njit` from here): they
    inline and call each other, so they share one key."""
    found = []
    for p in sorted(package.rglob("*.py")):
        if "__pycache__" in p.parts:
            continue
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        if "import njit" in text and "guard.jit" in text and p.name != "jit.py":
            found.append(p)
    return tuple(found)


KERNEL_SOURCES = kernel_sources()
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


def _unusable(folder: Path) -> str | None:
    """Why `folder` cannot hold a cache (it is made if missing), or None if it can."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".granel-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
        return None
    except OSError as e:
        return e.strerror or str(e)
    except ValueError as e:  # a NUL in the name
        return str(e)


def _home_cache() -> list[Path]:
    try:
        return [Path.home() / ".cache" / "granel" / "numba"]
    except (RuntimeError, KeyError, OSError):  # no home to be found
        return []


def cache_folder(sources, home: Path) -> Path | None:
    """Where the compiled code of `sources` is cached (made if missing): NUMBA_CACHE_DIR's
    folder, else `home`/__pycache__, else ~/.cache/granel/numba, the first that can be written;
    None if none can (the kernels are then compiled in every process). A NUMBA_CACHE_DIR that
    cannot be used, or no folder at all, is said in one note (`_announce`)."""
    key = sources_key(sources)
    user = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    why = None
    if user:
        folder = Path(user) / f"granel-{PREFIX}{key}"
        why = _unusable(folder)
        if why is None:
            return folder
    found = next((base / f"{PREFIX}{key}" for base in (home / "__pycache__", *_home_cache())
                  if _unusable(base) is None), None)
    instead = (f"granel keeps its compiled kernels in {found.parent} instead" if found is not None else
               "no other folder can be written either, so granel compiles its kernels in every process (about a minute)")
    if user:
        _announce(f"compiled-kernel cache: NUMBA_CACHE_DIR={user} cannot be used ({why}); {instead}")
    elif found is None:
        _announce(f"compiled-kernel cache: neither {home / '__pycache__'} nor ~/.cache/granel/numba can be written; "
                  "granel compiles its kernels in every process (about a minute); set NUMBA_CACHE_DIR to a folder "
                  "it can write")
    return found


_ANNOUNCED: set = set()


def _announce(message: str) -> None:
    """`message` as one line on standard error, once per process, in the process the user started
    only (not a study's workers): the kernels are decorated as granel is imported, before the
    command line shows warnings."""
    import multiprocessing
    import sys

    if message in _ANNOUNCED or multiprocessing.parent_process() is not None:
        return
    _ANNOUNCED.add(message)
    try:
        sys.stderr.write(f"note: {message}\n")
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass


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
    """`numba.njit` whose `cache=True` caches in the folder of `sources`' key (`cache_folder`),
    or nowhere: never in numba's own folders, which would keep stale kernels."""
    state = {}

    def folder() -> Path | None:
        if "folder" not in state:
            state["folder"] = f = cache_folder(sources, home)
            if f is not None and f.parent.exists():
                prune(f)
        return state["folder"]

    def njit(*args, **options):
        if args and callable(args[0]):  # bare @njit
            return njit(**options)(args[0])
        deco = numba.njit(*args, **options)
        if not options.get("cache"):
            return deco

        def apply(fn):
            f = folder()
            if f is None:
                return numba.njit(*args, **{**options, "cache": False})(fn)
            with _cache_dir(f):
                try:
                    dispatcher = deco(fn)
                except RuntimeError:  # numba found no folder it could write after all
                    return numba.njit(*args, **{**options, "cache": False})(fn)
            if not str(getattr(dispatcher._cache, "_cache_path", "")).startswith(str(f)):
                from numba.core.caching import NullCache

                dispatcher._cache = NullCache()  # numba fell back to a folder of its own
            return checked(dispatcher)
        return apply

    return njit


# ---------------------------------------------------------------- the cache's manifest

MANIFEST = "granel-manifest.json"
MANIFEST_LOCK = ".granel-manifest.lock"
_MANIFESTS: dict = {}  # folder -> ((device, inode, size, mtime_ns) of its manifest, its files)
_LISTINGS: dict = {}  # folder -> ((device, inode, mtime_ns) of the folder, its numba files by kernel)
_NOTED: set = set()


def checked(dispatcher):
    """`dispatcher` (a numba.njit with cache=True) with its cache checked before each load
    (`_check_kernel`) and recorded after each save (`_record_kernel`). A kernel whose damaged
    files cannot be removed is compiled without the cache. A kernel missing from the cache is
    compiled under its compile lock (`compile_lock_path`), after one more look at the cache
    once the lock is held (`_compile_lock`)."""
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if index is None:  # no disk cache (numba found no folder to write): nothing to check
        return dispatcher
    folder, base = Path(cache._cache_path), Path(index).name.removesuffix(".nbi")
    lock = compile_lock_path(folder, base)
    load, save = cache.load_overload, cache.save_overload

    def load_overload(sig, target_context):
        held = lock in _COMPILING["held"]
        if not held and _check_kernel(folder, base, remove=False):
            got = load(sig, target_context)
            if got is not None:
                return got
        if not held and _COMPILING["depth"]:
            # a miss, or files another process is writing: look again once the lock is held
            fd = _compile_lock(lock)
            if fd is not None:
                _COMPILING["held"][lock] = (_COMPILING["depth"], fd)
        if not _check_kernel(folder, base):
            cache.disable()
        return load(sig, target_context)

    def save_overload(sig, data):
        save(sig, data)
        _record_kernel(folder, base)

    cache.load_overload, cache.save_overload = load_overload, save_overload
    dispatcher.compile = _locked_compile(dispatcher.compile)
    return dispatcher


# ---------------------------------------------------------------- one compile for all processes

COMPILE_LOCK = ".granel-compile-{}.lock"
COMPILE_WAIT_S = 1200.0  # the longest wait for another process's compile (a cold compile: about a minute)
COMPILE_NOTE_S = 2.0  # a wait longer than this is announced (once per process)
# the nesting of compiles in this process, and the compile locks it holds: {path: (depth, descriptor)}
_COMPILING = {"depth": 0, "held": {}}
HELPERS: set = set()  # the processes this one started to compile ahead of it (their pids)


def compile_lock_path(folder: Path, base: str) -> Path:
    """The compile lock of the kernel whose cache files are `folder`/`base`.*"""
    return Path(folder) / COMPILE_LOCK.format(base)


class CompileWaitTimeout(GranelError, RuntimeError):
    """Another process held the compile lock longer than COMPILE_WAIT_S (exit 3)."""

    code = STOPPED


def _locked_compile(compile_):
    """numba's `Dispatcher.compile` counting the nesting of compiles: the compile lock a miss took
    (`checked`) is released when the compile that took it ends (after numba saved the kernel),
    whatever ends it."""

    from numba.core.compiler_lock import global_compiler_lock

    def compile(sig):
        with global_compiler_lock:  # numba's own (re-entrant): one thread of a process compiles at a time
            _COMPILING["depth"] += 1
            depth = _COMPILING["depth"]
            try:
                return compile_(sig)
            finally:
                _COMPILING["depth"] -= 1
                held = _COMPILING["held"]
                for path in [p for p, (d, _) in held.items() if d >= depth]:
                    os.close(held.pop(path)[1])  # releases the lock

    return compile


def _compile_lock(path: Path, wait_s: float | None = None):
    """The exclusive lock `path` (a descriptor; closing it releases the lock, as the end of the
    process does), its holder's token written in it; waits while another process holds it,
    announcing a wait beyond COMPILE_NOTE_S, and raises CompileWaitTimeout after `wait_s`
    (COMPILE_WAIT_S). None where the system has no flock or the folder is not writable (the
    compile then goes ahead unlocked)."""
    import time

    try:
        import fcntl
    except ImportError:
        return None
    wait_s = COMPILE_WAIT_S if wait_s is None else wait_s
    path = Path(path)
    folder = path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
    except OSError:
        return None
    start = time.monotonic()
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except BlockingIOError:
            waited = time.monotonic() - start
            if waited > wait_s:
                holder = _holder(fd)
                os.close(fd)
                raise CompileWaitTimeout(
                    f"compiled-kernel cache: waited {waited:.0f} s for {holder} to compile granel's kernels into "
                    f"{folder} (it holds {path}); let it finish or stop it, or give this process another cache "
                    "(NUMBA_CACHE_DIR)") from None
            if waited > COMPILE_NOTE_S and not _own_helper(fd):
                _note(("compile-wait",), f"compiled-kernel cache: waiting for {_holder(fd)}, which compiles "
                      f"granel's kernels into {folder} (at most {wait_s:.0f} s per kernel)")
            time.sleep(0.02)  # short: a process may wait for many small kernels in turn
        except OSError:
            os.close(fd)
            return None
    _claim(fd)
    return fd


def _own_helper(fd: int) -> bool:
    """Whether the lock's holder is a process this one started to compile ahead (`guard.ahead`):
    a wait for it is part of this process's own compile, not announced."""
    try:
        token = os.pread(fd, 200, 0).decode("ascii", "replace").strip()
        return int(token.rsplit("-", 2)[-2]) in HELPERS
    except (OSError, ValueError, IndexError):
        return False


def _holder(fd: int) -> str:
    """"process HOST-PID-START" as the lock's holder wrote itself in, or "another process"."""
    try:
        token = os.pread(fd, 200, 0).decode("ascii", "replace").strip()
    except OSError:
        token = ""
    return f"process {token}" if token else "another process"


def _claim(fd: int) -> None:
    """Write this process's token in the lock it now holds (for the messages of its waiters)."""
    from .owners import process_token

    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, process_token().encode("ascii", "replace") + b"\n", 0)
    except OSError:
        pass


def _kernel_files(folder: Path, base: str) -> list[Path]:
    """The cache files numba keeps for the kernel `base`: its index BASE.nbi and its data files
    BASE.N.nbc, those present (from the folder's listing, read again when the folder changed,
    and probed by name)."""
    names = set(_listing(folder).get(base, ()))
    names.add(f"{base}.nbi")
    number = 1
    while (folder / f"{base}.{number}.nbc").exists():
        names.add(f"{base}.{number}.nbc")
        number += 1
    return [folder / n for n in sorted(names) if (folder / n).exists()]


def _listing(folder: Path) -> dict:
    """{kernel: its file names} of the numba files in `folder`, kept while the folder is unchanged."""
    try:
        st = os.stat(folder)
        stamp = (st.st_dev, st.st_ino, st.st_mtime_ns)
        held = _LISTINGS.get(folder)
        if held is not None and held[0] == stamp:
            return held[1]
        kernels: dict = {}
        for entry in os.scandir(folder):
            name = entry.name
            if name.endswith(".nbi"):
                kernels.setdefault(name[:-4], []).append(name)
            elif name.endswith(".nbc"):
                base, _, number = name[:-4].rpartition(".")
                if number.isdigit():
                    kernels.setdefault(base, []).append(name)
    except OSError:
        return {}
    _LISTINGS[folder] = (stamp, kernels)
    return kernels


def _crc32(path: Path) -> tuple[int, int]:
    from .fingerprints import file_crc32

    return file_crc32(path)


def _manifest(folder: Path) -> dict:
    """The manifest of `folder` ({name: [size, crc32]}; empty when missing or unreadable), read
    again only when it changed."""
    path = folder / MANIFEST
    try:
        st = os.stat(path)
    except OSError:
        return {}
    stamp = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    held = _MANIFESTS.get(folder)
    if held is not None and held[0] == stamp:
        return held[1]
    try:
        files = json.loads(path.read_text())["files"]
        files = {str(k): [int(v[0]), int(v[1])] for k, v in files.items()}
    except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError):
        files = {}
    _MANIFESTS[folder] = (stamp, files)
    return files


def _check_kernel(folder: Path, base: str, remove: bool = True) -> bool:
    """Check the cached files of kernel `base` against the manifest; if one is unknown to it or
    does not match it, remove them all (numba then compiles the kernel again) with a note.
    False if they cannot be removed, or, with remove=False, if they do not match."""
    files = _kernel_files(folder, base)
    if not files:
        return True
    known = _manifest(folder)
    why = None
    for f in files:
        entry = known.get(f.name)
        try:
            got = list(_crc32(f))
        except OSError as e:
            got, why = None, f"cannot be read ({e.strerror or e})"
        if why is None and entry is None:
            why = "is not in the cache's manifest" if known else "has no manifest beside it"
        elif why is None and got[0] != entry[0]:
            why = f"holds {got[0]} bytes, the manifest {entry[0]}"
        elif why is None and got[1] != entry[1]:
            why = "does not match its checksum in the manifest"
        if why:
            break
    if why is None:
        return True
    if not remove:
        return False
    removed = True
    for g in files:
        try:
            g.unlink()
        except FileNotFoundError:
            pass
        except OSError:
            removed = False
    _note(("damaged", folder), f"compiled-kernel cache: {folder / f.name} {why}; "
          + ("its kernel's files removed, and numba compiles it again" if removed else
             "they cannot be removed, so the kernel is compiled without the cache"))
    return removed


def _note(key, message: str) -> None:
    """`message` as a warning (one line on the command line), once per process for `key`."""
    import warnings

    if key not in _NOTED:
        _NOTED.add(key)
        warnings.warn(message, stacklevel=3)


@contextmanager
def _manifest_lock(folder: Path):
    """An exclusive lock on the folder's manifest (released when the process ends, whatever
    ends it); none where the system has no flock."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    fd = os.open(folder / MANIFEST_LOCK, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _record_kernel(folder: Path, base: str) -> None:
    """Sync the cached files of kernel `base` (numba does not), then record their sizes and
    checksums in the folder's manifest, merged with what other processes recorded there, and
    sync that. A manifest that cannot be written leaves the kernel unrecorded: the next process
    compiles it again."""
    from .writing import fsync_path, write_text

    try:
        with _manifest_lock(folder):
            _MANIFESTS.pop(folder, None)
            files = dict(_manifest(folder))
            for f in _kernel_files(folder, base):
                fsync_path(f)
                files[f.name] = list(_crc32(f))
            fsync_path(folder)  # numba's renames
            files = {name: v for name, v in files.items() if (folder / name).exists()}
            write_text(folder / MANIFEST, json.dumps({"format": 1, "numba": numba.__version__, "files": files},
                                                     indent=0, sort_keys=True) + "\n")
    except OSError as e:
        _note(("unwritable", folder), f"compiled-kernel cache: {folder / MANIFEST} cannot be written "
              f"({e.strerror or e}); the next process compiles the kernels compiled here again")


njit = cached_njit(KERNEL_SOURCES)
