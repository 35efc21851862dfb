"""The design file of `granel design DESIGN.toml -o DIR`: its schema (`DesignSpec`: the scenario
fields searched, the metrics optimised or bounded, the sampler), its loading (`load_design`) and
the checks before anything runs (`check_design`: a variable that the base scenario cannot take,
or that no run depends on, `check_variables_matter`, is refused). The search is
`design_search`'s, the trials and what they leave `design_trials`'; docs/design.md gives the
design file."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .. import scenario as S
from ..scenario.usage import SOLID_FIELDS
from .modes import study_mode
from .screening import ScreeningSpec
from .sweep import CaseSpec, case_scenarios, check_base, check_mode

# a best value this close to a variable's bound (a share of its range, of its log for a log
# variable) is reported as at the bound: the optimum may lie outside the range searched
BOUND_SHARE = 0.01
# a target objective whose best misfit |m / target - 1| exceeds this (unless the objective sets
# its own `tolerance`) is reported as missed
TARGET_TOLERANCE = 0.01


class DesignFileError(S.ScenarioError):
    """A design file that cannot be used; the message names the file and the field."""


class VariableSpec(BaseModel):
    """One scenario field searched: continuous (low, high, optional log), integer (integer = true)
    or categorical (choices)."""

    model_config = ConfigDict(extra="forbid")
    field: str = Field(min_length=1)
    tied: list[str] = Field(default_factory=list, description="more fields that take the same value (e.g. every "
                                                               "bead's radius of a chain)")
    low: float | None = None
    high: float | None = None
    log: bool = False
    integer: bool = False
    choices: list[Any] | None = None

    @model_validator(mode="after")
    def _kind(self):
        for k, f in enumerate(self.tied):
            if not f.strip():
                raise ValueError(f"{self.field}: tied.{k} is empty")
        if len(set([self.field, *self.tied])) != len(self.tied) + 1:
            raise ValueError(f"{self.field}: tied repeats a field ({[self.field, *self.tied]})")
        if self.choices is not None:
            if self.low is not None or self.high is not None or self.log or self.integer:
                raise ValueError(f"{self.field}: a categorical variable takes choices only (no low, high, log, integer)")
            if not self.choices:
                raise ValueError(f"{self.field}: choices is empty")
            if len({json.dumps(c, sort_keys=True) for c in self.choices}) != len(self.choices):
                raise ValueError(f"{self.field}: choices repeat a value")
            return self
        if self.low is None or self.high is None:
            raise ValueError(f"{self.field}: a variable needs low and high, or choices")
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or not self.low < self.high:
            raise ValueError(f"{self.field}: needs finite low < high, got low = {self.low}, high = {self.high}")
        if self.log and self.low <= 0:
            raise ValueError(f"{self.field}: a log-scale variable needs low > 0, got {self.low}")
        if self.integer and (self.low != int(self.low) or self.high != int(self.high)):
            raise ValueError(f"{self.field}: an integer variable needs whole bounds, got {self.low}, {self.high}")
        return self

    @property
    def fields(self) -> list[str]:
        """Every field this variable sets: its own and the tied ones."""
        return [self.field, *self.tied]

    @property
    def kind(self) -> str:
        return "categorical" if self.choices is not None else "int" if self.integer else "float"

    def distribution(self):
        """Optuna's distribution of this variable."""
        from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

        if self.choices is not None:
            return CategoricalDistribution([_hashable(c) for c in self.choices])
        if self.integer:
            return IntDistribution(int(self.low), int(self.high), log=self.log)
        return FloatDistribution(self.low, self.high, log=self.log)

    def points(self) -> list[Any]:
        """Values that bracket the range, to check the field before anything runs."""
        return list(self.choices) if self.choices is not None else [self._cast(self.low), self._cast(self.high)]

    def probes(self) -> list[Any]:
        """The values at which `check_variables_matter` builds the runs: every choice, or the
        bounds and the middle of the range (on the log scale for a log variable)."""
        if self.choices is not None:
            return list(self.choices)
        mid = math.sqrt(self.low * self.high) if self.log else 0.5 * (self.low + self.high)
        out = [self._cast(self.low), self._cast(round(mid) if self.integer else mid), self._cast(self.high)]
        return list(dict.fromkeys(out))

    def bound_of(self, value) -> str | None:
        """"low" or "high" when `value` lies within BOUND_SHARE of the range (of its logarithm for
        a log variable) from that bound; None inside, or for a categorical variable."""
        if self.choices is not None or not isinstance(value, (int, float)) or isinstance(value, bool):
            return None
        lo, hi, x = (math.log(self.low), math.log(self.high), math.log(value)) if self.log and value > 0 else \
            (self.low, self.high, float(value))
        s = (x - lo) / (hi - lo)
        return "low" if s <= BOUND_SHARE else "high" if s >= 1.0 - BOUND_SHARE else None

    def _cast(self, v):
        return int(v) if self.integer else float(v)


def _hashable(v):
    """Optuna's categorical choices must be None, bool, int, float or str: lists travel as JSON."""
    return json.dumps(v) if isinstance(v, (list, dict)) else v


def _value(v):
    """A categorical choice back from `_hashable`."""
    if isinstance(v, str) and v[:1] in "[{":
        try:
            return json.loads(v)
        except ValueError:
            return v
    return v


class ObjectiveSpec(BaseModel):
    """A case metric to maximise or minimise, or to bring to a target (minimise |m / target - 1|);
    a target is met when the best design's misfit is at most `tolerance`."""

    model_config = ConfigDict(extra="forbid")
    metric: str = Field(min_length=1)
    direction: Literal["minimize", "maximize"] | None = None
    target: float | None = None
    tolerance: float | None = Field(None, description="a target's misfit |m / target - 1| that counts as met "
                                                      f"(default {TARGET_TOLERANCE:g})")

    @model_validator(mode="after")
    def _one(self):
        if (self.direction is None) == (self.target is None):
            raise ValueError(f"objective {self.metric}: give either direction (minimize, maximize) or target")
        if self.target is not None and (not math.isfinite(self.target) or self.target == 0):
            raise ValueError(f"objective {self.metric}: target must be finite and non-zero, got {self.target}")
        if self.tolerance is not None:
            if self.target is None:
                raise ValueError(f"objective {self.metric}: tolerance belongs to a target objective")
            if not (math.isfinite(self.tolerance) and self.tolerance > 0):
                raise ValueError(f"objective {self.metric}: tolerance must be a positive misfit, got {self.tolerance}")
        return self

    @property
    def met_within(self) -> float:
        """The misfit at which this target counts as met."""
        return TARGET_TOLERANCE if self.tolerance is None else self.tolerance

    @property
    def name(self) -> str:
        return self.metric if self.target is None else f"{self.metric}_misfit"

    @property
    def sense(self) -> str:
        return self.direction or "minimize"

    def value(self, metrics: dict) -> float:
        m = _metric(metrics, self.metric)
        return m if self.target is None else abs(m / self.target - 1.0)


class ConstraintSpec(BaseModel):
    """A case metric kept within max and/or min (Optuna's constraints: the value <= 0 is met)."""

    model_config = ConfigDict(extra="forbid")
    metric: str = Field(min_length=1)
    max: float | None = None
    min: float | None = None

    @model_validator(mode="after")
    def _bounds(self):
        if self.max is None and self.min is None:
            raise ValueError(f"constraint {self.metric}: give max, min or both")
        for b in (self.max, self.min):
            if b is not None and not math.isfinite(b):
                raise ValueError(f"constraint {self.metric}: bounds must be finite")
        if self.max is not None and self.min is not None and not self.min < self.max:
            raise ValueError(f"constraint {self.metric}: needs min < max")
        return self

    def violation(self, metrics: dict) -> float:
        """How far the metric is outside its bounds, relative to them (<= 0: met)."""
        m = _metric(metrics, self.metric)
        out = -np.inf
        if self.max is not None:
            out = max(out, (m - self.max) / max(abs(self.max), 1e-300))
        if self.min is not None:
            out = max(out, (self.min - m) / max(abs(self.min), 1e-300))
        return float(out)


class MetricError(ValueError):
    """An objective or constraint whose metric the case did not produce, or produced as NaN;
    `metric` names it."""

    def __init__(self, msg: str, metric: str = ""):
        super().__init__(msg)
        self.metric = metric


def _metric(metrics: dict, name: str) -> float:
    if name not in metrics:
        raise MetricError(f"no metric {name!r} in this case; it has {sorted(metrics)}", name)
    v = metrics[name]
    if not isinstance(v, (int, float)) or not math.isfinite(v):
        raise MetricError(f"metric {name!r} is {v!r}", name)
    return float(v)


class DesignSpec(CaseSpec):
    name: str = "design"
    trials: int = Field(50, ge=1, le=100_000)
    seed: int = Field(0, ge=0)
    sampler: Literal["auto", "tpe", "cmaes", "nsga2", "random"] = Field(
        "auto", description="auto: TPE and then a local refinement (studies.refine) for one objective, no "
                            "constraints and continuous variables; TPE for one objective otherwise; NSGA-II "
                            "for several")
    population: int | None = Field(None, ge=2, le=10_000, description="NSGA-II's generation size (default: "
                                                                     "trials / 6, between 8 and 50)")
    variables: list[VariableSpec] = Field(min_length=1)
    objectives: list[ObjectiveSpec] = Field(min_length=1)
    constraints: list[ConstraintSpec] = Field(default_factory=list)
    frequencies: list[float] | None = Field(None, description="spectrum mode: the band's drive frequencies [Hz], "
                                                              "each a narrowband run (both directions if the "
                                                              "[spectrum] table says so)")
    screening: ScreeningSpec | None = Field(None, description="trials at a looser accuracy, the best confirmed at the "
                                                              "design's own")

    @model_validator(mode="after")
    def _design(self):
        study_mode(self.mode).check_band(self.frequencies)
        if self.frequencies is not None:
            if not 1 <= len(self.frequencies) <= MAX_BAND:
                raise ValueError(f"frequencies: give 1 to {MAX_BAND} drive frequencies, got {len(self.frequencies)}")
            for k, f in enumerate(self.frequencies):
                if not (math.isfinite(f) and f > 0):
                    raise ValueError(f"frequencies.{k} = {f!r}: a drive frequency must be positive [Hz]")
        known = study_mode(self.mode).trial_metric_units(self)
        for what, items in (("objectives", self.objectives), ("constraints", self.constraints)):
            for k, item in enumerate(items):
                if item.metric not in known:
                    raise ValueError(f"{what}.{k}.metric = {item.metric!r}: not a metric of a {self.mode!r} case; "
                                     f"choose from {list(known)}")
        fields = [f for v in self.variables for f in v.fields]
        if len(set(fields)) != len(fields):
            raise ValueError(f"variables: a field appears twice in {fields}")
        names = [o.name for o in self.objectives]
        if len(set(names)) != len(names):
            raise ValueError(f"objectives: {names} repeats one")
        if self.sampler == "cmaes":
            if len(self.objectives) > 1:
                raise ValueError("sampler: cmaes optimises one objective; use nsga2 for several")
            if self.constraints:
                raise ValueError("sampler: cmaes takes no constraints; use tpe or nsga2")
        return self

    @property
    def directions(self) -> list[str]:
        return [o.sense for o in self.objectives]

    def screened(self) -> "DesignSpec":
        """The design as its trials run it: its overrides, then the screening's."""
        if self.screening is None:
            return self
        return self.model_copy(update={"overrides": [*self.overrides, *self.screening.overrides]})


# the largest band of a spectrum-mode design (each frequency is a run, or two)
MAX_BAND = 200


def load_design(path) -> tuple[DesignSpec, Path]:
    """A design file -> (DesignSpec, its folder); DesignFileError names the file and the field
    (or the line), with the reader's exit code (`guard.reading`)."""
    from ..guard.reading import InputFileError, read_toml

    path = Path(path)
    try:
        raw = read_toml(path, "design")
    except InputFileError as e:
        raise DesignFileError(str(e), e.code) from None
    try:
        spec = DesignSpec.model_validate(raw)
    except ValidationError as e:
        raise DesignFileError(S._format_validation_error(e).replace("invalid scenario", f"invalid design {path}")) from None
    return spec, path.parent


def check_design(spec: DesignSpec, base_dir: Path) -> None:
    """Fail before anything runs (DesignFileError naming the variable) when a variable's field
    cannot take its bounds or choices in the base scenario (a typo, a field that is not a
    scenario's, a value its schema refuses everywhere), or when no run depends on it
    (`check_variables_matter`, first: its reasons say more than a field check's)."""
    check_base(spec, base_dir)
    if spec.screening is not None:
        try:
            S.load(spec.base_path(base_dir), spec.screened().overrides)
        except S.ScenarioError as e:
            raise DesignFileError(f"screening.overrides: the base scenario refuses them ({' '.join(str(e).split())})") from None
    check_variables_matter(spec, base_dir)
    check_mode(spec, base_dir, _probe_case(spec, {}))
    base = spec.base_path(base_dir)
    for k, var in enumerate(spec.variables):
        errors = []
        for v in var.points():
            try:
                S.load(base, [*spec.overrides, *(S.override(f, v) for f in var.fields)])
            except S.ScenarioError as e:
                errors.append((v, str(e)))
        if len(errors) == len(var.points()):
            v, msg = errors[0]
            raise DesignFileError(f"variables.{k}.field = {var.field!r}{' (or a tied field)' if var.tied else ''}: the "
                                  "base scenario refuses it "
                                  f"({var.field} = {v!r}: {' '.join(msg.split())})")


# ---------------------------------------------------------------- variables that no run depends on


def _digest(obj) -> str:
    """A fingerprint of a built object: its dataclass fields, arrays, sparse matrices, containers
    and numbers, recursively (callables by their type only)."""
    import dataclasses

    import scipy.sparse as sp

    h = hashlib.sha256()

    def feed(x, depth=0):
        if depth > 40:
            raise RecursionError("too deep")
        if x is None or isinstance(x, (bool, int, str)):
            h.update(repr(x).encode())
        elif isinstance(x, float):
            h.update(x.hex().encode() if math.isfinite(x) else repr(x).encode())
        elif isinstance(x, np.generic):
            feed(x.item(), depth)
        elif isinstance(x, np.ndarray):
            h.update(f"nd{x.dtype.str}{x.shape}".encode())
            if x.dtype == object:
                for v in x.ravel():
                    feed(v, depth + 1)
            else:
                h.update(np.ascontiguousarray(x).tobytes())
        elif sp.issparse(x):
            x = x.tocsr().copy()
            x.sum_duplicates()
            x.sort_indices()
            h.update(f"sp{x.shape}".encode())
            for a in (x.data, x.indices, x.indptr):
                feed(a, depth + 1)
        elif isinstance(x, (list, tuple)):
            h.update(f"({type(x).__name__}{len(x)}".encode())
            for v in x:
                feed(v, depth + 1)
            h.update(b")")
        elif isinstance(x, dict):
            h.update(f"{{{len(x)}".encode())
            for key in sorted(x, key=repr):
                feed(key, depth + 1)
                feed(x[key], depth + 1)
            h.update(b"}")
        elif dataclasses.is_dataclass(x):
            h.update(type(x).__name__.encode())
            feed({f.name: getattr(x, f.name) for f in dataclasses.fields(x)}, depth + 1)
        elif callable(x):
            h.update(f"fn:{type(x).__name__}".encode())
        elif hasattr(x, "__dict__"):
            h.update(type(x).__name__.encode())
            feed(vars(x), depth + 1)
        else:
            h.update(repr(x).encode())

    feed(obj)
    return h.hexdigest()


def _probe_runs(spec: DesignSpec, base_dir: Path, overrides: dict) -> list | None:
    """The runs of a trial with these overrides, as the solver would receive them short of the
    solid: [(scenario, its granular system, fingerprint of the system, its initial state and the
    resolved [simulation] table)], or None when the design is invalid there."""
    from ..scenario.build import build_granular

    case = _probe_case(spec, overrides)
    try:
        runs = case_scenarios(spec, base_dir, case, check_usage=False)
        out = []
        for _, sc in runs:
            system, state, _ = build_granular(sc, sc.base)
            out.append((sc, system, _digest((system, state, sc.simulation.model_dump()))))
        return out
    except Exception:  # noqa: BLE001 - a design invalid there is a failed trial, not a verdict on the variable
        return None


def _probe_case(spec: DesignSpec, overrides: dict) -> dict:
    """The first case that a trial with these overrides runs (`StudyMode.trial_cases`)."""
    case = {"index": [0], "overrides": dict(overrides), "tag": "probe"}
    return study_mode(spec.mode).trial_cases(spec, case)[0][0]


def _solid_digests(runs: list) -> list[str] | None:
    """The fingerprints of the runs' solid models (`build_solid`), or None if one cannot be built."""
    from ..scenario.build import build_solid

    try:
        return [_digest(build_solid(sc, system)) for sc, system, _ in runs]
    except Exception:  # noqa: BLE001 - a solid this design cannot build is a failed trial, not a verdict
        return None


def _depends(spec: DesignSpec, base_dir: Path, var: VariableSpec, context: dict) -> bool:
    """Whether the runs built at `var`'s probe values (the other fields at `context`) differ: in
    their granular systems, initial states or [simulation] tables, else in their solids (built
    only then). Fewer than two valid probes cannot tell: True."""
    built = []
    for v in var.probes():
        runs = _probe_runs(spec, base_dir, {**context, **{f: v for f in var.fields}})
        if runs is not None:
            built.append(runs)
    if len(built) < 2:
        return True
    if len({tuple(d for _, _, d in runs) for runs in built}) > 1:
        return True
    solids = [d for d in (_solid_digests(runs) for runs in built) if d is not None]
    return len(solids) < 2 or len({tuple(d) for d in solids}) > 1


def _field_value(sc: S.Scenario, field: str):
    """A dotted field of a resolved scenario (list items by index), or a marker if absent."""
    x: Any = sc.model_dump(mode="json")
    for part in field.split("."):
        if isinstance(x, list) and part.isdigit() and int(part) < len(x):
            x = x[int(part)]
        elif isinstance(x, dict) and part in x:
            x = x[part]
        else:
            return "(absent)"
    return x


def _why_inert(spec: DesignSpec, base_dir: Path, var: VariableSpec) -> str:
    """A reader's hint at why a variable's values build the same runs."""
    runs = [r for r in (_probe_runs(spec, base_dir, {f: v for f in var.fields}) for v in var.probes()) if r]
    if not runs:
        return "the solver never receives it"
    sc = runs[0][0][0]
    if len({json.dumps([_field_value(r[0], var.field) for r in rs], sort_keys=True) for rs in runs}) == 1:
        return f"the design's {spec.mode!r} mode sets it in every run"
    parts = var.field.split(".")
    leaf = parts[-1]
    if parts[0] == "excitations" and len(parts) >= 3 and parts[1].isdigit() and int(parts[1]) < len(sc.excitations):
        return f"excitations.{parts[1]} is a {sc.excitations[int(parts[1])].kind} load, which does not use {leaf}"
    if parts[0] == "solid":
        kind = "none" if sc.solid is None else sc.solid.kind
        return "the design has no solid" if kind == "none" else f"the {kind} solid does not use {'.'.join(parts[1:])}"
    if parts[0] == "materials" and len(parts) >= 2:
        used = {n for m in sc.media for n in [m.material, *(m.materials or [])]}
        if S.elastic_solid(sc) is not None and "material" in SOLID_FIELDS[sc.solid.kind]:
            used.add(sc.solid.material)
        if parts[1] not in used:
            return f"no granule and no elastic solid is made of {parts[1]}"
        return f"the runs do not use the {leaf} of {parts[1]}"
    if parts[0] == "media" and len(parts) >= 3:
        return f"media.{parts[1]} is built without {'.'.join(parts[2:])}"
    return "the solver never receives it"


def check_variables_matter(spec: DesignSpec, base_dir: Path) -> None:
    """Refuse (DesignFileError naming the variable) a variable that no run of the design depends
    on: its probe values (`VariableSpec.probes`) build the same granular systems, initial states,
    [simulation] tables and solids (everything `scenario.build_problem` hands the solver, the
    static equilibrium being a function of them), with the other variables at their base
    values and then at each of their own probes in turn (a field may matter only with another's
    value, e.g. a pulse's duration once a load's kind is a variable). No run and no modal
    analysis: a plate is assembled only where all else agrees, and is usually cached."""
    for k, var in enumerate(spec.variables):
        if _depends(spec, base_dir, var, {}):
            continue
        others = ({f: v for f in o.fields} for j, o in enumerate(spec.variables) if j != k for v in o.probes())
        if any(_depends(spec, base_dir, var, ctx) for ctx in others):
            continue
        values = ", ".join(_fmt_value(v) for v in var.probes())
        raise DesignFileError(f"variables.{k}.field = {var.field!r}: no run of this design depends on it "
                              f"({_why_inert(spec, base_dir, var)}): its values {values} build the same granules, "
                              "loads, solid and solver settings")


def _fmt_value(v) -> str:
    return f"{v:.6g}" if isinstance(v, float) else json.dumps(v) if not isinstance(v, str) else repr(v)


# the engine moved to design_search and design_trials: its old names here still import, with a warning
MOVED = {**{n: "design_search" for n in ("run_design", "open_study", "confirm_best", "make_sampler", "finished_trials",
                                         "recover_interrupted", "design_inputs")},
         **{n: "design_trials" for n in ("evaluate_trial", "trial_case", "score", "tell", "trials_dataset", "best_trials",
                                         "design_scenario", "write_outputs", "design_warnings")}}


def __getattr__(name: str):
    if name not in MOVED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib
    import warnings

    where = f"{__package__}.{MOVED[name]}"
    warnings.warn(f"{__name__}.{name} moved to {where}: import it from there", FutureWarning, stacklevel=2)
    return getattr(importlib.import_module(where), name)
