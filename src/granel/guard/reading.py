"""The one reader of users' files: every OS, decoding and parse error becomes an `InputFileError`
that names the file (and the line where one applies), with exit code 2 (the name or the content
is wrong: no such file, not text, not TOML, a bad row or column) or 4 (there is no file to read
there: a folder, a FIFO or a device; or the file system refuses it: permission, I/O error)."""

from __future__ import annotations

import csv
import io
import math
import os
import re
import stat
import sys
import tomllib
from pathlib import Path

from .exits import FILES, USAGE, GranelError

# a scenario, sweep, design, CSV or load table larger than this is not one (a device, a log, a typo)
MAX_TEXT_BYTES = 64 * 2**20


class InputFileError(GranelError, ValueError):
    """A user's file that cannot be read or parsed; `code` 2 (bad content or name) or 4 (the
    file system refuses it)."""


def check_file(path: str | Path, what: str = "file") -> Path:
    """`path` names a regular file that can be opened (a symbolic link is followed)."""
    path = Path(path)
    try:
        st = os.stat(path)
    except UnicodeEncodeError:  # a name from a UTF-8 file, in a locale whose file names are ASCII
        raise InputFileError(f"{what} {str(path).encode('ascii', 'backslashreplace').decode()}: the name cannot be "
                             f"written in this locale's file-name encoding ({sys.getfilesystemencoding()}); run granel "
                             "in a UTF-8 locale (LC_ALL=C.UTF-8) or without PYTHONUTF8=0", USAGE) from None
    except FileNotFoundError:
        raise InputFileError(f"{what} {path}: no such file", USAGE) from None
    except NotADirectoryError:
        raise InputFileError(f"{what} {path}: no such file (a part of the path is a file, not a folder)", USAGE) from None
    except OSError as e:
        if e.errno == 36 or "too long" in str(e).lower():
            raise InputFileError(f"{what} {str(path)[:60]}...: the name is too long for the file system", USAGE) from None
        raise InputFileError(f"{what} {path}: cannot be read ({e.strerror or e})", FILES) from None
    if stat.S_ISDIR(st.st_mode):
        raise InputFileError(f"{what} {path}: is a folder, not a file", FILES)
    if not stat.S_ISREG(st.st_mode):
        raise InputFileError(f"{what} {path}: is not a regular file (a device, a FIFO or a socket)", FILES)
    return path


def read_bytes(path: str | Path, what: str = "file", limit: int = MAX_TEXT_BYTES) -> bytes:
    path = check_file(path, what)
    try:
        size = path.stat().st_size
        if size > limit:
            raise InputFileError(f"{what} {path}: {size / 2**20:.1f} MiB, larger than such a file can be "
                                 f"({limit / 2**20:.0f} MiB)", USAGE)
        with open(path, "rb") as fh:
            return fh.read(limit + 1)
    except InputFileError:
        raise
    except OSError as e:
        raise InputFileError(f"{what} {path}: cannot be read ({e.strerror or e})", FILES) from None


def read_text(path: str | Path, what: str = "file", limit: int = MAX_TEXT_BYTES) -> str:
    """A UTF-8 text file (a byte-order mark is allowed)."""
    return _decoded(read_bytes(path, what, limit), what, path)


_STDIN: dict = {}


def read_stdin(what: str = "file", limit: int = MAX_TEXT_BYTES) -> str:
    """Standard input as UTF-8 text, read once per process (a second call gets the same text, so
    that a command may load its scenario twice); a terminal is refused, since it would wait for
    typing with no prompt."""
    stream = sys.stdin
    if _STDIN.get("stream") is not stream or "text" not in _STDIN:
        _STDIN.clear()
        if stream is None or stream.closed:
            raise InputFileError(f"{what} -: there is no standard input to read", USAGE)
        try:
            if stream.isatty():
                raise InputFileError(f"{what} -: standard input is a terminal; pipe the file in, e.g. "
                                     "granel run - < my.toml", USAGE)
            data = getattr(stream, "buffer", stream).read(limit + 1)
        except InputFileError:
            raise
        except (OSError, ValueError) as e:
            raise InputFileError(f"{what} -: cannot read standard input ({getattr(e, 'strerror', None) or e})", FILES) from None
        if isinstance(data, str):
            data = data.encode("utf-8", "surrogateescape")
        if len(data) > limit:
            raise InputFileError(f"{what} -: standard input holds more than such a file can be "
                                 f"({limit / 2**20:.0f} MiB)", USAGE)
        _STDIN.update(stream=stream, text=_decoded(data, what, "(standard input)"))
    return _STDIN["text"]


def _decoded(data: bytes, what: str, path) -> str:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise InputFileError(f"{what} {path}, line {line}: not UTF-8 text (byte {data[e.start]:#04x} at offset "
                             f"{e.start})", USAGE) from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise InputFileError(f"{what} {path}, line {line}: a NUL byte: not a text file", USAGE)
    return text


_TOML_WHERE = re.compile(r"\(at line (\d+), column (\d+)\)")


def parse_toml(text: str, where: str) -> dict:
    """TOML text -> dict; a syntax error names `where` and the line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        msg = str(e)
        m = _TOML_WHERE.search(msg)
        if m:
            msg = _TOML_WHERE.sub("", msg).strip()
            raise InputFileError(f"{where}, line {m.group(1)}: not valid TOML ({msg}, column {m.group(2)})", USAGE) from None
        raise InputFileError(f"{where}: not valid TOML ({msg})", USAGE) from None
    except RecursionError:
        raise InputFileError(f"{where}: not valid TOML (nested too deeply)", USAGE) from None


def read_toml(path: str | Path, what: str = "file") -> dict:
    return parse_toml(read_text(path, what), f"{what} {path}")


def read_csv(path: str | Path, what: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> list[dict]:
    """Rows of a CSV file with a header naming its columns: every one of `required`, any of
    `optional`, nothing else (a misspelt column is an error, not ignored); blank lines and lines
    starting with # are skipped. Each row is a dict {column: text} with its line number under
    "__line__"; a row with too many or too few fields names its line."""
    text = read_text(path, what)
    where = f"{what} {path}"
    reader = csv.reader(io.StringIO(text, newline=""))
    header, rows = None, []
    try:
        for row in reader:
            line = reader.line_num
            if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
                continue
            if header is None:
                header = [c.strip() for c in row]
                _check_header(header, where, line, required, optional)
                continue
            if len(row) != len(header):
                raise InputFileError(f"{where}, line {line}: {len(row)} columns, the header names {len(header)} "
                                     f"({','.join(header)})", USAGE)
            rows.append({"__line__": line, **{k: v.strip() for k, v in zip(header, row)}})
    except csv.Error as e:
        raise InputFileError(f"{where}, line {reader.line_num}: not valid CSV ({e})", USAGE) from None
    if header is None:
        raise InputFileError(f"{where}: empty (a header line {','.join(required)} is needed)", USAGE)
    return rows


def _check_header(header, where, line, required, optional):
    known = set(required) | set(optional)
    unknown = [c for c in header if c not in known]
    if unknown:
        close = {c: _nearest(c, known) for c in unknown}
        hint = "; ".join(f"{c!r}" + (f" (did you mean {close[c]!r}?)" if close[c] else "") for c in unknown)
        raise InputFileError(f"{where}, line {line}: unknown column {hint}; the columns are {', '.join(required)}"
                             + (f" and optionally {', '.join(optional)}" if optional else ""), USAGE)
    repeated = sorted({c for c in header if header.count(c) > 1})
    if repeated:
        raise InputFileError(f"{where}, line {line}: column {', '.join(map(repr, repeated))} appears twice", USAGE)
    missing = [c for c in required if c not in header]
    if missing:
        raise InputFileError(f"{where}, line {line}: the header lacks {', '.join(map(repr, missing))} (it must name "
                             f"{', '.join(required)})", USAGE)


def _nearest(word: str, choices) -> str | None:
    import difflib

    hit = difflib.get_close_matches(word, sorted(choices), n=1, cutoff=0.6)
    return hit[0] if hit else None


def number(text: str, where: str, column: str, positive: bool = False) -> float:
    """A CSV cell as a finite float (positive where asked), the error naming the place."""
    try:
        v = float(text)
    except ValueError:
        raise InputFileError(f"{where}: {column} = {text!r} is not a number", USAGE) from None
    if not math.isfinite(v):
        raise InputFileError(f"{where}: {column} = {text!r} is not finite", USAGE)
    if positive and not v > 0:
        raise InputFileError(f"{where}: {column} = {text!r} must be positive", USAGE)
    return v
