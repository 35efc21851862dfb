"""The exit codes of every command, and the errors that carry them.

| code | meaning |
| 0 | done |
| 1 | an internal error (a bug): one line, the traceback in a file named there |
| 2 | invalid input or usage, found before any computation |
| 3 | a numerical or physical stop during the run (or, for studies, no case succeeded) |
| 4 | a file that cannot be read or written (no space left included) |
| 130 | interrupted (Ctrl-C) |
| 143 | terminated (SIGTERM) |

An error type carries its code as `code` (a class attribute, or set per instance); `exit_code`
reads it for any exception, so that the command line maps every failure in one place.
"""

from __future__ import annotations

import errno

try:  # imported now: with no descriptor left, importing it later fails too
    import resource
except ImportError:  # pragma: no cover - not on Windows
    resource = None

OK, INTERNAL, USAGE, STOPPED, FILES, INTERRUPTED, TERMINATED = 0, 1, 2, 3, 4, 130, 143


class GranelError(Exception):
    """An error with its exit code; the message is one line naming the field, option or file."""

    code = USAGE

    def __init__(self, message: str, code: int | None = None):
        super().__init__(message)
        if code is not None:
            self.code = code


class InputError(GranelError, ValueError):
    """Invalid input found before any computation (exit 2)."""

    code = USAGE


class FileError(GranelError, OSError):
    """A file that cannot be read or written (exit 4)."""

    code = FILES


class NotWritten(GranelError):
    """An output that could not be written (exit 4): `what` names it ("the result", "the
    figure"), `path` is where, `cause` the OSError. Not itself an OSError, so that an `except
    OSError` around a study's other writes does not take it for theirs."""

    code = FILES

    def __init__(self, what: str, path, cause: OSError):
        super().__init__(f"{path}: cannot write {what} ({cause})")
        self.what, self.path, self.cause = what, path, cause


def option_value(option: str, text, parse):
    """`parse(text)`, its ValueError an InputError naming the option and the text given (exit 2)."""
    try:
        return parse(text)
    except ValueError as e:
        raise InputError(f"{option} {text}: {e}") from None


class ResourceError(InputError):
    """A request whose estimated memory, disk or size exceeds what the machine has or a limit
    (exit 2), refused before anything is spent."""


class Terminated(BaseException):
    """SIGTERM reached the process (raised by `signals`); like KeyboardInterrupt, not an Exception,
    so that no `except Exception` swallows it."""


NO_SPACE = (errno.ENOSPC, errno.EDQUOT)


def is_no_space(e: BaseException) -> bool:
    """A write refused because the disk (or the quota) is full, whatever library raised it
    (h5py and HDF5 report it in the message, without errno)."""
    if isinstance(e, OSError) and e.errno in NO_SPACE:
        return True
    text = str(e).lower()
    return "no space left" in text or "disk quota exceeded" in text


def _size(n: int) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.4g} {unit}"
    return f"{n} bytes"


def _limit(kind: str):
    """This process's soft limit `kind` (a `resource.RLIMIT_*` name), or None where unknown or unlimited."""
    try:
        soft = resource.getrlimit(getattr(resource, kind))[0]
    except (AttributeError, OSError, ValueError):
        return None
    return None if soft == getattr(resource, "RLIM_INFINITY", -1) else soft


def describe(e: OSError) -> str:
    """An OSError's reason, and for a limit of the process (the size of a file, the open files)
    the limit and the setting that gives it."""
    reason = e.strerror or str(e)
    if e.errno == errno.EFBIG:
        limit = _limit("RLIMIT_FSIZE")
        return reason + (f" (the file-size limit of this process is {_size(limit)}: ulimit -f)" if limit is not None
                         else " (beyond the file-size limit of this process or of the file system)")
    if e.errno == errno.EMFILE:
        limit = _limit("RLIMIT_NOFILE")
        return reason + (f" (the limit of open files of this process is {limit}: ulimit -n)" if limit is not None
                         else " (the limit of open files of this process: ulimit -n)")
    if e.errno == errno.ENFILE:
        return reason + " (the system's limit of open files)"
    if e.errno in (errno.EACCES, errno.EPERM):
        mask = _umask()
        if mask is not None and mask & 0o300:
            return reason + f" (the umask {mask:03o} makes the folders and files this process creates closed to itself)"
    return reason


def _umask() -> int | None:
    """This process's umask (Linux's /proc, else set and restored), or None where unknown."""
    try:
        with open("/proc/self/status", "rb") as fh:
            for line in fh:
                if line.startswith(b"Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        mask = os.umask(0o022)
        os.umask(mask)
        return mask
    except OSError:
        return None


# failures of the numerics on values beyond what float64 models hold (a solid 1e-300 m wide, a
# density of 1e300): a numerical stop (exit 3), reported with the traceback's file, not a bug's
NUMERICAL = ("LinAlgError", "ArpackError", "ArpackNoConvergence", "ZeroDivisionError", "OverflowError",
             "FloatingPointError")


def is_numerical(e: BaseException) -> bool:
    return any(k.__name__ in NUMERICAL for k in type(e).__mro__)


def exit_code(e: BaseException) -> int:
    """The exit code of any exception: its own `code`, else by kind."""
    if isinstance(e, KeyboardInterrupt):
        return INTERRUPTED
    if isinstance(e, Terminated):
        return TERMINATED
    code = getattr(e, "code", None)
    if isinstance(code, int) and not isinstance(code, bool) and code in (USAGE, STOPPED, FILES):
        return code
    if isinstance(e, OSError) or is_no_space(e):
        return FILES
    if isinstance(e, MemoryError) or is_numerical(e):
        return STOPPED
    return INTERNAL
