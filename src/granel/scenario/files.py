"""Scenario input: built-in names and TOML files, `key.path=value` overrides, TOML output."""

from __future__ import annotations

import copy
import json
import math
import tomllib
from importlib import resources
from pathlib import Path

import tomli_w
from pydantic import ValidationError

from ..guard.reading import InputFileError, parse_toml, read_stdin, read_toml
from .schema import Scenario, ScenarioError


def _format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(scenario)"
        msg = e["msg"]
        if msg.startswith("Value error, @"):  # a field's type misfit found by the model (schema._Strict)
            _, key, shown, why = msg.split("@", 3)
            lines.append(f"{loc}.{key} = {shown}: {why}" if loc != "(scenario)" else f"{key} = {shown}: {why}")
            continue
        if e["type"] == "extra_forbidden":
            msg = "unknown field"
        msg = msg.removeprefix("Value error, ")
        inp = e.get("input")
        shown = repr(inp) if not isinstance(inp, dict) else "{...}"
        if len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"{loc} = {shown}: {msg}")
    return "invalid scenario: " + "; ".join(lines)


STDIN = "-"  # the scenario source that means standard input, as Unix tools read it


def builtin_names() -> list[str]:
    return [p.name[:-5] for p in resources.files("granel.scenario").joinpath("builtin").iterdir() if p.name.endswith(".toml")]


def load_raw(source: str | Path) -> tuple[dict, Path | None]:
    """TOML text of a built-in name or a file -> (dict, base directory for relative paths); any
    problem reading or parsing the file is a ScenarioError naming it (and the line), with the
    reader's exit code (`guard.reading`)."""
    src = str(source)
    if src == STDIN:  # relative table paths then resolve against the working folder
        try:
            text = read_stdin("scenario")
            if not text.strip():
                raise ScenarioError("scenario -: standard input is empty; pipe a scenario in, e.g. granel run - < my.toml")
            return parse_toml(text, "scenario (standard input)"), Path.cwd()
        except InputFileError as e:
            raise ScenarioError(str(e), e.code) from None
    if src in builtin_names():
        text = resources.files("granel.scenario").joinpath("builtin").joinpath(f"{src}.toml").read_text()
        return tomllib.loads(text), None
    path = Path(src)
    if not src.strip():
        raise ScenarioError(f"scenario {src!r}: give a built-in name ({', '.join(builtin_names())}) or a TOML file")
    try:
        if not path.exists() and not path.is_symlink():
            raise ScenarioError(f"scenario {src!r}: no such file and not a built-in ({', '.join(builtin_names())})")
        return read_toml(path, "scenario"), path.parent
    except InputFileError as e:
        raise ScenarioError(str(e), e.code) from None
    except OSError as e:  # a name the file system cannot even look up (too long, ...)
        raise ScenarioError(f"scenario {src[:80]!r}: {e.strerror or e}") from None


def _coerce(text: str):
    """A CLI override value: TOML literal if it parses, else a plain string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


# an override's value that removes its key or list entry (a bare - is no TOML value, so it cannot mean one)
REMOVE = "-"


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `a.b.c=value` overrides (list indices as numbers: media.1.radius=0.006); `key=-`
    removes the key or the list entry (media.1=- drops the second medium, the later ones moving
    up, so that several removals from one list count on the list as each leaves it)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise ScenarioError(f"override {item!r}: expected key=value, e.g. contact.mu=0.2")
        key, val = item.split("=", 1)
        parts = key.strip().split(".")
        node = raw
        for k, p in enumerate(parts[:-1]):
            if isinstance(node, list):
                try:
                    node = node[int(p)]
                except (ValueError, IndexError):
                    raise ScenarioError(f"override {key!r}: no list item {p!r}") from None
            elif isinstance(node, dict):
                node = node.setdefault(p, {})
            else:
                raise ScenarioError(f"override {key!r}: {'.'.join(parts[:k])} is a value, not a table")
        if not isinstance(node, (dict, list)):
            raise ScenarioError(f"override {key!r}: {'.'.join(parts[:-1])} is a value, not a table")
        last = parts[-1]
        if val.strip() == REMOVE:
            try:
                if isinstance(node, list):
                    del node[int(last)]
                else:
                    del node[last]
            except (ValueError, IndexError, KeyError):
                raise ScenarioError(f"override {key!r}=-: nothing to remove there") from None
            continue
        if isinstance(node, list):
            try:
                node[int(last)] = _coerce(val)
            except (ValueError, IndexError):
                raise ScenarioError(f"override {key!r}: no list item {last!r}") from None
        else:
            node[last] = _coerce(val.strip())
    return raw


def override(field: str, value) -> str:
    """The `field=value` override that `apply_overrides` reads back as `value` (a string, bool,
    number or list of them)."""
    return f"{field}={_literal(value)}"


def _literal(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_literal(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def to_toml(sc: Scenario) -> str:
    """The scenario as TOML text, every string `storable` (a result stores this text)."""
    from ..guard.writing import storable

    def clean(node):
        if isinstance(node, dict):
            return {k: clean(v) for k, v in node.items()}
        if isinstance(node, list):
            return [clean(v) for v in node]
        return storable(node) if isinstance(node, str) else node

    return tomli_w.dumps(clean(sc.model_dump(mode="json", exclude_none=True)))




def _referenced(sc: Scenario) -> dict[str, Path]:
    """{name as the scenario writes it: path as the run opens it} of every file it refers to."""
    names = [m.granules_file for m in sc.media if m.granules_file] + \
        [e.file for e in sc.excitations if e.kind == "table" and e.file]
    out = {}
    for name in names:
        path = Path(name)
        if sc.base is not None and not path.is_absolute():
            path = sc.base / path
        out[name] = path
    return out


def input_texts(sc: Scenario) -> dict[str, str]:
    """The text of every file the scenario refers to, by the names it gives them: a result
    stores them so that it carries its whole model (`with_input_texts` rebuilds it anywhere)."""
    from ..guard.reading import read_text
    from ..guard.writing import storable

    return {storable(name): read_text(path, "file") for name, path in _referenced(sc).items()}


def with_input_texts(raw: dict, texts: dict[str, str], folder: Path) -> dict:
    """`raw` with each referenced file that `texts` holds written into `folder` and named there
    (absolute), so that a stored scenario validates wherever its result is read."""
    import hashlib

    out = copy.deepcopy(raw)
    places = [(m, "granules_file") for m in out.get("media", []) if isinstance(m, dict)] + \
        [(e, "file") for e in out.get("excitations", []) if isinstance(e, dict)]
    for table, key in places:
        name = table.get(key)
        if isinstance(name, str) and name in texts:
            path = folder / f"{hashlib.sha1(name.encode()).hexdigest()[:12]}-{Path(name).name}"
            if not path.exists():
                path.write_text(texts[name], encoding="utf-8")
            table[key] = str(path)
    return out


def referenced_files(sc: Scenario) -> list[Path]:
    """Every file the scenario reads besides itself (granule tables, load tables), as the run
    opens them (relative to the scenario's folder)."""
    return list(_referenced(sc).values())


def scenario_inputs(source: str, sc: Scenario) -> list[Path]:
    """The files a command reads for the scenario `source` (a name, a file or -): the scenario
    file itself and every file it refers to."""
    return [scenario_file(source), *referenced_files(sc)]


def contact_note(sc: Scenario) -> str | None:
    """What a user should be told of a scenario without [contact] (it runs with the paper's
    friction and damping), or None."""
    if "contact" in sc.model_fields_set:
        return None
    c = sc.contact
    return (f"no [contact] table: the paper's contact law applies (mu = {c.mu:g}, alpha_n = {c.alpha_n:g}, "
            f"k_s = {c.k_s:g} s/m); write [contact] with mu = 0.0 and alpha_n = 0.0 for frictionless, undamped contacts")


def input_digests(sc: Scenario) -> dict[str, str]:
    """The contents' digests of every file the scenario refers to, by the names it gives them
    (empty for a scenario that reads no other file): a run's, a sweep case's or a checkpoint's
    fingerprint covers them, so that an edited table is never mixed with results of the old one."""
    from ..guard.fingerprints import digests

    return digests(_referenced(sc))


def scenario_file(source: str | Path) -> Path | None:
    """The file a scenario source names (None for a built-in name)."""
    return None if str(source) in builtin_names() or str(source) == STDIN else Path(source)


def referenced_names(source, overrides=()) -> list[str]:
    """The granule and load tables a scenario (with `overrides`) names, as written (relative to
    its folder); [] when it cannot be read (its errors are reported where it is loaded)."""
    try:
        raw = apply_overrides(load_raw(source)[0], list(overrides))
    except ScenarioError:
        return []
    names = [m.get("granules_file") for m in raw.get("media", []) if isinstance(m, dict)]
    names += [e.get("file") for e in raw.get("excitations", []) if isinstance(e, dict)]
    return [n for n in names if isinstance(n, str) and n]


def check_source(source, overrides=()) -> None:
    """ScenarioError when a scenario cannot be read or its `overrides` cannot be applied (whether
    the result is a valid scenario is checked where it is loaded)."""
    try:
        raw, _ = load_raw(source)
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"cannot read {source} ({e})") from None
    apply_overrides(raw, list(overrides))


def builtin_description(name: str) -> str:
    """The `description` of a built-in scenario."""
    return str(load_raw(name)[0].get("description", ""))


def shock_value(text: str | None):
    """`--shock`: a level name (weak, moderate, strong), or a peak force in newtons (a number,
    with or without N); None stays None. ScenarioError naming the option otherwise."""
    from ..granular.loads import SHOCK_LEVELS

    if text is None or text in SHOCK_LEVELS:
        return text
    try:
        value = float(text.removesuffix("N"))
    except ValueError:
        raise ScenarioError(f"--shock {text!r}: give weak, moderate, strong or a peak force in N, e.g. 500") from None
    if not math.isfinite(value):
        raise ScenarioError(f"--shock {text!r}: the peak force must be finite")
    return value
