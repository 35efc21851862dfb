"""Design searches: `granel design DESIGN.toml -o DIR` looks for the scenario fields (radii,
thicknesses, materials, friction, preload, drive amplitude, counts) that optimise one or more
metrics of a case, with Optuna, each trial evaluated by the sweep engine (`sweep.run_case`) on
dask.distributed workers.

A trial applies its variables' values as overrides on top of the design's and runs its cases
(`modes.StudyMode.trial_cases`); an invalid design is a failed trial with its reason, and the study
goes on. The study lives in DIR/study.journal (Optuna's journal file): a rerun continues it, and a
trial interrupted in flight is run again with the same values. Each trial's sampler is seeded from
the design's seed and the number of trials finished before it. `check_design` refuses a variable
that the base scenario cannot take or that no run depends on (`check_variables_matter`);
`design_warnings` says when a best design sits at a bound or misses a target. docs/design.md gives
the design file and the rest."""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .. import scenario as S
from .modes import study_mode
from .spectrum import SpectrumSpec
from .screening import ScreeningSpec, confirmed_trials, screened_ranking
from .sweep import CaseSpec, case_scenarios, check_base, check_mode, connect_scheduler, run_case, sweep_inputs

# a trial's reason when the study stopped while it ran
INTERRUPTED = "interrupted"
# a best value this close to a variable's bound (a share of its range, of its log for a log
# variable) is reported as at the bound: the optimum may lie outside the range searched
BOUND_SHARE = 0.01
# a target objective whose best misfit |m / target - 1| exceeds this (unless the objective sets
# its own `tolerance`) is reported as missed
TARGET_TOLERANCE = 0.01
# the design fields that do not define a study: a folder's study continues when only these change
NOT_DEFINING = ("name", "description", "trials")


def _trial_constraints() -> bool:
    """Whether this Optuna stores constraints on the trial (5.0 on) rather than through a
    sampler's constraints_func (deprecated there)."""
    try:
        from optuna.trial import Trial
    except ImportError:  # pragma: no cover - optuna is a dependency
        return False
    return hasattr(Trial, "set_constraint")


TRIAL_CONSTRAINTS = _trial_constraints()


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
        if (self.mode == "spectrum") != (self.frequencies is not None):
            raise ValueError("frequencies: a design in spectrum mode needs its band's frequencies [Hz], and only "
                             "that mode takes them")
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


def evaluate_trial(spec_json: str, base_dir: str, case: dict, out_dir: str, keep_runs: bool = False) -> dict:
    """A trial on a worker: the cases its mode runs for it (`StudyMode.trial_cases`), each by
    the sweep engine's `run_case` (metrics only, unless `keep_runs`). A trial of one case is that
    case's result; a trial of several (a spectrum's band) has their combined metrics
    (`StudyMode.trial_metrics`), and any case failing fails it, saying where. `reused`: every
    case was a stored result (`_timed_case`)."""
    spec = DesignSpec.model_validate_json(spec_json)
    mode = study_mode(spec.mode)
    parts = mode.trial_cases(spec, case)
    if parts == [(case, "")]:  # the trial is its case: run_case's result as it is (its notes too)
        return _timed_case(spec_json, base_dir, case, out_dir, keep_runs)
    start = time.perf_counter()
    res = {"tag": case["tag"], "index": case["index"], "overrides": case["overrides"], "solver_s": 0.0, "reused": True,
           "parts": {}}
    per = []
    for sub, where in parts:
        r = _timed_case(spec_json, base_dir, sub, out_dir, keep_runs)
        res["solver_s"] += float(r.get("solver_s", 0.0))
        res["reused"] = res["reused"] and r["reused"]
        for k, v in r.get("parts", {}).items():
            res["parts"][k] = res["parts"].get(k, 0.0) + float(v)
        if r.get("status") != "ok":
            res["status"] = f"{r.get('status')} ({where})"
            break
        per.append(r["metrics"])
    else:
        res["metrics"] = mode.trial_metrics(spec, per)
        res["status"] = "ok"
    res["wall_s"] = time.perf_counter() - start
    return res


def _timed_case(spec_json: str, base_dir: str, case: dict, out_dir: str, keep_runs: bool) -> dict:
    """`run_case`, with the times of this call: a case whose stored result was returned (the
    same values asked again) reports the stored run's times, longer than the call itself; it
    is marked `reused`, with this call's wall time and no solver time."""
    start = time.perf_counter()
    r = run_case(spec_json, base_dir, case, out_dir, keep_runs)
    took = time.perf_counter() - start
    reused = float(r.get("wall_s", 0.0)) > took  # a fresh case's wall_s is measured within this call
    return {**r, "reused": reused, **({"wall_s": took, "solver_s": 0.0, "parts": {}} if reused else {})}


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
        if sc.solid is not None and sc.solid.kind in ("beam", "plate"):
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


def trial_case(spec: DesignSpec, number: int, params: dict) -> dict:
    """A trial as a sweep case: its overrides and a tag named by its values (so that a replayed
    trial, or a repeated design, finds its finished case)."""
    overrides = {f: _value(params[v.field]) for v in spec.variables for f in v.fields}
    digest = hashlib.sha1(json.dumps(overrides, sort_keys=True, default=repr).encode()).hexdigest()[:12]
    return {"index": [number], "overrides": overrides, "tag": f"trial-{digest}"}


def make_sampler(spec: DesignSpec, seed: int):
    """Optuna's sampler for this design, seeded with `seed` (under "auto": TPE then a local
    refinement for one objective, no constraints and continuous variables (`refines`), TPE for
    one objective otherwise, NSGA-II for several; constraints through Optuna's
    constraints_func)."""
    import optuna

    # constraints: stored on each trial (Trial.set_constraint, Optuna 5) or read by constraints_func (Optuna 4)
    cons = (lambda t: t.user_attrs["constraints"]) if spec.constraints and not TRIAL_CONSTRAINTS else None
    kind = spec.sampler
    if kind == "auto":
        kind = "tpe" if len(spec.objectives) == 1 else "nsga2"
    if kind == "tpe":
        tpe = optuna.samplers.TPESampler(seed=seed, multivariate=True, constraints_func=cons,
                                         n_startup_trials=tpe_startup(spec))
        return refining_sampler(spec, tpe) if refines(spec) else tpe
    if kind == "cmaes":
        return optuna.samplers.CmaEsSampler(seed=seed, warn_independent_sampling=False)
    if kind == "nsga2":
        return optuna.samplers.NSGAIISampler(seed=seed, constraints_func=cons, population_size=nsga2_population(spec))
    return optuna.samplers.RandomSampler(seed=seed)


def tpe_startup(spec: DesignSpec) -> int:
    """TPE's random trials before it models the study."""
    return min(10, max(3, spec.trials // 5))


def refines(spec: DesignSpec) -> bool:
    """Whether the design's sampler refines locally after its global phase (`studies.refine`):
    `auto`, one objective, no constraints, every variable continuous."""
    return (spec.sampler == "auto" and len(spec.objectives) == 1 and not spec.constraints
            and all(v.kind == "float" for v in spec.variables))


def refining_sampler(spec: DesignSpec, global_sampler):
    """TPE for the study's first third (`refine.global_trials`), then the local refinement."""
    from . import refine

    o = spec.objectives[0]
    goal = refine.Goal(o.metric, o.target, 1.0 if o.sense == "minimize" else -1.0)
    scales = [refine.Scale(v.field, float(v.low), float(v.high), v.log) for v in spec.variables]
    return refine.RefiningSampler(global_sampler, scales, goal, refine.global_trials(spec.trials, tpe_startup(spec)))


def nsga2_population(spec: DesignSpec) -> int:
    """NSGA-II's generation size: `population`, or about a sixth of the trials (between 8 and
    50, Optuna's default), so that a study runs several generations."""
    return spec.population or int(min(50, max(8, spec.trials // 6)))


def trial_seed(seed: int, finished: int) -> int:
    """The sampler seed of the trial asked after `finished` trials."""
    return int(hashlib.sha256(f"{seed}:{finished}".encode()).hexdigest()[:8], 16)


def ask_trial(study, spec: DesignSpec, dists: dict):
    """The next trial: a queued one (a replay) or new values from a sampler seeded by the
    design's seed and the number of trials finished or running (so that trials asked side by
    side for several workers differ, and one worker's sequence does not depend on the trial
    numbers an interruption used up)."""
    from optuna.trial import TrialState

    running = len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)))
    study.sampler = make_sampler(spec, trial_seed(spec.seed, finished_trials(study) + running))
    return study.ask(fixed_distributions=dists)


def design_inputs(spec: DesignSpec, base_dir: Path) -> dict[str, str]:
    """The contents' digests of what every trial reads: the base scenario (a built-in's text, or
    its file) and every granule or load table it names (`sweep.sweep_inputs`)."""
    from importlib import resources

    from ..guard.fingerprints import file_digest, text_digest

    out = {}
    if spec.base in S.builtin_names():
        out[f"built-in {spec.base}"] = text_digest(resources.files("granel.scenario").joinpath("builtin")
                                                   .joinpath(f"{spec.base}.toml").read_text())
    for p in sweep_inputs(spec, base_dir):
        out[str(p)] = file_digest(p)
    return out


def open_study(spec: DesignSpec, out: Path, base_dir: Path | None = None):
    """The design's Optuna study in out/study.journal, created or continued. A folder that holds
    a study of another design is refused (DesignFileError naming each field that differs, with
    its stored and its new value; `design_differences`), and so is a study whose inputs (the base
    scenario, its tables: `design_inputs`, when `base_dir` is given) changed since it began."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = JournalStorage(JournalFileBackend(str(out / "study.journal")))
    study = optuna.create_study(study_name="granel-design", storage=storage, directions=spec.directions,
                                load_if_exists=True)
    mine = json.loads(spec.model_dump_json())
    held = study.user_attrs.get("design")
    diff = design_differences(held, mine) if held is not None else []
    if diff:
        said = "; ".join(f"{f}: {_short(a)} there, {_short(b)} here" for f, a, b in diff)
        raise DesignFileError(f"-o {out}: it holds a study of another design ({said}); write this one to another "
                              "folder, or restore those fields")
    if base_dir is not None:
        from ..guard.fingerprints import changed

        now, before = design_inputs(spec, base_dir), study.user_attrs.get("inputs")
        moved = changed(before, now) if isinstance(before, dict) else []
        if moved:
            raise DesignFileError(f"-o {out}: the study's inputs changed since it began ({', '.join(moved)}): its trials "
                                  "would mix the old and the new; restore them, or write this study to another folder")
        if before != now:
            study.set_user_attr("inputs", now)
    if held != mine:
        study.set_user_attr("design", mine)  # the latest name, description, budget and tolerances
    return study


def _short(v, width: int = 60) -> str:
    text = "(unset)" if v is _UNSET else json.dumps(v)
    return text if len(text) <= width else text[: width - 3] + "..."


_UNSET = object()


def _defaults(model) -> dict:
    """A pydantic model's field defaults, as JSON values."""
    from pydantic_core import PydanticUndefined, to_json

    out = {}
    for name, f in model.model_fields.items():
        d = f.get_default(call_default_factory=True)
        if d is not PydanticUndefined:
            out[name] = json.loads(to_json(d))
    return out


def design_differences(held: dict, mine: dict) -> list[tuple[str, Any, Any]]:
    """The fields that define a study and differ between a stored design (JSON) and this one:
    [(dotted field, stored value, this value)]. Every field defines it but NOT_DEFINING and the
    objectives' `tolerance` (they change no trial); a field the stored design lacks (added by a
    later granel) counts as its default."""
    child = {"variables": VariableSpec, "objectives": ObjectiveSpec, "constraints": ConstraintSpec,
             "spectrum": SpectrumSpec}
    skip = {"objectives": ("tolerance",)}
    out: list[tuple[str, Any, Any]] = []

    def walk(path: str, a, b, model, ignore=()):
        if model is not None and isinstance(a, dict) and isinstance(b, dict):
            d = _defaults(model)
            for key in dict.fromkeys([*a, *b]):
                if key in ignore:
                    continue
                top = model is DesignSpec
                walk(f"{path}.{key}" if path else key, a.get(key, d.get(key, _UNSET)), b.get(key, d.get(key, _UNSET)),
                     child.get(key) if top else None, skip.get(key, ()) if top else ())
        elif model is not None and isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                out.append((f"{path} (count)", len(a), len(b)))
            else:
                for k, (x, y) in enumerate(zip(a, b)):
                    walk(f"{path}.{k}", x, y, model, ignore)
        elif a != b:
            out.append((path, a, b))

    walk("", held, mine, DesignSpec, NOT_DEFINING)
    return out


def same_design(held: dict, mine: dict) -> bool:
    """Whether a stored design (as JSON) defines the same study as this one (`design_differences`)."""
    return not design_differences(held, mine)


def recover_interrupted(study) -> int:
    """Mark the trials left running by a stopped study as failed ("interrupted") and queue their
    values again; returns how many."""
    from optuna.trial import TrialState

    stale = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
    for t in stale:
        study._storage.set_trial_user_attr(t._trial_id, "reason", INTERRUPTED)
        study.tell(t.number, state=TrialState.FAIL, skip_if_finished=True)
        study.enqueue_trial(t.params, user_attrs={"replay_of": t.number}, skip_if_exists=False)
    return len(stale)


def finished_trials(study) -> int:
    """Trials that count toward the study's size: complete, or failed for their own reason."""
    from optuna.trial import TrialState

    n = 0
    for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.FAIL)):
        n += t.user_attrs.get("reason") != INTERRUPTED
    return n


def score(spec: DesignSpec, result: dict) -> tuple[list[float] | None, list[float], str]:
    """(objective values or None, constraint violations, reason) of a finished case."""
    if result.get("status") != "ok":
        return None, [], str(result.get("status", "error: no result"))
    metrics = result.get("metrics", {})
    try:
        values = [o.value(metrics) for o in spec.objectives]
        cons = [c.violation(metrics) for c in spec.constraints]
    except MetricError as e:
        note = result.get("notes", {}).get(e.metric)  # why the case could not measure it
        return None, [], f"error: {e}" + (f": {note}" if note else "")
    return values, cons, "ok"


def tell(study, spec: DesignSpec, trial, result: dict) -> str:
    """Record a finished case as the trial's result; returns its status."""
    from optuna.trial import TrialState

    values, cons, reason = score(spec, result)
    trial.set_user_attr("tag", result.get("tag", ""))
    trial.set_user_attr("reused", bool(result.get("reused", False)))
    for key in ("wall_s", "solver_s", "turnaround_s"):
        trial.set_user_attr(key, float(result.get(key, float("nan"))))
    trial.set_user_attr("parts", {k: float(v) for k, v in result.get("parts", {}).items()})
    trial.set_user_attr("metrics", {k: float(v) for k, v in result.get("metrics", {}).items()
                                    if isinstance(v, (int, float))})
    trial.set_user_attr("reason", reason)
    if values is None:
        study.tell(trial, state=TrialState.FAIL)
        return reason
    trial.set_user_attr("constraints", cons)
    if TRIAL_CONSTRAINTS:
        for k, (c, v) in enumerate(zip(spec.constraints, cons)):
            trial.set_constraint(f"{k}:{c.metric}", v)
    study.tell(trial, values if len(values) > 1 else values[0])
    return reason


def confirm_best(spec: DesignSpec, study, client, base_dir: str, out: Path, confirming=None) -> None:
    """Run a screened study's `screening.confirm` best trials (`screened_ranking`) again at the
    design's own accuracy, on the study's workers; each one's objective values, constraint
    violations and reason go to the study's `confirmed` attribute (by trial number), so that a
    rerun confirms only what is missing."""
    if spec.screening is None:
        return
    from dask.distributed import as_completed

    done = dict(study.user_attrs.get("confirmed", {}))
    best = screened_ranking(spec, study)[: spec.screening.confirm]
    todo = [t for t in best if str(t.number) not in done]
    spec_json = spec.model_dump_json()  # the design's own accuracy
    futures = {}
    for t in todo:
        case = trial_case(spec, t.number, t.params)
        case["tag"] = f"{case['tag']}-confirmed"
        futures[client.submit(evaluate_trial, spec_json, base_dir, case, str(out.resolve()), pure=False,
                              key=f"granel-confirm-{t.number}-{time.time_ns()}")] = t
    for k, fut in enumerate(as_completed(list(futures)), start=len(best) - len(todo) + 1):
        t = futures[fut]
        try:
            r = dict(fut.result())
        except Exception as e:  # noqa: BLE001 - a failed confirmation is recorded as failed
            r = {"status": f"error: task failed: {type(e).__name__}: {e}"}
        values, cons, reason = score(spec, r)
        done[str(t.number)] = {"values": values, "constraints": cons, "reason": reason,
                               "wall_s": float(r.get("wall_s", float("nan")))}
        study.set_user_attr("confirmed", done)
        if confirming is not None:
            confirming(k, len(best))


def run_design(spec: DesignSpec, base_dir: Path, out_dir, trials: int | None = None, workers: int = 2,
               scheduler: str | None = None, timeout: float = 60.0, max_wall: float | None = None,
               progress=None, check: bool = True, confirming=None, finishing=None) -> dict:
    """Run (or continue) the study until `trials` trials (default: the design's) have finished,
    on a LocalCluster of `workers` processes or the scheduler at `scheduler`; stop launching
    trials after `max_wall` seconds (the ones in flight are given up: a rerun repeats them).
    `check_design` runs first unless `check` is false (the caller ran it). A screened design's
    best trials are then confirmed (`confirm_best`, `confirming(done, total)` after each), and
    `finishing(study, client)` runs on the same workers when the study is complete. Writes trials.nc and
    the best designs (`write_outputs`; the figures and report.md are
    `design_report.write_study_report`'s); returns {"study", "trials", "stopped", "files", "best",
    "warnings"} (`design_warnings`)."""
    from dask.distributed import Client, as_completed

    from ..guard.signals import local_cluster

    if not scheduler and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
    target = int(trials or spec.trials)
    if check:
        check_design(spec, base_dir)
    client = connect_scheduler(scheduler, timeout) if scheduler else None  # a bad scheduler fails before anything is written
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        study = open_study(spec, out, base_dir)
        recover_interrupted(study)
    except BaseException:
        if client is not None:
            client.close()
        raise
    dists = {v.field: v.distribution() for v in spec.variables}
    spec_json = spec.screened().model_dump_json()  # the trials' accuracy
    base = str(base_dir.resolve())
    start = time.monotonic()
    cluster = None
    if client is None:
        cluster = local_cluster(workers)
        client = Client(cluster)
    started = time.monotonic() - start  # the workers' start (a LocalCluster's processes and imports)
    slots = max(1, len(client.scheduler_info()["workers"]))
    in_flight: dict = {}
    stopped = False

    def launch():
        trial = ask_trial(study, spec, dists)
        case = trial_case(spec, trial.number, trial.params)
        fut = client.submit(evaluate_trial, spec_json, base, case, str(out.resolve()), pure=False,
                            key=f"granel-design-{trial.number}-{case['tag']}-{time.time_ns()}")
        in_flight[fut] = (trial, case, time.monotonic())
        return fut

    done = first = finished_trials(study)
    wall = 0.0
    try:
        pending = as_completed([launch() for _ in range(min(slots, max(0, target - done)))])
        for fut in pending:
            trial, case, launched = in_flight.pop(fut)
            try:
                r = dict(fut.result())
            except OSError:
                raise
            except Exception as e:  # noqa: BLE001 - e.g. KilledWorker: the trial failed, the study goes on
                r = {"tag": case["tag"], "status": f"error: task failed: {type(e).__name__}: {e}"}
            r["turnaround_s"] = time.monotonic() - launched  # launch to result, as the study sees it
            status = tell(study, spec, trial, r)
            done += 1
            if progress is not None:
                progress(trial.number, status, done, target)
            if max_wall is not None and time.monotonic() - start > max_wall:
                stopped = True
                break
            if done + len(in_flight) < target:
                pending.add(launch())
        if not stopped and done >= target:
            confirm_best(spec, study, client, base, out, confirming)
        wall = time.monotonic() - start  # the study's session: its trials and their confirmations
        if not stopped and done >= target and finishing is not None:
            finishing(study, client)
    finally:
        for fut in in_flight:
            fut.cancel()
        client.close()
        if cluster is not None:
            cluster.close()
    sessions = list(study.user_attrs.get("sessions", []))
    sessions.append({"wall_s": wall, "trials": done - first, "workers": slots, "start_s": started})
    study.set_user_attr("sessions", sessions)
    written = write_outputs(spec, base_dir, study, out)
    return {"study": study, "trials": written["trials"], "stopped": stopped, "files": written["files"],
            "best": written["best"], "warnings": written["warnings"]}


# ---------------------------------------------------------------- outputs


def trials_dataset(spec: DesignSpec, study):
    """Every trial: its variables, objectives, constraint violations, feasibility, status,
    reason, wall time and metrics, along `trial` (Optuna's trial number)."""
    import xarray as xr
    from optuna.trial import TrialState

    ts = [t for t in study.get_trials(deepcopy=False) if t.state != TrialState.WAITING]
    n = len(ts)
    data: dict[str, Any] = {}
    for v in spec.variables:
        vals = [_value(t.params.get(v.field)) for t in ts]
        if v.kind == "categorical":
            data[f"var_{v.field}"] = ("trial", np.array([json.dumps(x) if not isinstance(x, str) else x for x in vals], dtype=str))
        else:
            data[f"var_{v.field}"] = ("trial", np.array([np.nan if x is None else float(x) for x in vals]))
    for k, o in enumerate(spec.objectives):
        data[f"objective_{o.name}"] = ("trial", np.array([t.values[k] if t.state == TrialState.COMPLETE else np.nan
                                                         for t in ts], float))
    if spec.screening is not None:  # the confirmed trials' values at the design's own accuracy (NaN: not confirmed)
        held = study.user_attrs.get("confirmed", {})
        for k, o in enumerate(spec.objectives):
            values = [(held.get(str(t.number)) or {}).get("values") for t in ts]
            data[f"confirmed_{o.name}"] = ("trial", np.array([v[k] if v else np.nan for v in values], float),
                                           {"long_name": f"{o.name} at the design's own accuracy (screened trials confirmed)"})
    for k, c in enumerate(spec.constraints):
        data[f"constraint_{c.metric}"] = ("trial", np.array([t.user_attrs.get("constraints", [np.nan] * len(spec.constraints))[k]
                                                            for t in ts], float))
    feasible = [t.state == TrialState.COMPLETE and all(c <= 0 for c in t.user_attrs.get("constraints", [])) for t in ts]
    data["feasible"] = ("trial", np.array(feasible, bool))
    data["status"] = ("trial", np.array([_status(t) for t in ts], dtype=str))
    data["reason"] = ("trial", np.array([str(t.user_attrs.get("reason", "")) for t in ts], dtype=str))
    data["reused"] = ("trial", np.array([bool(t.user_attrs.get("reused", False)) for t in ts], bool),
                      {"long_name": "the trial's values had been run: its case's stored result was used"})
    for key, what in (("wall_s", "the case's time in its worker"), ("solver_s", "its runs' time in the solver"),
                      ("turnaround_s", "launch to result, as the study saw it")):
        data[key] = ("trial", np.array([t.user_attrs.get(key, np.nan) for t in ts], float), {"units": "s", "long_name": what})
    names = sorted({k for t in ts for k in t.user_attrs.get("metrics", {})})
    for m in names:
        data[f"metric_{m}"] = ("trial", np.array([t.user_attrs.get("metrics", {}).get(m, np.nan) for t in ts], float))
    ds = xr.Dataset(data, coords={"trial": np.array([t.number for t in ts], int)})
    ds.attrs.update({"design": spec.model_dump_json(), "name": spec.name, "directions": json.dumps(spec.directions),
                     "trials": n, "warnings": json.dumps(design_warnings(spec, study, best_trials(spec, study)))})
    return ds


def design_warnings(spec: DesignSpec, study, best: list) -> list[str]:
    """What a reader must know about a study's best designs: a variable at a bound (within
    BOUND_SHARE of its range: the optimum may lie beyond it), a target missed (the best misfit
    above the objective's tolerance; on a Pareto front, by every design of it), no finished trial
    meeting the constraints."""
    from optuna.trial import TrialState

    if not best:
        done = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
        return ["no finished trial meets the constraints: there is no best design"] if done and spec.constraints else []
    out = []
    front = len(spec.objectives) > 1
    for var in spec.variables:
        sides: dict[str, list] = {}
        for t in best:
            side = var.bound_of(_value(t.params.get(var.field)))
            if side is not None:
                sides.setdefault(side, []).append(t)
        for side, ts in sides.items():
            bound = var.low if side == "low" else var.high
            where = f"{len(ts)} of the {len(best)} Pareto designs" if front else f"the best design (trial {ts[0].number})"
            value = "" if front else f" = {_fmt_value(ts[0].params[var.field])}"
            out.append(f"{var.field}{value} in {where} is at its {side} bound {bound:g} (within {100 * BOUND_SHARE:g} % of "
                       f"the range{', on the log scale' if var.log else ''}): the optimum may lie outside the range")
    for k, o in enumerate(spec.objectives):
        if o.target is None:
            continue
        t = min(best, key=lambda t: t.values[k])
        if t.values[k] > o.met_within:
            m = t.user_attrs.get("metrics", {}).get(o.metric, math.nan)
            who = "no design of the Pareto front meets" if front else "the best design misses"
            out.append(f"{who} the target {o.metric} = {o.target:g}: trial {t.number} gives {m:.6g}, a misfit "
                       f"|m / target - 1| of {t.values[k]:.3g} (tolerance {o.met_within:g})")
    return out


def _status(t) -> str:
    from optuna.trial import TrialState

    if t.state == TrialState.COMPLETE:
        return "ok"
    if t.state == TrialState.RUNNING:
        return "running"
    return t.user_attrs.get("reason", "error") if t.user_attrs.get("reason") == INTERRUPTED else "failed"


def best_trials(spec: DesignSpec, study) -> list:
    """The best feasible trial (one objective) or the feasible Pareto front (several), best
    first / in order of the first objective; for a screened study, among its confirmed trials,
    by their values at the design's own accuracy (`confirmed_trials`)."""
    from optuna.trial import TrialState

    ok = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
          if all(c <= 0 for c in t.user_attrs.get("constraints", []))]
    if spec.screening is not None and study.user_attrs.get("confirmed"):  # the best at the design's own accuracy
        ok = [t for t in confirmed_trials(spec, study) if all(c <= 0 for c in t.constraints)]
    if not ok:
        return []
    signs = np.array([1.0 if d == "minimize" else -1.0 for d in spec.directions])
    if len(spec.objectives) == 1:
        return [min(ok, key=lambda t: signs[0] * t.values[0])]
    v = np.array([t.values for t in ok]) * signs
    front = [t for k, t in enumerate(ok) if not any(np.all(v[j] <= v[k]) and np.any(v[j] < v[k]) for j in range(len(ok)))]
    return sorted(front, key=lambda t: signs[0] * t.values[0])


def design_scenario(spec: DesignSpec, base_dir: Path, params: dict) -> S.Scenario:
    """The runnable scenario of a trial: the base, the design's overrides and the trial's values
    (no values: the base scenario as the design runs it)."""
    values = trial_case(spec, 0, params)["overrides"] if params else {}
    return S.load(spec.base_path(base_dir), [*spec.overrides, *(S.override(k, v) for k, v in values.items())])


def _write_text(path: Path, text: str) -> None:
    from ..guard.writing import write_text

    write_text(path, text)


HEADER = "# written by granel design"


def write_outputs(spec: DesignSpec, base_dir: Path, study, out: Path) -> dict:
    """trials.nc (with the study's `design_warnings` as its `warnings` attribute), and best.toml
    (one objective) or pareto/NN.toml (several): each a scenario that `granel run` takes as it
    is, headed by its trial and objective values. Stale pareto/NN.toml
    files of this study (headed as granel design writes them) are removed; no other file is."""
    from ..io.results import write_netcdf

    ds = trials_dataset(spec, study)
    write_netcdf(ds, out / "trials.nc")
    files = [out / "trials.nc"]
    best = best_trials(spec, study)

    def scenario_text(t) -> str:
        values = ", ".join(f"{o.name} = {v:.6g}" for o, v in zip(spec.objectives, t.values))
        sc = design_scenario(spec, base_dir, t.params)
        return f"{HEADER} {spec.name!r}: trial {t.number}; {values}\n" + S.to_toml(sc)

    if len(spec.objectives) == 1:
        if best:
            _write_text(out / "best.toml", scenario_text(best[0]))
            files.append(out / "best.toml")
    else:
        folder = out / "pareto"
        folder.mkdir(exist_ok=True)
        keep = set()
        for k, t in enumerate(best):
            path = folder / f"{k:02d}.toml"
            _write_text(path, scenario_text(t))
            keep.add(path.name)
            files.append(path)
        for old in folder.glob("[0-9][0-9].toml"):
            if old.name not in keep and old.read_text().startswith(HEADER):
                old.unlink()
    return {"trials": ds, "files": files, "best": best, "warnings": json.loads(ds.attrs["warnings"])}
