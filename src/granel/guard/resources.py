"""Resources estimated before they are spent: a request whose memory exceeds what the machine
has (or the limit GRANEL_MAX_MEMORY) is refused with its estimate (exit 2), and an output whose
size exceeds the free disk is refused (exit 4), instead of a MemoryError, a swap storm or a
partial file after the computation."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from .exits import FILES, FileError, ResourceError

UNITS = {"": 1, "b": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


def parse_bytes(text: str) -> int | None:
    """'512M', '4G', '1e9' -> bytes; None if it does not read as a size."""
    t = str(text).strip().lower().removesuffix("ib").removesuffix("b")
    unit = t[-1:] if t[-1:] in UNITS else ""
    try:
        value = float(t[: len(t) - len(unit)] if unit else t) * UNITS[unit]
    except ValueError:
        return None
    return int(value) if value > 0 and value == value and value != float("inf") else None


def available_memory() -> tuple[int, str]:
    """(bytes a request may use, where that figure comes from): GRANEL_MAX_MEMORY if set, else
    the memory the kernel reports available (Linux MemAvailable), else the physical memory."""
    limit = os.environ.get("GRANEL_MAX_MEMORY", "").strip()
    if limit:
        b = parse_bytes(limit)
        if b is not None:
            return b, f"GRANEL_MAX_MEMORY = {limit}"
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024, "the memory available on this machine"
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "this machine's memory"
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 8 * 2**30, "an assumed 8 GiB"


def size(b: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if b >= scale:
            return f"{b / scale:.3g} {unit}"
    return f"{int(b)} B"


def check_memory(estimate: float, what: str, hint: str) -> None:
    """ResourceError (exit 2) naming `what`, its estimate, the limit and `hint`, if the estimate
    exceeds the memory this process may use."""
    have, source = available_memory()
    if estimate > have:
        raise ResourceError(f"{what} needs about {size(estimate)} of memory, more than {source} ({size(have)}); {hint}")


def check_disk(estimate: float, folder: Path, what: str) -> None:
    """FileError (exit 4) if the disk of `folder` (or its nearest existing parent) has less free
    space than `estimate` bytes."""
    folder = Path(folder).absolute()
    while not folder.exists() and folder.parent != folder:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    if estimate > free:
        raise FileError(f"{what} would take about {size(estimate)}, and {folder} has {size(free)} free: no space left "
                        "for it (free some space, write elsewhere, or store fewer outputs)", FILES)
