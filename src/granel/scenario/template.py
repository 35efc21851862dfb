"""`granel init`: a scenario file to start from, the paper's set-up with every field visible.

The values are the built-in paper scenario's, resolved (every default filled in); each field
carries its description from the schema as a comment, and the optional fields a table leaves
unset are listed, commented out, under it.
"""

from __future__ import annotations

import re
import typing

from pydantic import BaseModel

from .files import to_toml
from .schema import Scenario

_HEADER = re.compile(r"^\[\[?([A-Za-z0-9_.\-\"]+)\]\]?\s*$")
_KEY = re.compile(r"^([A-Za-z0-9_]+)\s*=")


def _model_of(annotation) -> type[BaseModel] | None:
    """The pydantic model inside an annotation (Model, list[Model], dict[str, Model], Optional)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _model_of(arg)
        if found is not None:
            return found
    return None


def _table_model(path: str) -> type[BaseModel] | None:
    """The schema model of a TOML table path such as 'simulation', 'materials.steel', 'media'."""
    model: type[BaseModel] | None = Scenario
    parts = [p.strip('"') for p in path.split(".")]
    k = 0
    while k < len(parts) and model is not None:
        field = model.model_fields.get(parts[k])
        if field is None:
            return None
        inner = _model_of(field.annotation)
        if typing.get_origin(field.annotation) is dict or "dict[" in str(field.annotation):
            k += 1  # a named entry: materials.NAME
        model = inner
        k += 1
    return model


def _unset_lines(model: type[BaseModel] | None, present: set[str]) -> list[str]:
    out = []
    if model is None:
        return out
    for name, field in model.model_fields.items():
        if name in present or _model_of(field.annotation) is not None:
            continue
        note = f"  # {field.description}" if field.description else ""
        out.append(f"# {name} = ...{note}")
    return out


def template(name: str) -> str:
    """The scenario text for `granel init NAME` (valid as written: it is the paper's set-up)."""
    from . import load

    sc = load("paper")
    sc = sc.model_copy(update={"name": name, "description": "my scenario (from granel init: the paper's set-up)"})
    lines = ["# A granel scenario: the paper's set-up, every field shown with its value (the schema's default",
             "# or the paper's). Fields a table leaves unset are listed commented out under it. Edit, then",
             f"#   granel show {name}.toml --resolved     (what granel reads)",
             f"#   granel run {name}.toml -o {name}.nc",
             "# Times take units (0.8ms, 1us); see the README's scenario section.", ""]
    model: type[BaseModel] | None = Scenario
    present: set[str] = set()
    for line in to_toml(sc).splitlines():
        head = _HEADER.match(line)
        if head:
            while lines and lines[-1] == "":
                lines.pop()
            lines += _unset_lines(model, present) if model is not Scenario else []
            model, present = _table_model(head.group(1)), set()
            if lines and lines[-1] != "":
                lines.append("")
            lines.append(line)
            continue
        key = _KEY.match(line)
        if key and model is not None:
            present.add(key.group(1))
            field = model.model_fields.get(key.group(1))
            if field is not None and field.description and len(line) + len(field.description) < 160:
                line = f"{line}  # {field.description}"
        lines.append(line)
    lines += _unset_lines(model, present)
    return "\n".join(lines) + "\n"


def write_template(name: str, output=None):
    """`granel init`: write `template(name)` to `output` (default NAME.toml), never over an
    existing file. InputError (exit 2) or FileError (exit 4) naming the name or the file."""
    from pathlib import Path

    from ..guard.commandline import text_argument
    from ..guard.exits import FileError, InputError, describe
    from ..guard.outputs import check_folder_writable, check_name_lengths
    from ..guard.writing import atomic_path, storable

    if not name.strip() or "/" in name or name.startswith("."):
        raise InputError(f"NAME {name!r}: give a plain name, e.g. mychain")
    out = Path(output) if output is not None else Path(f"{name}.toml")  # the name's bytes as given: a file name
    name = text_argument(name)
    if storable(name) != name:
        raise InputError(f"NAME {storable(name)}: not UTF-8 text")
    check_name_lengths(out, "-o")  # the output rules' checks of a name and its folder (exit 2 or 4)
    if out.exists():  # before the folder's check: a device in /dev is refused as such
        raise InputError(f"{out}: exists; granel init never replaces a file (choose another NAME or -o)")
    check_folder_writable(out.absolute().parent, "-o", out)
    try:
        with atomic_path(out) as tmp:
            Path(tmp).write_text(template(name), encoding="utf-8")
    except OSError as e:
        raise FileError(f"{out}: cannot write it ({describe(e)}{': ' + str(e.filename) if e.filename else ''})") from None
    return out
