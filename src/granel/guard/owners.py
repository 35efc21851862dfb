"""Who a file or a lock belongs to.

- A process is named by a token `HOST-PID-START` (a hash of the host name, the pid and the
  process's start time in clock ticks since boot): a pid that the system reused for another
  process no longer matches, so a dead holder is recognised even then.
- A file granel wrote carries granel's mark (`MARK`): in a NetCDF file's attributes, in a
  picture's or a movie's metadata, in the first line of a text file. `is_granel_file` looks for
  it, so that no command replaces a file it did not write.
- A folder granel made carries a stamp file (`STAMP`) naming the command that owns it.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
from pathlib import Path

MARK = "written by granel"
STAMP = ".granel-folder.json"


def _host() -> str:
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]


def start_ticks(pid: int) -> int | None:
    """The process's start time in clock ticks since boot (Linux /proc), or None where unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            stat = fh.read().decode(errors="replace")
    except OSError:
        return None
    try:  # the command name (field 2) is in parentheses and may hold spaces
        return int(stat.rsplit(")", 1)[1].split()[19])
    except (IndexError, ValueError):
        return None


def process_token(pid: int | None = None) -> str:
    """This process's token HOST-PID-START (START 0 where the start time is unknown)."""
    pid = os.getpid() if pid is None else pid
    return f"{_host()}-{pid}-{start_ticks(pid) or 0}"


def token_state(token: str) -> str:
    """"alive", "dead" or "elsewhere" (another host: cannot be told from here) for a token of
    `process_token`; a malformed token is "dead"."""
    parts = token.split("-")
    if len(parts) != 3 or not parts[1].isdigit() or not parts[2].isdigit():
        return "dead"
    host, pid, start = parts[0], int(parts[1]), int(parts[2])
    if host != _host():
        return "elsewhere"
    if not _pid_exists(pid):
        return "dead"
    now = start_ticks(pid)
    if start and now is not None and now != start:
        return "dead"  # the pid now belongs to another process
    return "alive"


def _pid_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OverflowError:
        return False
    return True


# ---------------------------------------------------------------- marks on files

HEAD, TAIL = 1 << 16, 1 << 20
# text files carry the mark on their first line (a user's notes that quote it further down are theirs)
TEXT_SUFFIXES = (".md", ".toml", ".csv", ".txt", ".json", ".extxyz", ".xyz", ".pvd", ".xdmf", ".xmf")


def is_granel_file(path: Path) -> bool:
    """Whether the regular file at `path` carries granel's mark: a NetCDF file's `granel_version`
    attribute, a text file's first line, or (pictures, movies, checkpoints, VTU) the mark in its
    first 64 KiB or last MiB."""
    path = Path(path)
    if path.suffix == ".nc":
        return _netcdf_mark(path)
    mark = MARK.encode()
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(HEAD)
            if path.suffix.lower() == ".json":  # no comments in JSON: the mark is its first key
                return mark in head[:512]
            if path.suffix.lower() in TEXT_SUFFIXES:
                return mark in head.split(b"\n", 1)[0]
            tail = b""
            if size > HEAD:
                fh.seek(max(HEAD, size - TAIL))
                tail = fh.read(TAIL)
    except OSError:
        return False
    return any(m in head or m in tail for m in (mark, MARK.replace(" ", "_").encode()))


def _netcdf_mark(path: Path) -> bool:
    try:
        import h5py

        with h5py.File(path, "r") as f:
            return "granel_version" in f.attrs
    except Exception:  # noqa: BLE001 - not HDF5, truncated, unreadable: not recognisably granel's
        return False


def text_mark(comment: str = "#") -> str:
    """The first line of a text file granel writes (a TOML or CSV comment, a Markdown comment)."""
    from .. import __version__

    if comment == "<!--":
        return f"<!-- {MARK} {__version__} -->"
    return f"{comment} {MARK} {__version__}"


# the picture formats whose files carry the mark (so that a rerun may replace them)
PICTURE_FORMATS = ("png", "pdf", "svg", "eps", "ps", "jpg", "jpeg")


def picture_metadata(suffix: str) -> dict:
    """Matplotlib's savefig metadata that carries the mark, for the picture format `suffix`."""
    from .. import __version__

    s = suffix.lower().lstrip(".")
    if s == "png":
        return {"Software": f"{MARK} {__version__}"}
    if s in ("pdf", "svg", "eps", "ps"):
        return {"Creator": f"{MARK} {__version__}"}
    return {}


# ---------------------------------------------------------------- stamps on folders


def folder_stamp(folder: Path) -> dict | None:
    """The stamp of a folder granel made ({"kind": ..., "version": ...}), or None."""
    try:
        data = json.loads((Path(folder) / STAMP).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("kind"), str) else None
