"""Scenario -> built problem -> solver -> driver -> trajectory -> result Dataset, and the run summary.

This is the one place that knows both the scenario and the solvers: below it, solvers receive
built objects (`problem.Problem`); above it, figures and analysis read result Datasets and the
model record each carries (`io.model`). Results of an earlier granel, without a record, get one
here from their stored scenario (`legacy_model_record`).
May import: scenario, problem, analysis, coupling, solid, granular, io, guard."""

from __future__ import annotations

import time
import tomllib
from pathlib import Path

import numpy as np

from . import scenario as S
from .guard.exits import STOPPED, GranelError, NotWritten
from .io.checkpoint import CheckpointError, fingerprint
from .coupling.driver import drive
from .problem import Problem
from .io.results import write_spec_netcdf
from .io.run_result import base_attrs, trajectory_spec
from .analysis.balance import balance_scale, relative_balance_error


def make_solver(problem: Problem, sparse: bool | None = None):
    """The solver of a built problem (`coupling.protocol.Solver`), its modes fetched: the fast
    method's exact integrator with the modes below its cut-off (for solids beyond
    `solid.modal.DENSE_LIMIT` DOFs, or with `simulation.modes = "below_cutoff"`, only those are
    computed, at most `problem.max_modes` for the former);
    Newmark (the paper's method, or `integrator = "newmark"`) on all modes, none for a rigid
    solid, or sparse Newmark for solids too large for all modes (`sparse` forces either)."""
    from .coupling.modal import ModalSolver
    from .solid.modal import DENSE_LIMIT
    from .solid.mode_cache import all_modes, modes_below

    solid, settings = problem.solid, problem.settings
    large = sparse if sparse is not None else solid.ndof > DENSE_LIMIT
    if settings.method == "fast" and settings.integrator == "exact" and not sparse:
        from .coupling.exact.solver import ExactSolver

        modes = None
        if solid.ndof and large:
            modes = modes_below(solid, float(settings.mode_cutoff), problem.max_modes)
        elif solid.ndof and settings.modes == "below_cutoff":
            modes = modes_below(solid, float(settings.mode_cutoff))
        elif solid.ndof:
            modes = all_modes(solid)
        return ExactSolver(problem, modes)
    if large:
        from .coupling.sparse import SparseSolver

        return SparseSolver(problem)
    return ModalSolver(problem, all_modes(solid) if solid.ndof else None)


def run_problem(problem: Problem, progress=None, checkpoint=None, resume=None, sparse: bool | None = None,
                max_wall: float | None = None, dataset: bool = True):
    """Solve a built problem and return its result Dataset (a `io.results.ResultSpec` with
    dataset=False: no xarray needed), after at most `max_wall` seconds of solving
    (`coupling.driver.WallTimeExceeded` beyond)."""
    from .guard.fingerprints import encode

    start = time.perf_counter()
    solver = make_solver(problem, sparse)
    setup_s = time.perf_counter() - start
    # what a checkpoint resumes: the scenario, the method and the contents of the files it reads
    fp = fingerprint(problem.source + problem.settings.method + (encode(problem.inputs) if problem.inputs else ""))
    traj = drive(solver, problem.schedule, progress=progress, checkpoint=checkpoint, resume=resume, fingerprint=fp,
                 guards=problem.guards, max_wall=max_wall, stored=problem.stored)
    solid = problem.solid
    steps = traj.step_series("h")
    its = traj.step_series("iterations").astype(float)
    info = {**traj.solver, "setup_s": setup_s, "steps": int(len(steps)), "min_step": float(steps.min()) if len(steps) else problem.settings.dt,
            "mean_iterations": float(its.mean()) if len(its) else 0.0, "max_iterations_used": int(its.max()) if len(its) else 0}
    attrs = base_attrs(problem.source, info)
    if problem.inputs:
        attrs["input_files"] = encode(problem.inputs)
        attrs["input_texts"] = encode(problem.input_texts)
    attrs.update(problem.equilibrium or {})
    omega = solver.modes.omega if solver.modes is not None else None
    spec = trajectory_spec(traj, problem.system, solid, attrs, omega)
    if problem.equilibrium_contacts is not None:  # the static equilibrium, contact by contact
        names, force, overlap = problem.equilibrium_contacts
        spec.coords["equilibrium_contact"] = ("equilibrium_contact", np.array(names, dtype=object))
        spec.data["equilibrium_force"] = ("equilibrium_contact", np.asarray(force, float),
                                          {"units": "N", "long_name": "normal force of each loaded contact at the static equilibrium"})
        spec.data["equilibrium_overlap"] = ("equilibrium_contact", np.asarray(overlap, float),
                                            {"units": "m", "long_name": "its overlap (eq. 2)"})
    return spec.to_dataset() if dataset else spec


def run_scenario(sc: S.Scenario, progress=None, checkpoint=None, resume=None, max_wall: float | None = None,
                 dataset: bool = True):
    """Run a validated scenario and return its result Dataset (or `io.results.ResultSpec`); its
    `build_s` attribute is the time building the problem took."""
    start = time.perf_counter()
    problem = S.build_problem(sc)
    build_s = time.perf_counter() - start
    result = run_problem(problem, progress, checkpoint, resume, max_wall=max_wall, dataset=dataset)
    result.attrs["build_s"] = build_s
    return result


class RunStopped(GranelError):
    """A run that its solver, the driver or a guard stopped (exit 3): "`what` stopped: the
    RuntimeError" (the error is the cause)."""

    code = STOPPED

    def __init__(self, what: str, cause: BaseException):
        super().__init__(f"{what} stopped: {cause}")


def run_to_file(sc: S.Scenario, output, progress=None, checkpoint=None, resume=None,
                max_wall: float | None = None) -> dict:
    """Run a validated scenario (`run_scenario`, without xarray), write its result to `output`
    atomically, remove the run's checkpoint (the result replaces it), and return the result's
    `summarize` with its `output`. A RuntimeError of the run is RunStopped (a checkpoint's
    CheckpointError passes as it is), a failed write NotWritten."""
    try:
        spec = run_scenario(sc, progress, checkpoint=checkpoint, resume=resume, max_wall=max_wall, dataset=False)
    except CheckpointError:
        raise
    except RuntimeError as e:
        raise RunStopped("run", e) from e
    try:
        write_spec_netcdf(spec, output)
    except OSError as e:
        raise NotWritten("the result", output, e) from e
    ckpt = None if checkpoint is None else Path(checkpoint)
    if ckpt is not None and ckpt.exists() and (sc.simulation.checkpoint_every > 0 or resume is not None):
        ckpt.unlink()  # the result replaces the checkpoint this run wrote or resumed from
    summary = summarize(spec)
    summary["output"] = str(output)
    return summary


def plan_run_outputs(output: Path, sc: S.Scenario, source: str, resume: Path | None) -> Path:
    """The result and checkpoint paths of a run of `sc` (read from `source`), checked before any
    computation (`guard.outputs`; its disk use by `scenario.estimate.run_needs`) and their folder
    made: the checkpoint is the result's name with .ckpt; an existing one is only ever replaced
    or removed by the run that resumes from it. Returns the checkpoint's path."""
    from .guard.exits import InputError
    from .guard.outputs import OutputPlan, check_name_lengths
    from .guard.resources import check_disk
    from .scenario.estimate import run_needs

    checkpoints = sc.simulation.checkpoint_every > 0
    given = None if resume is None else (resume if resume.suffix == ".ckpt" or not resume.name
                                         else resume.with_suffix(".ckpt"))
    if given is not None:
        check_name_lengths(given, "--resume")  # a name the file system refuses is a wrong name (exit 2)
    plan = OutputPlan(reserved={".ckpt": "the .ckpt suffix is kept for checkpoints; give the result a .nc name"})
    plan.add_inputs(S.scenario_file(source), *S.referenced_files(sc), given)
    plan.file(output, "-o")
    plan.check()
    check_disk(run_needs(sc).result * (2 if checkpoints else 1), output.absolute().parent, f"-o {output}: the result")
    ckpt = output.with_suffix(".ckpt")
    resuming = given is not None and given.exists() and given.resolve() == ckpt.resolve()
    if checkpoints and ckpt.exists() and not resuming:
        raise InputError(f"{ckpt} exists (the checkpoint of an earlier run?): continue it with --resume {ckpt}, or move "
                         "it away")
    plan.prepare()
    return ckpt


def _share(s: dict) -> str:
    """The balance error's share of its scale, named (`analysis.balance.balance_scale`)."""
    if not s.get("balance_scale_J", 0.0) > 0:
        return "nothing stored or put in"
    return f"{s['max_balance_error_rel']:.2e} of the {s['balance_scale']}, {s['balance_scale_J']:.3e} J"


def summary_rows(s: dict) -> list[tuple[str, str]]:
    """The end-of-run table of a `summarize` dict: (label, value) rows."""
    rows = [("steps", f"{s['steps']}"), ("wall time", f"{s['wall_time_s']:.2f} s"),
            ("simulated time", f"{s['simulated_time_s'] * 1e3:.4f} ms")]
    if "mean_iterations" in s:
        rows.append(("mean iterations", f"{s['mean_iterations']:.2f}"))
    if "min_step" in s:
        rows.append(("smallest step", f"{s['min_step']:.3e} s"))
    rows += [("input work", f"{s['input_work_J']:.6e} J"),
             ("max balance error", f"{s['max_balance_error_J']:.3e} J ({_share(s)})")]
    rows += [(f"peak speed {m}", f"{p['m_per_s']:.4f} m/s ({p['granule']})") for m, p in s["peak_speed"].items()]
    eq = s.get("equilibrium")
    if eq:
        rows.append(("equilibrium", f"{int(eq['loaded_pairs'])} pairs and {int(eq['loaded_walls'])} wall contacts "
                                    f"loaded, {int(eq['iterations'])} Newton iterations, residual {eq['residual_N']:.1e} N "
                                    f"(round-off bound {eq.get('tolerance_N', float('nan')):.1e} N)"))
        rows.append(("equilibrium forces", f"largest: pair {eq['max_pair_force_N']:.4g} N, wall "
                                           f"{eq['max_wall_force_N']:.4g} N, solid {eq['max_solid_force_N']:.4g} N; "
                                           f"deepest overlap {eq['max_overlap_m']:.3e} m"))
    rows.append(("output", s.get("output", "")))
    return rows


def legacy_model_record(ds):
    """The model record (`io.model.ResultModel`) of a result written by a granel that did not
    store one, built from its stored scenario, with the texts of the files it refers to (its
    `input_texts`) written to a private folder. The migration of such results, and the one place
    where a result's scenario is built."""
    import shutil
    import tempfile

    from .guard.fingerprints import decode
    from .io.model import model_record

    raw = tomllib.loads(ds.attrs["scenario"])
    texts = decode(str(ds.attrs.get("input_texts", "{}")))
    folder = Path(tempfile.mkdtemp(prefix="granel-inputs-")) if texts else None
    try:
        if texts:
            raw = S.with_input_texts(raw, texts, folder)
        problem = S.build_problem(S.validate(raw))
    finally:
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
    return model_record(problem.system, problem.solid), {"solver_ledger_tol": problem.settings.ledger_tol}


def with_model_record(ds, name="result"):
    """The result Dataset `ds` with its model record: as stored, or, for a result of an earlier
    granel (no record, or one of an earlier layout), built once by `legacy_model_record` and added
    (after `io.model.check_result_model`) with the solver attributes it lacked. ResultFileError
    (code 2) naming `name` if its scenario cannot be built or does not fit it."""
    from .io.model import check_result_model, has_record, with_record

    if has_record(ds):
        return ds
    try:
        rec, attrs = legacy_model_record(ds)
    except Exception as e:  # noqa: BLE001 - invalid TOML, an invalid or unbuildable scenario
        raise _bad_scenario(name, e) from None
    check_result_model(ds, rec, name)
    out = with_record(ds, rec)
    if out.attrs.get("solver_integrator") == "exact":
        out.attrs.update({k: v for k, v in attrs.items() if k not in out.attrs})
    return out


def _bad_scenario(name, e: Exception):
    from .io.results import ResultFileError

    lines = str(e).strip().splitlines()
    return ResultFileError(f"{name}: its scenario attribute is not a valid granel scenario "
                           f"({type(e).__name__}{': ' + lines[0][:200] if lines else ''})", 2)


def load_result(path, what: str = "result file"):
    """A run's result file, read and checked: its structure (`io.results.check_result_schema`), a
    scenario attribute that is a valid scenario, and the agreement of its variables with the model
    it carries (`io.model.check_result_model`: the same granules, contacts and walls and, for an
    elastic solid, a modal or reduced state of the solid's size); a result of an earlier granel
    gets its model record here (`with_model_record`). ResultFileError naming the file: code 4 if
    it cannot be read as NetCDF, 2 if it is not a result or is damaged."""
    from .io.model import check_result_model, has_record, read_record
    from .io.results import ResultFileError, check_result_schema, read_netcdf_or, with_every_granule

    path = Path(path)
    ds = read_netcdf_or(path, ResultFileError, what)
    check_result_schema(ds, path)
    if not has_record(ds):
        return with_model_record(ds, path)
    try:
        S.Scenario.model_validate(tomllib.loads(ds.attrs["scenario"]))
    except Exception as e:  # noqa: BLE001 - invalid TOML, invalid fields
        raise _bad_scenario(path, e) from None
    check_result_model(ds, read_record(ds, path), path)
    return with_every_granule(ds)


def summarize(ds) -> dict:
    """Numbers for the end-of-run table and --json-summary (of a Dataset or a `ResultSpec`)."""
    w = ds["input_work"].values
    wmax = float(np.max(np.abs(w))) if w.size else 0.0
    err = np.abs(ds["balance_error"].values)
    scale, scale_name = balance_scale(ds)
    out = {
        "scenario": _scenario_name(ds),
        "solid": ds.attrs.get("solid_kind", ""),
        "steps": int(ds.attrs.get("solver_steps", 0)),
        "wall_time_s": float(ds.attrs.get("solver_wall_time_s", float("nan"))),
        "simulated_time_s": float(ds["time"].values[-1]),
        "input_work_J": wmax,
        "max_balance_error_J": float(err.max()) if err.size else 0.0,
        "max_balance_error_rel": relative_balance_error(ds, scale) if scale > 0 else None,
        "balance_scale": scale_name,
        "balance_scale_J": scale,
        "peak_speed": {},
    }
    out["peak_speed"] = _peak_speeds(ds)
    for key in ("solver_mean_iterations", "solver_min_step"):
        if key in ds.attrs:
            out[key[7:]] = float(ds.attrs[key])
    eq = {k[len("equilibrium_"):]: float(v) for k, v in ds.attrs.items() if k.startswith("equilibrium_")}
    if eq:
        out["equilibrium"] = eq
    return out


def _peak_speeds(ds) -> dict:
    """{medium: {granule, m_per_s}}: the fastest granule of each medium among those whose states
    the result stores (every granule, the traced ones, or none)."""
    if "v_x" not in ds:
        return {}
    labels, media = np.asarray(ds["granule"].values), np.asarray(ds["medium"].values)
    stored = np.arange(len(labels))
    if "traced" in ds:  # a few granules' traces
        index = {str(g): k for k, g in enumerate(labels)}
        stored = np.array([index[str(g)] for g in ds["traced"].values], int)
    peak = np.hypot(ds["v_x"].values, ds["v_y"].values).max(axis=0)
    keep = np.isfinite(peak)  # a result read with every granule: NaN where not traced
    stored, peak = stored[keep], peak[keep]
    out = {}
    for m in np.unique(media[stored]):
        sel = media[stored] == m
        g = int(np.argmax(np.where(sel, peak, -1)))
        out[str(m)] = {"granule": str(labels[stored[g]]), "m_per_s": float(peak[g])}
    return out


def _scenario_name(ds) -> str:
    try:
        return tomllib.loads(ds.attrs["scenario"]).get("name", "")
    except Exception:  # noqa: BLE001 - a summary must not fail on foreign files
        return ""
