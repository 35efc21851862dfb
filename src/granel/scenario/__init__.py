"""Scenarios: the TOML schema (`schema`), file input and overrides (`files`), and building the
objects the solvers receive (`build`); every error names the offending field and value.
May import: problem, coupling, solid, granular, io, guard."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from ..granular.loads import SHOCK_LEVELS  # noqa: F401
from ..granular.scales import HERTZ_DURATION, safe_time_step  # noqa: F401
from .build import (  # noqa: F401
    build_granular,
    build_media,
    build_problem,
    build_solid,
    built_models,
    check_scenario,
    elastic_solid,
)
from .files import (  # noqa: F401
    _format_validation_error,
    apply_overrides,
    builtin_description,
    check_source,
    contact_note,
    builtin_names,
    input_digests,
    input_texts,
    load_raw,
    override,
    referenced_files,
    referenced_names,
    STDIN,
    scenario_file,
    scenario_inputs,
    shock_value,
    to_toml,
    with_input_texts,
)
from .schema import (  # noqa: F401
    ContactSpec,
    ExcitationSpec,
    InitialVelocitySpec,
    MaterialSpec,
    MediumSpec,
    Scenario,
    ScenarioError,
    SimulationSpec,
    SolidSpec,
    WallSpec,
)


def validate(raw: dict, base: Path | None = None) -> Scenario:
    """Field validation, then whole-scenario checks; raises ScenarioError naming the field."""
    try:
        sc = Scenario.model_validate(raw)
    except ValidationError as e:
        raise ScenarioError(_format_validation_error(e)) from None
    check_scenario(sc, base)
    sc._base = base
    return sc


def load(source: str | Path, overrides: list[str] | None = None, check_usage: bool = True, shock=None,
         implied=()) -> Scenario:
    """A built-in name, a TOML file or standard input ("-"), with `key.path=value` overrides,
    validated; an override of a field the run ignores is refused (`usage.check_overrides_used`)
    unless `check_usage` is false (a design's probe of what its variables change). `shock` (a
    level name or a peak force [N]) replaces the first excitation's `shock` and `fmax`;
    `implied` overrides (set by a shortcut's meaning) are not checked for use."""
    from .usage import check_overrides_used

    overrides = list(overrides or [])
    raw, base = load_raw(source)
    if shock is not None:
        keys = (o.split("=", 1)[0].strip() for o in overrides)
        both = [k for k in keys if k in ("excitations.0.shock", "excitations.0.fmax")]
        if both:
            raise ScenarioError(f"--shock and --set {both[0]} both set the first excitation's peak force: give one")
    raw = apply_overrides(raw, [*overrides, *implied])
    if shock is not None:
        if not raw.get("excitations"):
            raise ScenarioError("--shock: the scenario has no excitation to set")
        exc = raw["excitations"][0]
        exc.pop("fmax", None)
        exc.pop("shock", None)
        exc["shock" if isinstance(shock, str) else "fmax"] = shock
    sc = validate(raw, base)
    if check_usage:
        check_overrides_used(sc, overrides)
    return sc
