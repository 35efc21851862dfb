"""One computation of a solid's modes at a time, across processes: a lock file beside the cache
entry names its holder, the others wait for it within a bound (LOCK_WAIT_S), and a lock whose
holder is gone is taken over."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .cache_files import _unlink, note, unwritable


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
