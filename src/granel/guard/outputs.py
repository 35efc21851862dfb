"""The files and folders a command writes, checked before any computation (`OutputPlan`), so
that no run ends in an error that loses its result and no command overwrites what the user had:

- an output never resolves (symbolic links followed) to a file the command reads;
- an existing output file is replaced only if granel wrote it (`owners.is_granel_file`), never if
  it is read-only, a folder, or not a regular file (a device, a FIFO);
- an output folder is new, empty, or granel's own for the same command (its stamp); a folder
  that holds files granel did not write is refused, and no input may lie inside one;
- every path's folder must accept a new file, and names must fit the file system.

`prepare()` then makes the folders and stamps them; nothing is created before it."""

from __future__ import annotations

import json
import os
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from .exits import FILES, USAGE, GranelError
from .owners import STAMP, folder_stamp, is_granel_file, process_token
from .writing import PREFIX, STAGE, replace_refusal, write_text

# foreign entries named in a refusal
SHOWN = 3


class OutputPathError(GranelError, ValueError):
    """An output path that cannot or must not be written; `code` is the exit code (2: a wrong
    choice of path, 4: the file system refuses it)."""


def _real(path) -> Path:
    return Path(os.path.realpath(Path(path).expanduser()))


def _existing_ancestor(path: Path) -> Path:
    above = path.absolute()
    while not os.path.lexists(above):
        if above.parent == above:
            break
        above = above.parent
    return above


def check_name_lengths(path: Path, option: str) -> None:
    """Every part of `path` fits the file system's name limit, and the whole its path limit."""
    base = _existing_ancestor(path)
    try:
        name_max = os.pathconf(base if base.is_dir() else base.parent, "PC_NAME_MAX")
        path_max = os.pathconf(base if base.is_dir() else base.parent, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise OutputPathError(f"{option} {str(path)[:60]}...: the name {part[:30]}... is {len(os.fsencode(part))} "
                                  f"bytes, longer than the file system allows ({name_max})", USAGE)
    if len(os.fsencode(str(path.absolute()))) + 64 > path_max:
        raise OutputPathError(f"{option} {str(path)[:60]}...: the path is longer than the file system allows "
                              f"({path_max} bytes, with granel's temporary names)", USAGE)


def check_folder_writable(folder: Path, option: str, shown: Path) -> None:
    """`folder` exists as a folder that accepts a new file, or can be made under one that does:
    probed with a temporary file in the nearest existing folder (removed at once); nothing is
    created."""
    base = _existing_ancestor(folder)
    if not base.is_dir():
        raise OutputPathError(f"{option} {shown}: {base} is a file, not a folder", USAGE)
    try:
        fd, probe = tempfile.mkstemp(prefix=".granel-probe-", dir=base)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise OutputPathError(f"{option} {shown}: cannot write in {base}: {e.strerror or e}", FILES) from None


@dataclass
class _File:
    path: Path
    option: str


@dataclass
class _Folder:
    path: Path
    option: str
    kind: str
    recognise: object = None  # folder -> bool: a folder of this kind written before stamps existed
    resume: bool = True  # whether an existing folder of this kind is continued (else refused)


@dataclass
class OutputPlan:
    """What one command will write; `inputs` are every file it reads."""

    inputs: list = field(default_factory=list)
    files: list = field(default_factory=list)
    folders: list = field(default_factory=list)
    reserved: dict = field(default_factory=dict)  # suffix -> why (e.g. ".ckpt": checkpoints)

    def add_inputs(self, *paths) -> "OutputPlan":
        self.inputs += [Path(p) for p in paths if p is not None and str(p)]
        return self

    def file(self, path, option: str) -> Path:
        """An output file (a result, a figure, a report, a companion)."""
        path = Path(path)
        self.files.append(_File(path, option))
        return path

    def folder(self, path, option: str, kind: str, recognise=None, resume: bool = True) -> Path:
        """An output folder owned by the command `kind` (continued when it is one of its own)."""
        path = Path(path)
        self.folders.append(_Folder(path, option, kind, recognise, resume))
        return path

    # ------------------------------------------------------------------ checks

    def _inputs(self) -> dict:
        out = {}
        for p in self.inputs:
            try:
                if p.exists():
                    out[_real(p)] = p
            except OSError:
                continue
        return out

    def check(self) -> "OutputPlan":
        """Every rule of the module, for every output; raises OutputPathError (nothing is created)."""
        inputs = self._inputs()
        for f in self.folders:
            self._check_folder(f, inputs)
        for f in self.files:
            self._check_file(f, inputs)
        return self

    def _check_file(self, f: _File, inputs: dict) -> None:
        path, option = f.path, f.option
        check_name_lengths(path, option)
        why = self.reserved.get(path.suffix)
        if why:
            raise OutputPathError(f"{option} {path}: {why}", USAGE)
        if path.is_dir():
            raise OutputPathError(f"{option} {path}: is a folder; give a file name, e.g. {path / 'result.nc'}", USAGE)
        real = _real(path)
        if real in inputs:
            raise OutputPathError(f"{option} {path}: is an input of this command ({inputs[real]}); writing there "
                                  "would overwrite it", USAGE)
        if os.path.lexists(path):
            target = real if path.is_symlink() else path
            if not os.path.lexists(target):
                pass  # a dangling link: the result is written where it points
            else:
                why = replace_refusal(target)
                if why:
                    raise OutputPathError(f"{option} {path}: {why}", USAGE)
                if not is_granel_file(target):
                    raise OutputPathError(f"{option} {path}: exists and was not written by granel; granel replaces only "
                                          "its own files (move it away or choose another name)", USAGE)
        check_folder_writable(real.parent, option, path)

    def _check_folder(self, f: _Folder, inputs: dict) -> None:
        path, option = f.path, f.option
        check_name_lengths(path, option)
        if os.path.lexists(path) and not path.is_dir():
            raise OutputPathError(f"{option} {path}: is a file, not a folder", USAGE)
        real = _real(path)
        for r, given in inputs.items():
            if r == real or real in r.parents:
                raise OutputPathError(f"{option} {path}: holds an input of this command ({given}); write the outputs "
                                      "to another folder", USAGE)
        if path.is_dir():
            self._check_existing_folder(f)
        check_folder_writable(real, option, path)

    def _check_existing_folder(self, f: _Folder) -> None:
        path, option, kind = f.path, f.option, f.kind
        held = folder_stamp(path)
        if held is not None:
            if held["kind"] != kind:
                raise OutputPathError(f"{option} {path}: holds the outputs of granel {held['kind']}, not of granel "
                                      f"{kind}; write to another folder", USAGE)
            if not f.resume:
                raise OutputPathError(f"{option} {path}: holds the outputs of an earlier granel {kind}; move it away or "
                                      "choose another folder", USAGE)
            return
        try:
            entries = [e for e in os.scandir(path) if not (e.name.startswith(PREFIX) or e.name.startswith(STAGE))]
        except OSError as e:
            raise OutputPathError(f"{option} {path}: cannot be read ({e.strerror or e})", FILES) from None
        if not entries:
            return
        if f.recognise is not None and f.resume and f.recognise(path):
            return  # written by an earlier granel, before folders carried a stamp
        names = sorted(e.name + ("/" if e.is_dir() else "") for e in entries)
        shown = ", ".join(names[:SHOWN]) + (f" and {len(names) - SHOWN} more" if len(names) > SHOWN else "")
        raise OutputPathError(f"{option} {path}: holds files granel did not write ({shown}); give a new or empty "
                              "folder", USAGE)

    # ------------------------------------------------------------------ after the checks

    def prepare(self) -> "OutputPlan":
        """Make the output folders (stamped with their command) and the output files' folders."""
        try:
            for f in self.folders:
                f.path.mkdir(parents=True, exist_ok=True)
                stamp_folder(f.path, f.kind)
            for f in self.files:
                _real(f.path).parent.mkdir(parents=True, exist_ok=True)
        except GranelError:
            raise  # already names its file (a full disk while stamping a folder, ...)
        except OSError as e:
            from .exits import is_no_space

            if is_no_space(e):
                raise OutputPathError(f"{e.filename or ''}: no space left on the device", FILES) from None
            raise OutputPathError(f"cannot make the output folder {e.filename or ''} ({e.strerror or e})", FILES) from None
        return self


def check_outputs(inputs=(), files=(), folder=None, prepare: bool = True) -> OutputPlan:
    """Check (and make, with `prepare`) a command's outputs before any computation: `files` as
    (path, option), `folder` as (path, option, kind, recognise); `inputs` the files it reads."""
    plan = OutputPlan(inputs=[Path(p) for p in inputs if p is not None])
    if folder is not None:
        plan.folder(*folder)
    for path, option in files:
        plan.file(path, option)
    plan.check()
    return plan.prepare() if prepare else plan


def picture_file(output: Path, option: str, inputs=()) -> Path:
    """A picture to write, checked and its folder made: a format whose files carry granel's mark
    (`owners.PICTURE_FORMATS`), under the output rules."""
    from .owners import PICTURE_FORMATS

    if output.suffix.lower().lstrip(".") not in PICTURE_FORMATS:
        raise OutputPathError(f"{option} {output}: give a picture file name ending in one of "
                              f"{', '.join('.' + k for k in PICTURE_FORMATS)}")
    check_outputs(inputs, [(output, option)])
    return output


@contextmanager
def removed_if_refused(folder: Path):
    """Around a command's work on output folder `folder`, prepared inside the block: when the
    block ends in a GranelError and the folder, new before it, holds only its stamp, remove the
    folder, so that a command refused before writing anything (e.g. by an unreachable
    scheduler) leaves no folder behind."""
    folder = Path(folder)
    fresh = not folder.exists()
    try:
        yield
    except GranelError:
        if fresh and folder.is_dir() and [p.name for p in folder.iterdir()] == [STAMP]:
            (folder / STAMP).unlink()
            folder.rmdir()
        raise


def stamp_folder(folder: Path, kind: str) -> None:
    """Mark `folder` as made by granel for `kind` (a command's outputs); idempotent."""
    from .. import __version__

    held = folder_stamp(folder)
    if held is not None and held.get("kind") == kind:
        return
    write_text(Path(folder) / STAMP, json.dumps({"kind": kind, "version": __version__, "made": time.time(),
                                                 "by": process_token()}) + "\n", check=False)


def owned_by(folder: Path, kind: str) -> bool:
    """Whether `folder` carries the stamp of granel `kind`."""
    held = folder_stamp(folder)
    return held is not None and held.get("kind") == kind


__all__ = ["OutputPathError", "OutputPlan", "STAMP", "check_folder_writable", "check_name_lengths", "owned_by",
           "removed_if_refused"]
