"""Atomic, synced writes: a file appears whole or not at all, and survives a crash once written.

Every file granel writes goes through `atomic_path`: the data goes to a temporary file in the
same folder (named `.granel-HASH-TOKEN.tmp`: short whatever the target's name, and naming the
writing process by `owners.process_token`), which is flushed to disk, checked against the target
(never over a read-only or special file), renamed over it, and the folder synced. A full disk, or
any other refusal of the system (a file-size limit, too many open files), removes the temporary
and raises `FileError` (exit 4) naming the file; temporaries of processes that died are removed
by the next write in their folder (`remove_stale_temporaries`). A temporary file is writable by
its writer whatever the umask; the file it becomes gets the umask's permissions.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .exits import FILES, FileError, GranelError, describe, is_no_space
from .owners import process_token, token_state

PREFIX, SUFFIX = ".granel-", ".tmp"
STAGE = ".granel-stage-"


def _digest(name: str) -> str:
    return hashlib.sha1(name.encode(errors="surrogateescape")).hexdigest()[:10]


def target_of(path: str | Path) -> Path:
    """The file a write to `path` lands in: a symbolic link is followed (the link stays)."""
    path = Path(path)
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def replace_refusal(path: Path) -> str | None:
    """Why an existing `path` must not be replaced by a write, or None: a folder, a special file
    (device, FIFO, socket), or a file its owner made read-only (mode bits, whoever runs)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        return f"cannot be inspected ({e.strerror or e})"
    if stat.S_ISDIR(st.st_mode):
        return "is a folder"
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file (a device, a FIFO or a socket)"
    if not st.st_mode & 0o222:
        return "is read-only (its owner made it so): granel never replaces it"
    return None


def storable(text: str) -> str:
    """`text` as a UTF-8 file can hold it: a file name that is not UTF-8, held by Python as lone
    surrogates, keeps its undecodable bytes as backslash escapes (the text `\\xff`)."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def fsync_path(path: str | Path) -> None:
    """Flush a file's (or a folder's) data to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot sync a folder: the data is still written
        pass
    finally:
        os.close(fd)


def no_space(path: Path, e: BaseException) -> FileError:
    """The one-line error of a full disk while writing `path`."""
    try:
        free = shutil.disk_usage(path.parent if not path.is_dir() else path).free
        extra = f" ({free / 2**20:.1f} MiB free)"
    except OSError:
        extra = ""
    return FileError(f"{path}: no space left on the device{extra}; nothing was written there", FILES)


def not_written(path: Path, e: OSError) -> FileError:
    """The one-line error of a write to `path` that the system refused (the file too large for
    the process's limit, too many open files, ...), naming the file and the limit."""
    return FileError(f"{path}: {describe(e)}; nothing was written there", FILES)


@contextmanager
def atomic_path(path: str | Path, check: bool = True, keep_suffix: bool = False):
    """Yield a temporary path beside `path`; when the block ends without error, sync it and
    rename it over `path` (refused, with FileError, where `replace_refusal` objects and `check`
    is set); on any error, or a stop, remove it. A full disk, and any other OSError of the
    block, becomes FileError (exit 4) naming `path`.
    `keep_suffix`: the temporary ends in the target's suffix too (for writers that pick the
    format from the name)."""
    target = target_of(path)
    folder = target.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(folder)
        fd, tmp = tempfile.mkstemp(prefix=f"{PREFIX}{_digest(target.name)}-{process_token()}-",
                                   suffix=SUFFIX + (target.suffix if keep_suffix else ""), dir=folder)
        try:
            os.fchmod(fd, 0o600)  # writable by its writer whatever the umask (the file gets the umask's in the end)
        finally:
            os.close(fd)
    except OSError as e:
        if is_no_space(e):
            raise no_space(target, e) from None
        raise not_written(target, e) from None
    try:
        yield tmp
        _set_mode(tmp, target)
        fsync_path(tmp)
        why = replace_refusal(target) if check else None
        if why:
            raise FileError(f"{path}: {why}", FILES)
        os.replace(tmp, target)
        fsync_path(folder)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, Exception) and is_no_space(e):
            raise no_space(target, e) from None
        if isinstance(e, OSError) and not isinstance(e, GranelError):
            raise not_written(target, e) from None
        raise


def _set_mode(tmp: str, target: Path) -> None:
    """The temporary's permissions as the file would have had: the replaced file's, else the
    default for a new file (0666 less the umask), not mkstemp's private 0600."""
    try:
        mode = os.stat(target).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    try:
        os.chmod(tmp, mode)
    except OSError:
        pass


def write_text(path: str | Path, text: str, check: bool = True) -> Path:
    """`text` (UTF-8) to `path`, atomically and synced."""
    with atomic_path(path, check) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
    return Path(path)


def write_bytes(path: str | Path, data: bytes, check: bool = True) -> Path:
    with atomic_path(path, check) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
    return Path(path)


def _token_of(name: str, prefix: str) -> str | None:
    """The process token in a temporary's or a staging folder's name, or None."""
    if not name.startswith(prefix):
        return None
    rest = name[len(prefix):]
    if prefix == PREFIX:
        if SUFFIX not in rest:
            return None
        parts = rest[: rest.index(SUFFIX)].split("-")
        return "-".join(parts[1:4]) if len(parts) >= 5 else None
    parts = rest.split("-")
    return "-".join(parts[:3]) if len(parts) >= 3 else None


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Remove the temporary files and staging folders that granel processes which no longer run
    left in `folder` (a killed write, whatever killed it); those of live processes, and of other
    hosts sharing the folder, are kept. Returns the removed paths."""
    folder = Path(folder)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        prefix = STAGE if name.startswith(STAGE) else PREFIX if name.startswith(PREFIX) else None
        token = _token_of(name, prefix) if prefix else None
        if token is None or token_state(token) != "dead":
            continue
        try:
            if prefix == STAGE and entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            elif prefix == PREFIX and entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
            else:
                continue
            removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def staging_folder(parent: str | Path) -> Path:
    """A new staging folder in `parent` named after this process (removed by the next write in
    `parent` once this process is gone, whatever ended it)."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(parent)
    return Path(tempfile.mkdtemp(prefix=f"{STAGE}{process_token()}-", dir=parent))


def save_figure(fig, path: str | Path, close: bool = True, **options) -> Path:
    """A matplotlib figure to `path` (the format from its suffix), atomically, with granel's mark
    in its metadata (`owners.picture_metadata`); the figure is closed unless `close` is false."""
    from .owners import MARK, picture_metadata

    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    extra = {}
    meta = picture_metadata(fmt)
    if meta:
        extra["metadata"] = meta
    elif fmt in ("jpg", "jpeg"):
        extra["pil_kwargs"] = {"comment": MARK.encode()}
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, **extra, **options)
    finally:
        if close:
            import matplotlib.pyplot as plt

            plt.close(fig)
    return path
