"""A design's trials: one trial as a sweep case (`trial_case`, `evaluate_trial`: its variables'
values as overrides on top of the design's, its cases run by `sweep.run_case`; an invalid design
is a failed trial with its reason, and the study goes on), what the study stores of it (`score`,
`tell`), and what the study leaves: trials.nc, the best designs (`best_trials`, `write_outputs`)
and what a reader must know of them (`design_warnings`)."""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import scenario as S
from .design import BOUND_SHARE, DesignSpec, MetricError, _fmt_value, _value
from .modes import study_mode
from .screening import confirmed_trials
from .sweep import run_case

# a trial's reason when the study stopped while it ran
INTERRUPTED = "interrupted"


def _trial_constraints() -> bool:
    """Whether this Optuna stores constraints on the trial (5.0 on) rather than through a
    sampler's constraints_func (deprecated there)."""
    try:
        from optuna.trial import Trial
    except ImportError:  # pragma: no cover - optuna is a dependency
        return False
    return hasattr(Trial, "set_constraint")


TRIAL_CONSTRAINTS = _trial_constraints()


def trial_case(spec: DesignSpec, number: int, params: dict) -> dict:
    """A trial as a sweep case: its overrides and a tag named by its values (so that a replayed
    trial, or a repeated design, finds its finished case)."""
    overrides = {f: _value(params[v.field]) for v in spec.variables for f in v.fields}
    digest = hashlib.sha1(json.dumps(overrides, sort_keys=True, default=repr).encode()).hexdigest()[:12]
    return {"index": [number], "overrides": overrides, "tag": f"trial-{digest}"}


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
    first / in order of the first objective, each design once (a sampler that asks for values
    already run, as NSGA-II does, leaves the first trial that ran them); for a screened study,
    among its confirmed trials, by their values at the design's own accuracy (`confirmed_trials`)."""
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
    first: dict = {}
    for t in sorted(front, key=lambda t: t.number):
        first.setdefault(repr(sorted(t.params.items())), t)
    return sorted(first.values(), key=lambda t: signs[0] * t.values[0])


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
