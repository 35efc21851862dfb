"""granel's own cache is checked before it is used (solid.cache_files's checked cache files, granel.guard.jit's
manifest of numba's files): a damaged entry is rebuilt, never used; a cache that cannot be
written is skipped with a note; a lock of a dead holder is taken over at once, and a wait for a
live one is announced and bounded."""

import errno
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from granel.guard import jit
from granel import scenario as S
from granel.guard.owners import process_token, start_ticks
from granel.run import run_scenario
from granel.solid import cache_files, cache_lock, mode_cache, modal
from granel.solid.base import Material, Slab
from granel.solid.plate import LayerSpec, PlateMesh, assemble_plate, build_plate

# a coarse plate (752 DOFs) at fixed 100 ns steps over 0.05 ms, strong shock on SSGM:C: the run
# of test_mode_scaling, about 0.1 s once compiled
COARSE = ["solid.mesh.nx=2", "solid.mesh.growth=3.0", "solid.mesh.max_size=0.01", 'excitations.0.granule="SSGM:C"',
          'simulation.duration="0.05ms"', "simulation.adaptive=false", "simulation.dt=1e-7"]
FIELDS = ("energy_solid", "energy_lsgm", "energy_ssgm", "input_work", "v_x", "v_y", "contact_force_normal")


def outcome(result) -> dict:
    return {name: np.array(result[name].values) for name in FIELDS}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """The coarse run from an empty cache (the cache then holds its plate and modes), and the files
    that cache holds."""
    folder = tmp_path_factory.mktemp("clean")
    mp = pytest.MonkeyPatch()
    mp.setenv("GRANEL_CACHE", str(folder))
    try:
        result = outcome(run_scenario(S.load("paper", COARSE)))
    finally:
        mp.undo()
    return result, folder


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRANEL_CACHE", str(tmp_path))
    return tmp_path


def damage(path: Path, how: str) -> None:
    """Truncate the file to half, zero its second half (its size kept: blocks never written),
    flip one bit in its middle, or remove its check record (a file of an older cache)."""
    if how == "no record":
        cache_files.check_path(path).unlink()
        return
    data = bytearray(path.read_bytes())
    half = len(data) // 2
    if how == "truncated":
        data = data[:half]
    elif how == "zero-filled":
        data[half:] = bytes(len(data) - half)
    else:
        data[half] ^= 0x10
    path.write_bytes(bytes(data))


ENTRIES = {"shapes": "modes-*.shapes.npy", "omega": "modes-*.omega.npy", "plate": "plate-*.npz"}


@pytest.mark.parametrize("how", ["truncated", "zero-filled", "bit-flipped", "no record"])
@pytest.mark.parametrize("entry", list(ENTRIES))
def test_a_damaged_cache_file_is_rebuilt_and_the_run_equals_the_clean_one(clean, cache, entry, how):
    """Each damaged file is noticed, noted, rebuilt and checked again, and the run equals the
    clean run's exactly: the rebuilt entry comes from the same solver on the same matrices in the
    same process. (Used as they were, zero-filled shapes would hold part of the solid at rest.)"""
    import shutil

    expected, folder = clean
    for f in folder.iterdir():
        shutil.copy2(f, cache / f.name)
    (target,) = cache.glob(ENTRIES[entry])
    damage(target, how)
    with pytest.warns(cache_files.CacheNote, match=f"cache: {target.name}"):
        got = outcome(run_scenario(S.load("paper", COARSE)))
    assert cache_files.verify(target) is None  # written again, with its record
    for name in FIELDS:
        assert np.array_equal(got[name], expected[name]), name
    assert np.abs(got["energy_solid"]).max() > 0


@pytest.mark.parametrize("how", ["truncated", "zero-filled", "bit-flipped", "no record"])
def test_a_damaged_scale_record_is_never_a_base(cache, how):
    """A set whose scale-free record is damaged does not serve a proportional solid: that solid's
    modes are computed, and the damaged set is removed."""
    args = (Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), [LayerSpec("A", "left", 0.05, 1e-3)],
            PlateMesh(2, 2.5, 8e-3))
    mode_cache.all_modes(build_plate(*args))
    (record,) = cache.glob("modes-*.scale.npz")
    damage(record, how)
    with pytest.warns(cache_files.CacheNote, match=f"{record.name}.*removed"):
        thicker = mode_cache.all_modes(build_plate(Slab(0.0, 0.0, 0.01, 0.1, 0.0013), *args[1:]))
    assert thicker.origin == "computed" and not record.exists()
    (base,) = cache.glob("modes-*.scale.npz")  # the thicker plate's own
    assert cache_files.verify(base) is None


def test_a_record_lost_alone_is_written_again(cache):
    """The modes' own files intact, their scale record damaged: the modes serve, the record is
    written again."""
    plate = build_plate(Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), [LayerSpec("A", "left", 0.05, 1e-3)], PlateMesh(2, 2.5, 8e-3))
    mode_cache.all_modes(plate)
    (record,) = cache.glob("modes-*.scale.npz")
    damage(record, "bit-flipped")
    with pytest.warns(cache_files.CacheNote, match="writing it again"):
        assert mode_cache.all_modes(plate).origin == "cache"
    assert cache_files.verify(record) is None


def test_every_cache_file_has_its_check_record(clean):
    _, folder = clean
    data = [f for f in folder.iterdir() if not f.name.endswith(cache_files.CHECK_SUFFIX)]
    assert len(data) == 4  # the plate, the modes' frequencies, shapes and scale record
    for f in data:
        record = json.loads(cache_files.check_path(f).read_text())
        assert record["size"] == f.stat().st_size and record["crc32"] == cache_files.file_crc32(f)[1]


def test_pruning_removes_a_file_with_its_record(cache):
    for name in ("plate-a-1.npz", "plate-a-2.npz"):
        cache_files.write_checked(cache / name, np.zeros(1000))
        os.utime(cache / name, (1e9, 1e9))
    (cache / "plate-a-3.npz.sum").write_text("{}")  # a record left without its file
    removed = cache_files.prune_cache(keep=(cache / "plate-a-2.npz",), limit=0)
    assert [p.name for p in removed] == ["plate-a-1.npz"]
    assert sorted(p.name for p in cache.iterdir()) == ["plate-a-2.npz", "plate-a-2.npz.sum"]


# ---------------------------------------------------------------- a cache that cannot be written


def small_plate():
    layers = [LayerSpec("a", "left", 0.05, 0.001), LayerSpec("b", "right", 0.04, 0.001)]
    return (Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), layers, PlateMesh(2, 2.5, 8e-3))


def test_a_cache_path_that_is_a_file_is_skipped_with_a_note(tmp_path, monkeypatch):
    blocker = tmp_path / "cache"
    blocker.write_text("not a folder")
    monkeypatch.setenv("GRANEL_CACHE", str(blocker))
    with pytest.warns(cache_files.CacheNote, match="is a file, not a folder.*without the cache"):
        plate = build_plate(*small_plate())
        modes = mode_cache.all_modes(plate)
    assert modes.origin == "computed" and modes.count == plate.ndof
    assert blocker.read_text() == "not a folder"


def test_a_full_disk_is_skipped_with_a_note_and_leaves_no_temporaries(cache, monkeypatch):
    def full(path, array):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(cache_files, "_write_npy", full)
    with pytest.warns(cache_files.CacheNote, match="no space left"):
        plate = build_plate(*small_plate())
        assert mode_cache.all_modes(plate).origin == "computed"
    assert list(cache.iterdir()) == []


def _runs_as_nobody() -> bool:
    """Whether this interpreter starts as the user nobody (it may not: a Python installed under
    root's home, or its shared library there, is out of nobody's reach)."""
    import shutil

    if shutil.which("setpriv") is None:
        return False
    probe = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c",
                            "import granel"], capture_output=True, text=True, timeout=120)
    return probe.returncode == 0


def test_a_read_only_cache_is_skipped_with_a_note(monkeypatch):
    """A real read-only folder: a process that cannot write it (a folder it does not own, with
    no write permission). Root writes anywhere, so then the process runs as nobody through
    setpriv; where nobody cannot start this Python, the same refusal is made in this process: every
    creation under the folder fails with EACCES, as the kernel answers a reader without write
    permission."""
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="granel-ro-"))
    code = ("from granel.solid import mode_cache\nfrom granel.solid.base import Material, Slab\n"
            "from granel.solid.plate import LayerSpec, PlateMesh, build_plate\n"
            "layers = [LayerSpec('a', 'left', 0.05, 0.001), LayerSpec('b', 'right', 0.04, 0.001)]\n"
            "plate = build_plate(Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), layers, PlateMesh(2, 2.5, 8e-3))\n"
            "print(mode_cache.all_modes(plate).origin)\n")
    env = {**os.environ, "GRANEL_CACHE": str(folder), "PYTHONDONTWRITEBYTECODE": "1"}
    command = [sys.executable, "-c", code]
    try:
        if os.geteuid() == 0 and not _runs_as_nobody():
            _read_only_in_process(folder, monkeypatch)
            return
        if os.geteuid() == 0:
            folder.chmod(0o755)  # root's: nobody may read it, not write it
            command = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", *command]
            env["HOME"] = str(folder)
        else:
            folder.chmod(0o555)
        res = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
        assert res.stdout.split()[-1] == "computed"
        assert "cannot be written" in res.stderr and "computing without the cache" in res.stderr
        assert list(folder.iterdir()) == []
    finally:
        folder.chmod(0o755)
        shutil.rmtree(folder, ignore_errors=True)


def _read_only_in_process(folder: Path, monkeypatch) -> None:
    """The read-only case in this process: os.open and os.mkdir under `folder` fail with EACCES."""
    real_open, real_mkdir = os.open, os.mkdir
    inside = str(folder.resolve()) + os.sep

    def denied(path) -> bool:
        return os.path.abspath(os.fspath(path)).startswith(inside)

    def fake_open(path, flags, *args, **kwargs):
        if denied(path) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real_open(path, flags, *args, **kwargs)

    def fake_mkdir(path, *args, **kwargs):
        if denied(path):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setenv("GRANEL_CACHE", str(folder))
    monkeypatch.setattr(os, "open", fake_open)
    monkeypatch.setattr(os, "mkdir", fake_mkdir)
    monkeypatch.setattr(cache_files, "_NOTED", set())
    with pytest.warns(cache_files.CacheNote, match="cannot be written.*computing without the cache"):
        plate = build_plate(*small_plate())
        origin = mode_cache.all_modes(plate).origin
    monkeypatch.undo()
    assert origin == "computed"
    assert list(folder.iterdir()) == []


def test_granel_run_with_the_cache_path_a_file_completes(tmp_path):
    """The command line, GRANEL_CACHE naming a regular file: the run ends (exit 0) with the note,
    within a bound (the lock loop used to spin forever there)."""
    blocker = tmp_path / "cache"
    blocker.write_text("")
    out = tmp_path / "out.nc"
    args = [a for s in COARSE for a in ("--set", s)]
    res = subprocess.run([sys.executable, "-m", "granel", "run", "paper", *args, "-o", str(out)],
                         env={**os.environ, "GRANEL_CACHE": str(blocker)}, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "is a file, not a folder" in res.stderr and out.exists()


# ---------------------------------------------------------------- locks


@pytest.fixture
def plate(cache, monkeypatch):
    monkeypatch.setattr(cache_lock, "LOCK_POLL_S", 0.02)
    return assemble_plate(*small_plate())


def lock_of(plate, token: str, since: float | None = None) -> Path:
    """A lock on the plate's modes naming the process of `token`, taken at `since` (now)."""
    lock = mode_cache._stem(plate, "modes", "").with_suffix(".lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    lock.write_text(json.dumps({"token": token, "host": "there", "pid": int(token.split("-")[1]),
                                "since": time.time() if since is None else since, "what": "modes"}))
    return lock


def no_wait(*args):
    raise AssertionError("waited for a lock whose holder is gone")


def test_a_lock_of_a_dead_process_is_taken_over_at_once(plate, monkeypatch):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = lock_of(plate, process_token(dead.pid))
    monkeypatch.setattr(mode_cache, "_wait_for", no_wait)
    assert mode_cache.all_modes(plate).origin == "computed" and not lock.exists()
    assert mode_cache.all_modes(plate).origin == "cache"


def test_a_lock_whose_pid_now_names_another_process_is_taken_over_at_once(plate, monkeypatch):
    """The holder's pid is alive (this process) but started at another time: the pid was reused."""
    host, pid, start = process_token().split("-")
    assert start_ticks(os.getpid()) == int(start)
    lock = lock_of(plate, f"{host}-{pid}-{int(start) + 1}")
    monkeypatch.setattr(mode_cache, "_wait_for", no_wait)
    assert mode_cache.all_modes(plate).origin == "computed" and not lock.exists()


def test_a_wait_is_announced_once_and_bounded(plate, monkeypatch):
    """A live holder (this process's token) that never finishes: the waiter says what it waits for
    and for whom, gives up at LOCK_WAIT_S after the lock was taken, computes the modes itself and
    leaves the holder's lock and the storing to it."""
    monkeypatch.setattr(cache_lock, "LOCK_WAIT_S", 0.3)
    lock = lock_of(plate, process_token())
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        modes = mode_cache.all_modes(plate)
    notes = [str(w.message) for w in seen if issubclass(w.category, cache_files.CacheNote)]
    assert len(notes) == 1 and "waiting for the modes of a plate of 408 DOFs" in notes[0]
    assert f"process {os.getpid()} on this host" in notes[0] and "at most until" in notes[0]
    assert modes.origin == "computed" and lock.exists()
    assert not list(lock.parent.glob("modes-*.npy"))


def test_a_holder_older_than_the_bound_is_not_waited_for(plate, monkeypatch):
    lock = lock_of(plate, process_token(), since=time.time() - cache_lock.LOCK_WAIT_S - 60)
    with pytest.warns(cache_files.CacheNote, match="longer than 600 s; computing them here too"):
        assert mode_cache.all_modes(plate).origin == "computed"
    assert lock.exists()


def test_a_lock_of_another_host_is_stale_after_the_bound(plate, monkeypatch):
    lock = lock_of(plate, "ffffffff-1234-5678")  # no host hashes to that
    old = time.time() - cache_lock.LOCK_WAIT_S - 60
    os.utime(lock, (old, old))
    monkeypatch.setattr(mode_cache, "_wait_for", no_wait)
    assert mode_cache.all_modes(plate).origin == "computed" and not lock.exists()


# ---------------------------------------------------------------- numba's cache

KERNEL = """\
from pathlib import Path
from granel.guard.jit import cached_njit

here = Path(__file__).parent
njit = cached_njit((here / "kernel.py",), home=here)


@njit(cache=True)
def f(n):
    s = 0.0
    for i in range(n):
        s += (i % 7) * 0.5
    return s


@njit(cache=True)
def g(n):
    return f(n) + 1.0
"""


def run_kernel(folder: Path, cache: Path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, "-c", "import kernel; print(kernel.g(1000), kernel.f(10))"], cwd=folder,
                          env=env, capture_output=True, text=True, timeout=300)


def numba_files(cache: Path) -> list[Path]:
    return sorted(p for p in cache.rglob("*") if p.suffix in (".nbi", ".nbc"))


def test_a_damaged_numba_cache_is_cleared_and_compiled_again(tmp_path):
    """A private numba cache (NUMBA_CACHE_DIR): a data file truncated, one zero-filled, an index
    with a flipped bit, a file the manifest never recorded, the manifest lost. Each time the next
    process removes the damaged kernel's files before numba loads them (numba alone ends in a
    pickle error or an LLVM assertion), compiles it again, says so in one line and gives the
    right result; the process after the last loads everything from the cache, silently."""
    (tmp_path / "kernel.py").write_text(KERNEL)
    cache = tmp_path / "numba"
    first = run_kernel(tmp_path, cache)
    assert first.returncode == 0, first.stderr[-2000:]
    expected = first.stdout.split()
    files = numba_files(cache)
    assert [p.suffix for p in files] == [".nbc", ".nbi", ".nbc", ".nbi"]  # f and g: a data file and an index each
    (manifest,) = cache.rglob(jit.MANIFEST)
    assert sorted(json.loads(manifest.read_text())["files"]) == sorted(p.name for p in files)
    f_data, f_index, g_data, g_index = files
    # data files numba wrote but the manifest never recorded: the next in line, and one past a gap
    unrecorded = [g_data.with_name(g_data.name.replace(".1.nbc", ".2.nbc")),
                  f_data.with_name(f_data.name.replace(".1.nbc", ".7.nbc"))]
    for how, victims in (("truncated", [g_data]), ("zero-filled", [f_data]), ("bit-flipped", [f_index]),
                         ("unrecorded", unrecorded), ("no manifest", [manifest])):
        for victim in victims:
            if how == "unrecorded":
                victim.write_bytes(g_data.read_bytes()[:100])
            elif how == "no manifest":
                victim.unlink()
            else:
                damage(victim, how)
        res = run_kernel(tmp_path, cache)
        assert res.returncode == 0, (how, res.stderr[-2000:])
        assert res.stdout.split() == expected, how
        assert "compiled-kernel cache:" in res.stderr and "compiles it again" in res.stderr, how
    assert not any(p.exists() for p in unrecorded)
    again = run_kernel(tmp_path, cache)
    assert again.returncode == 0 and again.stdout.split() == expected
    assert "compiled-kernel" not in again.stderr and numba_files(cache) == files
