"""Checks on the files a command will write, made before any computation: a run must not end in
an error that loses its result, nor overwrite or delete what the user had."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

EXIT_USAGE, EXIT_IO = 2, 4


class OutputPathError(ValueError):
    """An output path that cannot or must not be written; `code` is the exit code (2: a wrong
    choice of path, 4: the file system refuses it)."""

    def __init__(self, message: str, code: int = EXIT_USAGE):
        super().__init__(message)
        self.code = code


def writable_parent(path: Path, option: str, folder: Path | None = None) -> None:
    """The folder of `path` (or `folder`) must exist or be creatable, and accept a new file:
    probed by creating (the folders and) an empty temporary file there, removed at once."""
    parent = (folder if folder is not None else path.parent).absolute()
    above = parent
    while not above.exists():
        above = above.parent
    if not above.is_dir():
        raise OutputPathError(f"{option} {path}: {above} is a file, not a folder", EXIT_USAGE)
    try:
        parent.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".granel-probe-", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise OutputPathError(f"{option} {path}: cannot write in {parent}: {e.strerror or e}", EXIT_IO) from None


def check_result_path(path: Path, option: str = "-o", inputs: tuple = (), reserved_suffixes=(".ckpt",)) -> None:
    """A result file: not a folder, not one of the command's input files, not a reserved suffix
    (a checkpoint), and in a folder that can be written."""
    if path.is_dir():
        raise OutputPathError(f"{option} {path}: is a folder; give a file name, e.g. {path / 'result.nc'}")
    if path.suffix in reserved_suffixes:
        raise OutputPathError(f"{option} {path}: the {path.suffix} suffix is kept for checkpoints; use e.g. "
                              f"{path.with_suffix('.nc')}")
    for other in inputs:
        if other is not None and Path(other).exists() and path.exists() and path.resolve() == Path(other).resolve():
            raise OutputPathError(f"{option} {path}: is an input of this command ({other}); it would be overwritten")
    writable_parent(path, option)


def check_folder_path(path: Path, option: str = "--out") -> None:
    """An output folder: not an existing file, and creatable or writable."""
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{option} {path}: is a file, not a folder")
    writable_parent(path, option, folder=path)
