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
    check_scenario,
)
from .files import (  # noqa: F401
    _format_validation_error,
    apply_overrides,
    builtin_names,
    input_digests,
    input_texts,
    load_raw,
    override,
    referenced_files,
    scenario_file,
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


def load(source: str | Path, overrides: list[str] | None = None, check_usage: bool = True) -> Scenario:
    """A built-in name or a TOML file, with `key.path=value` overrides, validated; an override
    of a field the run ignores is refused (`usage.check_overrides_used`) unless `check_usage` is
    false (a design's probe of what its variables change)."""
    from .usage import check_overrides_used

    raw, base = load_raw(source)
    sc = validate(apply_overrides(raw, overrides or []), base)
    if check_usage:
        check_overrides_used(sc, overrides)
    return sc
