"""The design search: the Optuna study of a design (`run_design`), its trials run by the sweep
engine on dask.distributed workers, its samplers (`make_sampler`) and its journal
DIR/study.journal (`open_study`): a rerun continues it, a trial interrupted in flight is run
again with the same values, and each trial's sampler is seeded from the design's seed and the
number of trials finished before it. A screened study's best trials are confirmed here
(`confirm_best`)."""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import scenario as S
from .design import ConstraintSpec, DesignFileError, DesignSpec, ObjectiveSpec, VariableSpec, check_design
from .design_trials import INTERRUPTED, TRIAL_CONSTRAINTS, evaluate_trial, score, tell, trial_case, write_outputs
from .screening import screened_ranking
from .spectrum import SpectrumSpec
from .sweep import connect_scheduler, sweep_inputs

# the design fields that do not define a study: a folder's study continues when only these change
NOT_DEFINING = ("name", "description", "trials")


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


@dataclass(frozen=True)
class DesignRunOptions:
    """How `run_design` runs a study: on a LocalCluster of `workers` processes, or on the
    scheduler at `scheduler` (connected within `timeout` seconds); no trial is launched after
    `max_wall` seconds (None: no limit). `progress(number, status, done, total)` is called after
    each trial, `confirming(done, total)` after each confirmation of a screened design's best,
    and `finishing(study, client)` on the same workers once the study is complete."""

    workers: int = 2
    scheduler: str | None = None
    timeout: float = 60.0
    max_wall: float | None = None
    progress: Callable[[int, str, int, int], None] | None = None
    confirming: Callable[[int, int], None] | None = None
    finishing: Callable[[Any, Any], None] | None = None


def run_design(spec: DesignSpec, base_dir: Path, out_dir, trials: int | None = None,
               options: DesignRunOptions = DesignRunOptions(), check: bool = True) -> dict:
    """Run (or continue) the study until `trials` trials (default: the design's) have finished,
    on the workers of `options` (`DesignRunOptions`); stop launching trials after its `max_wall`
    seconds (the ones in flight are given up: a rerun repeats them). `check_design` runs first
    unless `check` is false (the caller ran it). A screened design's best trials are then
    confirmed (`confirm_best`, `options.confirming(done, total)` after each), and
    `options.finishing(study, client)` runs on the same workers when the study is complete.
    Writes trials.nc and the best designs (`design_trials.write_outputs`; the figures and
    report.md are `design_report.write_study_report`'s); returns {"study", "trials", "stopped",
    "files", "best", "warnings"} (`design_trials.design_warnings`)."""
    from dask.distributed import Client, as_completed

    from ..guard.signals import local_cluster

    workers, scheduler, timeout, max_wall = options.workers, options.scheduler, options.timeout, options.max_wall
    progress, confirming, finishing = options.progress, options.confirming, options.finishing
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
