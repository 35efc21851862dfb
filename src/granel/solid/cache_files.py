"""granel's cache folder and its checked files: where the cache lives (`cache_dir`), its size bound
and least-recently-used pruning (`prune_cache`), each file's check record (size and CRC-32)
written with it and verified before it is used, and the notes (`CacheNote`) about the cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..guard.fingerprints import file_crc32


# ---------------------------------------------------------------- the cache folder


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

