"""The solids' modes on disk: all modes, or the modes below a cut-off, of a solid are stored
under a hash of its M and K, each file with a check record (size and CRC-32) so that a damaged
entry is computed again, never used; one process computes a given set at a time, the others wait
for it; a solid proportional to a cached one (another thickness, modulus or density) gets that
one's modes scaled; the least recently used entries are pruned beyond a size bound."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..guard.fingerprints import file_crc32, sparse_digest
from .base import SolidModel
from .modal import Modes, modal_analysis, modes_up_to


# ---------------------------------------------------------------- all modes, cached on disk


def cache_dir():
    """granel's cache folder: GRANEL_CACHE, or ~/.cache/granel when it is unset or empty."""
    import os

    return Path(os.environ.get("GRANEL_CACHE") or Path.home() / ".cache" / "granel")


# granel's own cache files (modes, modes below a cut-off, their scale-free records, assembled
# plates): the only files pruning removes, each with its check record (`CHECK_SUFFIX`)
CACHE_PATTERNS = ("modes-*.omega.npy", "modes-*.shapes.npy", "modes-*.scale.npz", "plate-*.npz")
CACHE_LIMIT = 2 * 1024**3  # bytes, unless GRANEL_CACHE_LIMIT says otherwise


def cache_limit() -> int:
    """The cache's size bound in bytes: GRANEL_CACHE_LIMIT (bytes, or with K, M, G suffix), or 2 GiB."""
    import os

    text = os.environ.get("GRANEL_CACHE_LIMIT", "").strip().upper().removesuffix("B")
    if not text:
        return CACHE_LIMIT
    scale = {"K": 1024, "M": 1024**2, "G": 1024**3}.get(text[-1], 1)
    try:
        value = float(text[:-1] if scale > 1 else text) * scale
    except ValueError:
        return CACHE_LIMIT
    return int(value) if value > 0 else CACHE_LIMIT


def prune_cache(keep=(), limit: int | None = None) -> list:
    """Remove the least recently used of granel's cache files (CACHE_PATTERNS; a cache hit
    touches its files), each with its check record, until the cache holds at most `limit` bytes
    (`cache_limit()`), never the files in `keep` (the ones just written or read): a design study
    meets a new plate at every trial. Check records left without their file go too. Returns the
    removed files (not their records); files it cannot remove are left."""
    limit = cache_limit() if limit is None else limit
    folder = cache_dir()
    files = []
    for pattern in CACHE_PATTERNS:
        for f in folder.glob(pattern):
            try:
                st = f.stat()
            except OSError:
                continue
            try:
                extra = check_path(f).stat().st_size
            except OSError:
                extra = 0
            files.append((st.st_mtime, st.st_size + extra, f))
        for record in folder.glob(pattern + CHECK_SUFFIX):
            if not record.with_name(record.name.removesuffix(CHECK_SUFFIX)).exists():
                _unlink(record)
    total = sum(size for _, size, _ in files)
    keep = {Path(k).resolve() for k in keep}
    removed = []
    for _, size, f in sorted(files):
        if total <= limit:
            break
        if f.resolve() in keep:
            continue
        try:
            f.unlink()
        except OSError:
            continue
        _unlink(check_path(f))
        total -= size
        removed.append(f)
    return removed


def _unlink(path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def all_modes(model: SolidModel) -> Modes:
    """All modes of the solid, cached on disk by a hash of M and K. The shapes come back
    memory-mapped: a run reads only the rows at its contacts (`at_dofs`), a field plot the whole
    matrix. A solid whose K and M are those of a cached one times two scalars (another thickness,
    Young's modulus or density of the same plate) gets that solid's modes scaled (`scaled_modes`),
    with no eigen-solve."""
    what = f"the modes of a {model.kind} of {model.ndof} DOFs"
    return cached_modes(model, "modes", "", lambda: modal_analysis(model, None), mmap=True, what=what)


def modes_below(model: SolidModel, f_cut: float, max_count: int | None = None) -> Modes:
    """The eigenmodes up to f_cut [Hz] (at most `max_count` of them) of a solid too large for all
    of them (beyond DENSE_LIMIT DOFs) or a run that keeps only those (`modal.modes_up_to`); cached on disk by M, K, f_cut and max_count like `all_modes`, and
    scaled like it from a cached set of a proportional solid that reaches far enough."""
    w_cut = 2 * np.pi * f_cut
    top = model.ndof - 1 if max_count is None else min(model.ndof - 1, max_count)

    def compute():
        return modes_up_to(model, w_cut, top)

    what = f"the modes below {f_cut / 1e6:.4g} MHz of a {model.kind} of {model.ndof} DOFs"
    return cached_modes(model, "modes-below", repr((float(f_cut), max_count)), compute, mmap=False, wanted=(w_cut, top),
                   what=what)


def cached_modes(model: SolidModel, prefix: str, key: str, compute, mmap: bool, wanted=(np.inf, None),
            what="modes") -> Modes:
    """Modes from the disk cache (by a hash of M, K and `key`), or scaled from the cached modes
    of a proportional solid (`scaled_modes`), or `compute()` and store them. Only files that match
    their check records are used (`verify`): a damaged entry is computed again, with a note.
    `wanted` = (w_cut [rad/s], most modes): what `compute` returns, the lowest modes up to w_cut,
    at most that many (None: no bound); all modes by default. Each stored set gets a scale-free
    record (`_write_record`). Only one process computes a given set at a time (`_acquire`): the
    others wait for it, within a bound (`_wait_for`). Without a writable cache the modes are
    computed, with a note, and nothing is stored."""
    stem = _stem(model, prefix, key)
    free = _scale_free(model)
    lock = stem.with_suffix(".lock")
    while True:
        modes, damage = _from_cache(model, stem, free, wanted, mmap)
        if modes is None and free is not None:
            modes = scaled_modes(model, prefix, free, wanted, mmap, exclude=stem)
        if modes is not None:
            return modes
        held = _acquire(lock, what)
        if held is False and _wait_for(lock, what):
            continue  # released, or its holder is gone: look again
        try:
            if held:  # stored by another process while this one waited for the lock
                modes, damage = _from_cache(model, stem, free, wanted, mmap)
                if modes is not None:
                    return modes
            if damage:
                note(("rebuilt", stem), f"cache: {damage}; computing {what} again")
            modes = compute()
            if held is not False:  # a live holder that outlasted the wait stores its own
                _store(model, stem, free, wanted, modes)
        finally:
            if held:
                _release(lock)
        return modes


def _stem(model: SolidModel, prefix: str, key: str) -> Path:
    """The cache entry's path without suffix: a hash of M, K and `key`."""
    return cache_dir() / f"{prefix}-{model.kind}-{model.ndof}-{matrix_key(model, key)}"


def matrix_key(model: SolidModel, key: str = "") -> str:
    """The hash of M, K (and `key`) that names the solid's mode-cache entries."""
    return sparse_digest((model.M, model.K), key)[:20]


def _from_cache(model: SolidModel, stem: Path, free, wanted, mmap: bool) -> tuple[Modes | None, str | None]:
    """(the solid's own modes from the cache files at `stem`, None), or (None, what is wrong
    with them) for a damaged entry, or (None, None) without one."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    if not (omega_path.exists() and shapes_path.exists()):
        return None, None
    for path in (omega_path, shapes_path):
        damage = verify(path)
        if damage:
            return None, damage
    try:
        omega = np.load(omega_path)
        shapes = np.load(shapes_path, mmap_mode="r" if mmap else None)
    except (OSError, ValueError, EOFError) as e:  # matches its record, yet unreadable: written so
        return None, f"{shapes_path.name} cannot be read ({type(e).__name__})"
    if shapes.shape != (model.ndof, len(omega)):
        return None, f"{shapes_path.name} holds {shapes.shape} shapes, not ({model.ndof}, {len(omega)})"
    touch(omega_path, shapes_path)  # recently used: pruned last
    if free is not None:
        record = _record_path(stem)
        damage = verify(record) if record.exists() else None
        if damage:
            note(("rebuilt", record), f"cache: {damage}; writing it again")
        if damage or not record.exists():  # lost or damaged on its own: written again from this solid
            try:
                _write_record(stem, free, omega, model.ndof, wanted)
            except OSError as e:
                unwritable(stem.parent, e)
        else:
            touch(record)
    return Modes(omega, shapes, "cache"), None


def _store(model: SolidModel, stem: Path, free, wanted, modes: Modes) -> None:
    """Computed modes into the cache (each file atomically, synced, then its check record), with
    their scale-free record; a note and nothing else if the cache cannot be written."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    try:
        write_checked(shapes_path, modes.shapes)
        write_checked(omega_path, modes.omega)
        kept = [omega_path, shapes_path]
        if free is not None:
            kept.append(_write_record(stem, free, modes.omega, model.ndof, wanted))
        prune_cache(keep=kept)
    except OSError as e:
        unwritable(stem.parent, e)


# ---------------------------------------------------------------- checked cache files
#
# Every cache file (a set's frequencies and shapes, its scale-free record, an assembled plate)
# has a check record beside it, FILE.sum: the file's byte size and CRC-32, written once the file
# is synced and renamed into place (`guard.writing.atomic_path`), and synced itself. A file is
# used only when its record is there and matches it; otherwise its entry counts as damaged and is
# built again. The size catches truncation; the CRC catches zero-filled blocks and flipped
# bytes (every burst of up to 32 bits, other damage but for 1 in 2^32). The CRC of a file is
# computed once per process: a file checked before, with the same device, inode, size and
# modification time, is not read again (`_CHECKED`).

CHECK_SUFFIX = ".sum"
CHECK_FORMAT = 1

_CHECKED: dict = {}  # path -> (device, inode, size, mtime_ns, crc) of a file that matched its record
_NOTED: set = set()


class CacheNote(UserWarning):
    """A note about granel's disk cache: an entry damaged and built again, a cache that cannot be
    written, a wait for another process's computation."""


def note(key, message: str) -> None:
    """`message` as a warning (one line on the command line), once per process for `key`."""
    import warnings

    if key in _NOTED:
        return
    _NOTED.add(key)
    warnings.warn(message, CacheNote, stacklevel=3)


def unwritable(folder: Path, e: BaseException) -> None:
    """Note, once per folder, that the cache cannot be written there, and why."""
    from ..guard.exits import FileError

    if folder.exists() and not folder.is_dir():
        why = "it is a file, not a folder"
    elif isinstance(e, FileError):
        why = str(e)
    else:
        why = getattr(e, "strerror", None) or str(e)
    note(("unwritable", str(folder)), f"cache: {folder} cannot be written ({why}); computing without the cache")


def check_path(path: Path) -> Path:
    return path.with_name(path.name + CHECK_SUFFIX)


def verify(path: Path) -> str | None:
    """What is wrong with the cache file at `path` (one line naming it), or None: it matches its
    check record."""
    import json
    import os

    try:
        st = os.stat(path)
    except OSError as e:
        return f"{path.name} cannot be read ({e.strerror or e})"
    try:
        record = json.loads(check_path(path).read_text())
        size, crc = int(record["size"]), int(record["crc32"])
    except FileNotFoundError:
        return f"{path.name} has no check record"
    except (OSError, ValueError, KeyError, TypeError):
        return f"{path.name}: its check record cannot be read"
    if st.st_size != size:
        return f"{path.name} holds {st.st_size} bytes, its record {size}"
    known = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, crc)
    if _CHECKED.get(str(path)) == known:
        return None
    try:
        _, got = file_crc32(path)
    except OSError as e:
        return f"{path.name} cannot be read ({e.strerror or e})"
    if got != crc:
        return f"{path.name}: its checksum differs from its record (damaged content)"
    _CHECKED[str(path)] = known
    return None


def touch(*paths) -> None:
    """Touch cache files that were used (pruning removes the least recently used first),
    keeping their memo of a passed check (the touch changes their modification time)."""
    import os

    for p in paths:
        for f in (p, check_path(p)):
            try:
                os.utime(f)
            except OSError:
                continue
        known = _CHECKED.get(str(p))
        if known is not None:
            try:
                st = os.stat(p)
            except OSError:
                continue
            if known[:3] == (st.st_dev, st.st_ino, st.st_size):
                _CHECKED[str(p)] = (*known[:3], st.st_mtime_ns, known[4])


def _write_npy(path, array) -> None:
    """np.save `array` (np.savez for a dict of arrays) to the file at `path`."""
    with open(path, "wb") as fh:
        if isinstance(array, dict):
            np.savez(fh, **array)
        else:
            np.save(fh, array)


def write_checked(path: Path, array) -> Path:
    """`array` (or a dict of arrays) to the cache file `path`: written to a temporary, synced
    and renamed (`guard.writing.atomic_path`; a full disk raises FileError), then its check
    record (size and CRC-32 of what was written), synced too. Raises OSError when the cache
    cannot be written."""
    import json
    import os

    from ..guard.owners import process_token
    from ..guard.writing import atomic_path, write_text

    with atomic_path(path) as tmp:
        _write_npy(tmp, array)
        size, crc = file_crc32(tmp)
    write_text(check_path(path), json.dumps({"format": CHECK_FORMAT, "file": path.name, "size": size, "crc32": crc,
                                              "by": process_token()}) + "\n")
    try:
        st = os.stat(path)
        _CHECKED[str(path)] = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, crc)
    except OSError:
        pass
    return path


def discard(paths, damage: str, busy: Path | None = None) -> None:
    """Remove a damaged cache entry (its files and their check records) with a note, unless
    `busy` (its lock) exists: its holder may be writing it now."""
    if busy is not None and busy.exists():
        return
    for p in paths:
        _unlink(p)
        _unlink(check_path(p))
    note(("removed", str(paths[0])), f"cache: {damage}; removed")


# ---------------------------------------------------------------- one computation at a time
#
# Workers of a sweep or a design study that meet the same new solid at once would each solve it:
# the first takes a lock file beside the cache entry, naming itself by `guard.owners.process_token`
# (host, pid and the process's start time), and the others wait for its modes. A lock whose holder
# is dead (its process gone on this host, or its pid now another process's) is taken over at once;
# a lock of another host when older than LOCK_WAIT_S. A wait says once what it waits for, and ends
# at LOCK_WAIT_S after the lock was taken: the waiter then computes the modes itself (without
# storing them: the live holder will). LOCK_WAIT_S is the longest a dense solve at DENSE_LIMIT DOFs
# is given (docs/performance.md, "One solve per new solid"); a wrong guess costs one extra solve,
# never a wrong result.

LOCK_WAIT_S = 600.0
LOCK_WRITE_S = 10.0  # an unreadable lock younger than this may be being written
LOCK_POLL_S = 0.25


@dataclass
class _Holder:
    """What a lock file says about its holder."""

    text: str
    age: float  # seconds since the lock file was written (its modification time)
    token: str | None = None  # None: unreadable (being written, or left half-written)
    host: str = "?"
    pid: int = 0
    since: float = 0.0  # when the lock was taken (the holder's clock)
    what: str = ""


def _lock_text(what: str) -> str:
    import json
    import os
    import socket
    import time

    from ..guard.owners import process_token

    return json.dumps({"token": process_token(), "host": socket.gethostname(), "pid": os.getpid(),
                       "since": time.time(), "what": what}) + "\n"


def _holder(lock: Path) -> _Holder | None:
    """The lock's holder, or None when there is no lock (or it cannot be read)."""
    import json
    import time

    try:
        age = time.time() - lock.stat().st_mtime
        text = lock.read_text()
    except (OSError, UnicodeDecodeError):
        return None
    try:
        d = json.loads(text)
        return _Holder(text, age, str(d["token"]), str(d["host"]), int(d["pid"]), float(d["since"]), str(d["what"]))
    except (ValueError, KeyError, TypeError):
        return _Holder(text, age)


def _stale(holder: _Holder) -> bool:
    """The lock's holder is gone: its token is dead (`guard.owners.token_state`), the lock is
    unreadable and older than LOCK_WRITE_S, or it is another host's and older than LOCK_WAIT_S."""
    from ..guard.owners import token_state

    if holder.token is None:
        return holder.age > LOCK_WRITE_S
    state = token_state(holder.token)
    return state == "dead" or (state == "elsewhere" and holder.age > LOCK_WAIT_S)


def _acquire(lock: Path, what: str = "modes") -> bool | None:
    """True: this process holds `lock`; False: another holder has it; None: no lock can be taken
    (an unwritable cache, noted), and the caller computes without one. A stale lock is taken
    over."""
    import os

    for _ in range(3):
        try:
            lock.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            if not lock.parent.is_dir():
                unwritable(lock.parent, NotADirectoryError())
                return None
            holder = _holder(lock)
            if holder is not None and _stale(holder):
                if not _take_over(lock, holder):
                    note(("lock", str(lock)), f"cache: the stale lock {lock} cannot be removed; computing {what} "
                          "without it")
                    return None
                continue
            return False
        except OSError as e:
            unwritable(lock.parent, e)
            return None
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(_lock_text(what))
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as e:  # a full disk: no lock, no cache
            _unlink(lock)
            unwritable(lock.parent, e)
            return None
        return True
    return False


def _take_over(lock: Path, holder: _Holder) -> bool:
    """Remove a stale lock if it still says what it said when judged stale; False if it cannot
    be removed."""
    try:
        if lock.read_text() == holder.text:
            lock.unlink()
    except (FileNotFoundError, UnicodeDecodeError):
        pass  # released or replaced meanwhile: look again
    except OSError:
        return False
    return True


def _wait_for(lock: Path, what: str = "modes") -> bool:
    """Wait until `lock` is released or stale (True: look again), or until LOCK_WAIT_S after
    it was taken (False: compute without it). Says once what it waits for, and for whom."""
    import time

    from ..guard.owners import token_state

    start = time.time()
    noted = False
    while True:
        holder = _holder(lock)
        if holder is None:
            if not lock.exists():
                return True
            note(("lock", str(lock)), f"cache: the lock {lock} cannot be read; computing {what} without it")
            return False
        if _stale(holder):
            return True
        since = holder.since if holder.token is not None and holder.since < start else start
        until = since + LOCK_WAIT_S
        now = time.time()
        if not noted and holder.token is not None:
            noted = True
            where = "this host" if token_state(holder.token) == "alive" else f"host {holder.host}"
            clock = lambda t: time.strftime("%H:%M:%S", time.localtime(t))  # noqa: E731
            if now >= until:
                note(("outlasted", str(lock)), f"cache: process {holder.pid} on {where} has been computing {what} "
                      f"since {clock(holder.since)}, longer than {LOCK_WAIT_S:.0f} s; computing them here too")
                return False
            note(("waiting", str(lock), holder.token), f"cache: waiting for {what} ({lock.stem}), which process "
                  f"{holder.pid} on {where} has been computing since {clock(holder.since)}; "
                  f"at most until {clock(until)}")
        if now >= until:
            return False
        time.sleep(LOCK_POLL_S)


def _release(lock: Path) -> None:
    """Remove `lock` if this process holds it."""
    from ..guard.owners import process_token

    holder = _holder(lock)
    if holder is not None and holder.token == process_token():
        _unlink(lock)


# ---------------------------------------------------------------- modes of a proportional solid
#
# For one mesh, clamping, rigid layers and Poisson ratio, the plane-stress plate's K is E h times
# a fixed matrix and its M rho h times another (plate.plane_stress_forms: K = h D(E, nu), D
# proportional to E at a fixed nu; M = rho h N'N; the rigid layers' T and the clamps are
# geometric), and the beam's K is E I and its M rho A times fixed matrices (beam.build_beam: it
# has bending DOFs only, so its thickness and width scale both exactly). If K = a K0 and M = b M0,
# K phi = w^2 M phi has the shapes of (K0, M0), w^2 = (a / b) w0^2, and the mass-normalised shapes
# are phi0 / sqrt(b). The check is on the matrices themselves, not on the parameters: each cached
# set keeps K0 / tr K0 and M0 / tr M0 (a "scale-free record"), and a solid reuses it only when its
# own K / tr K and M / tr M agree with them within SCALE_TOL of their largest entry (entry by
# entry, a stored entry missing on one side counting as zero: a sparse product drops the entries
# that cancel to exactly zero, so the sparsity itself may differ at round-off); a changed Poisson
# ratio, mesh, clamping or any term that does not scale (a spring of fixed stiffness) fails that
# and the modes are computed.

SCALE_TOL = 1e-12  # the largest difference of the normalised matrices, relative to their largest entry


@dataclass
class _ScaleFree:
    k: sp.csr_matrix  # K / tr K
    m: sp.csr_matrix  # M / tr M
    k_trace: float
    m_trace: float


def _scale_free(model: SolidModel) -> _ScaleFree | None:
    """The solid's matrices divided by their traces; None if a trace is not positive (no
    proportional reuse then)."""
    parts = []
    for A in (model.K, model.M):
        A = A.tocsr()
        trace = float(A.diagonal().sum())
        if not (np.isfinite(trace) and trace > 0):
            return None
        parts.append((A * (1.0 / trace), trace))
    (k, tk), (m, tm) = parts
    return _ScaleFree(k, m, tk, tm)


def _record_path(stem: Path) -> Path:
    return stem.with_name(f"{stem.name}.scale.npz")


def _write_record(stem: Path, free: _ScaleFree, omega: np.ndarray, ndof: int, wanted) -> Path:
    """Store the scale-free record of the modes at `stem` (a checked cache file): the normalised
    matrices, their traces and how far the set is complete (`complete_to` [rad/s]: every mode up
    to it is in the set; infinite for all modes). Raises OSError when it cannot be written."""
    w_cut, top = wanted
    if len(omega) >= ndof:
        complete = np.inf
    elif top is None or len(omega) < top:
        complete = w_cut
    else:  # the count bound cut the set: complete up to its highest mode
        complete = float(omega[-1]) if len(omega) else 0.0
    arrays = dict(traces=np.array([free.k_trace, free.m_trace]), complete_to=np.array(complete))
    for name, A in (("k", free.k), ("m", free.m)):
        arrays.update({f"{name}_data": A.data, f"{name}_indices": A.indices, f"{name}_indptr": A.indptr})
    return write_checked(_record_path(stem), arrays)


def _same_up_to_scale(a: sp.csr_matrix, z, name: str) -> bool:
    """Whether the normalised matrix `a` equals the record's (`z`, `name`) within SCALE_TOL."""
    b = sp.csr_matrix((z[f"{name}_data"], z[f"{name}_indices"], z[f"{name}_indptr"]), shape=a.shape)
    scale = float(abs(b).max()) if b.nnz else 0.0
    return scale > 0 and float(abs(a - b).max()) <= SCALE_TOL * scale


def scaled_modes(model: SolidModel, prefix: str, free: _ScaleFree, wanted, mmap: bool, exclude: Path | None = None
                 ) -> Modes | None:
    """The modes of `model` from a cached set (`prefix`: "modes" or "modes-below") of a solid with
    K0 = K / a and M0 = M / b, or None. a and b are the ratios of the traces; omega = sqrt(a / b)
    omega0 and the shapes phi0 / sqrt(b), which stay memory-mapped (`ScaledShapes`) when `mmap`.
    A set of modes below a cut-off serves when it reaches the wanted cut-off (in its own
    frequencies) or holds the wanted count below it. Only checked files serve (`verify`); a
    damaged set is removed. `exclude`: the stem of the solid's own entry, not a base. Nothing new
    is written."""
    w_cut, top = wanted
    for record in sorted(cache_dir().glob(f"{prefix}-{model.kind}-{model.ndof}-*.scale.npz")):
        stem = record.with_name(record.name.removesuffix(".scale.npz"))
        omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
        if stem == exclude or not (omega_path.exists() and shapes_path.exists()):
            continue  # a half-pruned entry: not a base
        files = [omega_path, shapes_path, record]
        damage = verify(record)  # the small record first: the shapes are read only for a match
        if damage:  # never a base; removed unless its lock says it is being written
            discard(files, damage, busy=stem.with_suffix(".lock"))
            continue
        try:
            with np.load(record) as z:
                if not (_same_up_to_scale(free.k, z, "k") and _same_up_to_scale(free.m, z, "m")):
                    continue
                k_trace, m_trace = (float(t) for t in z["traces"])
                complete = float(z["complete_to"])
            damage = verify(omega_path) or verify(shapes_path)
            if damage:
                discard(files, damage, busy=stem.with_suffix(".lock"))
                continue
            omega0 = np.load(omega_path)
            shapes0 = np.load(shapes_path, mmap_mode="r" if mmap else None)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            continue  # removed meanwhile, or unreadable though it matches its record: not a base
        if shapes0.shape != (model.ndof, len(omega0)) or not (k_trace > 0 and m_trace > 0):
            continue
        a, b = free.k_trace / k_trace, free.m_trace / m_trace
        c = np.sqrt(a / b)
        w0 = w_cut / c  # the wanted cut-off in the base's frequencies
        if w0 <= complete:
            n = int(np.count_nonzero(omega0 <= w0))
            n = n if top is None else min(n, top)
        elif top is not None and np.count_nonzero(omega0 <= complete) >= top:
            n = top
        else:
            continue  # the base stops short of the wanted cut-off
        touch(omega_path, shapes_path, record)
        omega = omega0[:n] * c
        factor = 1.0 / np.sqrt(b)
        part = shapes0 if n == shapes0.shape[1] else shapes0[:, :n]
        if factor == 1.0:
            shapes = part
        elif mmap:
            shapes = ScaledShapes(part, factor)
        else:
            shapes = np.asarray(part) * factor
        return Modes(omega, shapes, "scaled")
    return None


class ScaledShapes(np.lib.mixins.NDArrayOperatorsMixin):
    """A (memory-mapped) matrix of mode shapes times a scalar, the product taken on what is read:
    `shapes[rows]`, `shapes[:, :n]` read only those entries; `np.asarray(shapes)` and products
    read it all. Stands in for the mass-normalised shapes of a solid proportional to a cached one."""

    def __init__(self, base, factor: float):
        self.base, self.factor = base, float(factor)

    shape = property(lambda self: self.base.shape)
    ndim = property(lambda self: self.base.ndim)
    size = property(lambda self: self.base.size)
    dtype = property(lambda self: self.base.dtype)
    nbytes = property(lambda self: self.base.nbytes)

    def __len__(self) -> int:
        return len(self.base)

    def __repr__(self) -> str:
        return f"ScaledShapes(shape={self.shape}, factor={self.factor:.17g})"

    def __getitem__(self, index):
        return np.asarray(self.base[index]) * self.factor

    def __array__(self, dtype=None, copy=None):
        out = np.asarray(self.base) * self.factor
        return out if dtype is None else out.astype(dtype, copy=False)

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if any(isinstance(x, ScaledShapes) for x in kwargs.get("out", ())):
            return NotImplemented
        inputs = tuple(np.asarray(x) if isinstance(x, ScaledShapes) else x for x in inputs)
        return getattr(ufunc, method)(*inputs, **kwargs)

    def __matmul__(self, other):
        return (self.base @ other) * self.factor

    def __rmatmul__(self, other):
        return (other @ self.base) * self.factor

    @property
    def T(self) -> np.ndarray:
        return np.asarray(self).T

    def copy(self) -> np.ndarray:
        return np.asarray(self)

    def astype(self, dtype, copy=True) -> np.ndarray:
        return np.asarray(self).astype(dtype)
