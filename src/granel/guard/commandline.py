"""The exit contract of every command, in one place: whatever a command raises ends as one line
on standard error and one of the documented exit codes (`exits`), never a traceback.

`GuardedGroup` is the click group of the `granel` command: it formats usage errors on one line
(with the replacement of a removed option), maps every exception through `exits.exit_code`, turns
Ctrl-C and SIGTERM into exits 130 and 143, writes the traceback of an internal error (a bug) to a
file it names, and shows Python warnings as one line each. Standard output and error never fail
on a character their encoding cannot hold (an ASCII locale): it is escaped (`console_streams`);
and text given on the command line is read as UTF-8 whatever the locale (`text_argument`)."""

from __future__ import annotations

import codecs
from contextlib import contextmanager
import os
import sys
import tempfile
import time
import traceback
import warnings

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

try:  # typer 0.2x carries its own copy of click
    from typer._click.exceptions import NoSuchOption, UsageError
except ImportError:  # pragma: no cover - older typer uses click itself
    from click.exceptions import NoSuchOption, UsageError

Exit, Abort = typer.Exit, typer.Abort

from .exits import (FILES, INTERNAL, INTERRUPTED, TERMINATED, USAGE, GranelError, NotWritten, Terminated, describe,
                    exit_code, is_no_space, is_numerical)
from .signals import stops_as_exceptions


def make_console(**options) -> Console:
    """A rich console (on standard output unless `stderr=True`) whatever the environment says of
    the terminal: a COLUMNS or LINES of 0, with which rich would print nothing, counts as unset."""
    for name, key in (("COLUMNS", "width"), ("LINES", "height")):
        value = os.environ.get(name, "").strip()
        if value.isdigit() and int(value) < 1:
            options.setdefault(key, 80 if key == "width" else 25)
    return Console(**options)


console = make_console(stderr=True, soft_wrap=True)

# options of earlier releases, by command: their replacement
REMOVED = {
    ("run", "--output-every"): "--set simulation.output_every=VALUE (e.g. --set simulation.output_every=1us)",
    ("run", "--fmax"): "--shock VALUE (a peak force in N, e.g. --shock 500) or --set excitations.0.fmax=VALUE",
    ("reciprocity", "--fmax"): "--shock VALUE (a peak force in N, e.g. --shock 500)",
}


def one_line(text: str) -> str:
    """A message on one line: its lines joined by '; ', runs of spaces collapsed."""
    parts = [" ".join(p.split()) for p in str(text).splitlines()]
    parts = [p for p in parts if p]
    out = parts[0] if parts else ""
    for p in parts[1:]:
        out += (" " if out.endswith(":") else "; ") + p
    return out


def error(message: str) -> None:
    console.print(f"[bold red]error:[/] {escape(one_line(message))}", emoji=False)  # "a:b:" stays as given


def note(message: str) -> None:
    console.print(f"[yellow]note:[/] {escape(one_line(message))}", emoji=False)


def _warning(message, category, filename, lineno, file=None, line=None):
    console.print(f"[yellow]warning:[/] {escape(one_line(str(message)))}", emoji=False)


ESCAPE = "granel-escape"


def _escape(e: UnicodeError):
    """The console's codec error handler: a character its encoding cannot hold is written as a
    \\uXXXX escape (as TOML and JSON strings write it), a byte of a name the locale could not
    decode (a lone surrogate) as the text \\xNN (as `guard.writing.storable` keeps it)."""
    if not isinstance(e, UnicodeEncodeError):
        raise e
    out = []
    for ch in e.object[e.start:e.end]:
        n = ord(ch)
        out.append(f"\\x{n - 0xDC00:02x}" if 0xDC80 <= n <= 0xDCFF else f"\\u{n:04x}" if n <= 0xFFFF else f"\\U{n:08x}")
    return "".join(out), e.end


codecs.register_error(ESCAPE, _escape)


def console_streams() -> None:
    """This process's standard output and error write what their encoding cannot hold escaped
    (`_escape`) instead of failing (the C locale's ASCII); streams another caller put in their
    place (a test's runner) are left as they are."""
    for stream, own in ((sys.stdout, sys.__stdout__), (sys.stderr, sys.__stderr__)):
        if stream is None or stream is not own or getattr(stream, "errors", ESCAPE) == ESCAPE:
            continue
        try:
            stream.reconfigure(errors=ESCAPE)
        except (AttributeError, ValueError, OSError):
            pass


def text_argument(value: str) -> str:
    """A text given on the command line (a name, a --set value) as the user typed it: where the
    locale is not UTF-8, Python holds the bytes it could not decode as lone surrogates, and those
    that form UTF-8 are decoded so (file names are left as they are: they name the bytes)."""
    if not isinstance(value, str) or not any("\udc80" <= ch <= "\udcff" for ch in value):
        return value
    try:
        return os.fsencode(value).decode("utf-8")
    except UnicodeError:
        return value


def print_table(rows, header=None, title=None, out=None, **options) -> None:
    """Rows (lists of strings) as a table on `out` (default standard output); without `header`,
    (label, value) rows."""
    from rich.table import Table

    t = Table(*(header or []), title=title, show_header=header is not None, **options)
    for row in rows:
        t.add_row(*row)
    (out or make_console()).print(t)


def progress_bar(label: str = "[bold]{task.description}", counted: bool = True, extra=(), remaining: bool = True,
                 **options):
    """A rich progress bar on standard error: `label`, the bar, done/total with `counted` (else a
    percentage), the `extra` columns, the time elapsed and, with `remaining`, the time left."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    done = TextColumn("{task.completed}/{task.total}") if counted else TextColumn("{task.percentage:>5.1f}%")
    return Progress(TextColumn(label), BarColumn(), done, *extra, TimeElapsedColumn(),
                    *([TimeRemainingColumn()] if remaining else []), console=console, **options)


def why_not_written(e: BaseException) -> str:
    """Why a write failed: an OSError's reason with the limit it met and the file it names."""
    if isinstance(e, GranelError) or not isinstance(e, OSError):
        return str(e)
    return describe(e) + (f": {e.filename}" if e.filename else "")


@contextmanager
def written(option: str, what: str):
    """A failed write of `what` (an OSError, or `NotWritten` from a study) ends the command with
    exit 4 naming `option` and the reason."""
    try:
        yield
    except NotWritten as e:
        raise GranelError(f"{option}: cannot write {e.what} ({why_not_written(e.cause)})", FILES) from None
    except OSError as e:
        raise GranelError(f"{option}: cannot write {what} ({why_not_written(e)})", FILES) from None


def _usage_message(e: UsageError) -> str:
    command = e.ctx.command.name if e.ctx is not None and e.ctx.command is not None else ""
    if isinstance(e, NoSuchOption):
        hint = REMOVED.get((command, e.option_name))
        if hint:
            return f"{e.option_name} was removed: use {hint}"
    text = e.format_message()
    where = f"granel {command}" if command and command != "granel" else "granel"
    return f"{where}: {text} (see {where} --help)"


def crash_report(e: BaseException) -> str:
    """Write the traceback of an internal error to a file; its path (or '' if none could be written)."""
    try:
        fd, path = tempfile.mkstemp(prefix=f"granel-crash-{time.strftime('%Y%m%d-%H%M%S')}-", suffix=".txt")
        with os.fdopen(fd, "w", errors="backslashreplace") as fh:
            fh.write(" ".join(sys.argv) + "\n\n")
            traceback.print_exception(type(e), e, e.__traceback__, file=fh)
        return path
    except OSError:
        return ""


def exit_for(e: BaseException) -> int:
    """Report `e` on one line and return its exit code."""
    code = exit_code(e)
    if code == INTERRUPTED:
        error("interrupted (Ctrl-C); finished outputs are kept, and a rerun continues a study")
    elif code == TERMINATED:
        error("terminated (SIGTERM); finished outputs are kept, and a rerun continues a study")
    elif code == INTERNAL:
        if os.environ.get("GRANEL_DEBUG"):
            raise e
        path = crash_report(e)
        error(f"internal error (a bug in granel, please report it): {type(e).__name__}: {one_line(str(e))[:300]}"
              + (f"; the traceback is in {path}" if path else ""))
    elif is_numerical(e):
        path = crash_report(e)
        error(f"a numerical failure ({type(e).__name__}: {one_line(str(e))[:200]}): the scenario's values are probably "
              "beyond what the models hold in double precision" + (f"; the traceback is in {path}" if path else ""))
    elif isinstance(e, MemoryError):
        error("out of memory: the request needs more memory than this machine could give (lower the outputs' size or "
              "the number of granules or modes)")
    elif isinstance(e, GranelError):
        error(str(e))
    elif is_no_space(e):
        name = getattr(e, "filename", None)
        error(f"{str(name) + ': ' if name else ''}no space left on the device; nothing was written there")
    elif isinstance(e, OSError):
        name = getattr(e, "filename", None)
        error(f"{str(name) + ': ' if name else ''}{describe(e)}")
    else:
        error(str(e))
    return code


class GuardedGroup(TyperGroup):
    """The `granel` group: every command ends with one line and a documented exit code."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except Exit:
            raise
        except UsageError as e:
            error(_usage_message(e))
            raise Exit(USAGE) from None
        except Abort:
            error("interrupted")
            raise Exit(INTERRUPTED) from None
        except (Exception, KeyboardInterrupt, Terminated) as e:  # noqa: BLE001 - the one place every failure ends
            raise Exit(exit_for(e)) from None

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        console_streams()
        with stops_as_exceptions(), warnings.catch_warnings():
            warnings.showwarning = _warning
            try:
                rv = super().main(args=args, prog_name=prog_name or "granel", complete_var=complete_var,
                                  standalone_mode=False, **extra)
                code = rv if isinstance(rv, int) and not isinstance(rv, bool) else 0
            except Exit as e:
                code = e.exit_code
            except UsageError as e:
                error(_usage_message(e))
                code = USAGE
            except Abort:
                error("interrupted")
                code = INTERRUPTED
            except BrokenPipeError:  # the reader of standard output went away (`granel scenarios | head -1`)
                sys.stdout = open(os.devnull, "w")
                code = 0
            except (Exception, KeyboardInterrupt, Terminated) as e:  # noqa: BLE001
                code = exit_for(e)
        if standalone_mode:
            sys.exit(code)
        return code
