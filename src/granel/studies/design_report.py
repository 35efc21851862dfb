"""What `granel design` leaves for a reader: Optuna's own figures (optimisation history, Pareto
front, parameter importances), the best design drawn beside the base scenario with their
traces, and report.md, in which the base and the best designs are re-evaluated at a tighter
accuracy than the study's (an optimiser may exploit a loose tolerance; the report shows whether
it did).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from .design import DesignSpec
from .design_trials import (TRIAL_CONSTRAINTS, best_trials, design_scenario, design_warnings, evaluate_trial,
                            trial_case)
from .modes import study_mode
from .screening import confirmed_trials

# an objective re-evaluated at the tighter accuracy may move by this share of its value (or of
# its improvement over the base, whichever is larger) before the report flags it
EXPLOIT_SHARE = 0.01


def tighter(sc) -> list[str]:
    """Overrides that make a run about ten times more accurate than `sc`'s settings: the error
    controlled integrator's rtol and ledger_tol / 10 (and Newton's tolerances / 10); a fixed-step
    run (the paper's algorithm, Newmark, --dt) at dt / 4."""
    s = sc.simulation
    out = [f"simulation.abstol={s.abstol / 10!r}", f"simulation.reltol={s.reltol / 10!r}"]
    if s.solver == "fast" and s.integrator == "exact" and s.adaptive:
        return out + [f"simulation.rtol={s.rtol / 10!r}", f"simulation.ledger_tol={s.ledger_tol / 10!r}"]
    return out + [f"simulation.dt={s.dt / 4!r}"]


def reevaluate(spec: DesignSpec, base_dir: Path, out: Path, best: list, client=None) -> list[dict]:
    """The base scenario and up to three best designs, each run at the study's accuracy and at
    the tighter one (`tighter`), runs kept in out/reevaluation: [{label, params, study, tight}],
    `study` and `tight` being `run_case` results. On `client`'s workers when given (the study's
    cluster, all at once), else one after the other here."""
    folder = str((out / "reevaluation").resolve())
    tight = tighter(design_scenario(spec, base_dir, {}))
    rows = [("base", {})] + [(f"trial {t.number}", dict(t.params)) for t in best[:3]]
    jobs = []
    for label, params in rows:
        overrides = trial_case(spec, 0, params)["overrides"] if params else {}  # tied fields too
        for key, extra in (("study", []), ("tight", tight)):
            sj = spec.model_copy(update={"overrides": [*spec.overrides, *extra]}).model_dump_json()
            case = {"index": [0], "overrides": overrides, "tag": f"{label.replace(' ', '-')}-{key}"}
            jobs.append((label, key, (sj, str(base_dir.resolve()), case, folder, True)))
    if client is not None:
        futures = [client.submit(evaluate_trial, *args, pure=False) for _, _, args in jobs]
        done = client.gather(futures)
    else:
        done = [evaluate_trial(*args) for _, _, args in jobs]
    results = {label: {"label": label, "params": params} for label, params in rows}
    for (label, key, _), r in zip(jobs, done):
        results[label][key] = r
    return list(results.values())


def objective_values(spec: DesignSpec, result: dict) -> list[float]:
    if result.get("status") != "ok":
        return [math.nan] * len(spec.objectives)
    out = []
    for o in spec.objectives:
        try:
            out.append(o.value(result["metrics"]))
        except ValueError:
            out.append(math.nan)
    return out


def exploited(spec: DesignSpec, rows: list[dict]) -> list[str]:
    """The objectives of the best designs that moved by more than EXPLOIT_SHARE of their value
    (or of their improvement over the base) between the study's accuracy and the tighter one."""
    base = objective_values(spec, rows[0]["tight"])
    flags = []
    for r in rows[1:]:
        a, b = objective_values(spec, r["study"]), objective_values(spec, r["tight"])
        for o, x, y, z in zip(spec.objectives, a, b, base):
            scale = max(abs(y), abs(y - z) if math.isfinite(z) else 0.0, 1e-300)
            if not (math.isfinite(x) and math.isfinite(y)) or abs(x - y) > EXPLOIT_SHARE * scale:
                flags.append(f"{r['label']}: {o.name} {x:.6g} at the study's accuracy, {y:.6g} at the tighter one")
    return flags


# ---------------------------------------------------------------- figures


def _quiet():
    import optuna

    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)


def _save(fig, path: Path) -> Path:
    """A finished figure to `path` (PNG at 130 dpi), closed."""
    from ..guard.writing import save_figure

    fig.tight_layout()
    return save_figure(fig, path, dpi=130)


def optuna_figures(spec: DesignSpec, study, out: Path) -> list[Path]:
    """history.png (every objective), pareto.png (several objectives), importances.png (two or
    more variables and enough finished trials), by Optuna's matplotlib visualisation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from optuna.trial import TrialState
    from optuna.visualization import matplotlib as vis

    _quiet()
    done = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    files = []
    if not done:
        return files

    def save(ax, name):
        fig = (ax[0] if isinstance(ax, np.ndarray) else ax).figure
        fig.set_size_inches(7, 4.5)
        files.append(_save(fig, out / name))

    for k, o in enumerate(spec.objectives):
        target = None if len(spec.objectives) == 1 else (lambda t, k=k: t.values[k])
        ax = vis.plot_optimization_history(study, target=target, target_name=o.name)
        save(ax, "history.png" if len(spec.objectives) == 1 else f"history-{k}.png")
    if len(spec.objectives) > 1:
        ax = vis.plot_pareto_front(study, target_names=[o.name for o in spec.objectives],
                                   constraints_func=(lambda t: t.user_attrs.get("constraints", [0.0]))
                                   if spec.constraints and not TRIAL_CONSTRAINTS else None)
        save(ax, "pareto.png")
    if len(spec.variables) >= 2 and len(done) >= 4:
        for k, o in enumerate(spec.objectives[:1]):
            ax = vis.plot_param_importances(study, target=None if len(spec.objectives) == 1 else (lambda t: t.values[0]),
                                            target_name=o.name)
            save(ax, "importances.png")
    return files


def draw_design(ax, sc, title: str) -> None:
    """A scenario's granules, walls and solid (no labels), in mm."""
    from ..scenario.build import built_models, elastic_solid
    from ..viz.drawing import MM, draw_granules, draw_solid, draw_walls

    system, model = built_models(sc)
    depth = 0.04 * float(np.ptp(system.pos0[:, 1]) + 2 * system.radius.max()) * MM
    if elastic_solid(sc) is not None or system.solid_contacts:
        draw_solid(ax, sc, model, "design")  # (a rigid block parked away from the granules is left out)
    draw_granules(ax, system, "design", labels=False)
    if np.ptp(system.E) > 0:  # granules of several materials: each marked with its modulus
        for g in range(system.n):
            ax.text(*(system.pos0[g] * MM), f"{system.E[g] / 1e9:.3g}", ha="center", va="center", fontsize=6)
        ax.text(0.01, 0.02, "numbers: Young's modulus [GPa]", transform=ax.transAxes, fontsize=6)
    draw_walls(ax, system, "design", depth, fontsize=5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")


def best_figure(spec: DesignSpec, base_dir: Path, rows: list[dict], out: Path) -> Path | None:
    """best.png: the base scenario and the best design drawn side by side, and their traces at
    the tighter accuracy: the largest wall force (an objective on a wall force) or the largest
    granule speed, and the energy held by each medium and the solid over the input."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.results import read_netcdf, require

    mode = study_mode(spec.mode)
    if len(rows) < 2 or rows[1]["tight"].get("status") != "ok" or rows[0]["tight"].get("status") != "ok":
        return None
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    draw_design(axes[0, 0], design_scenario(spec, base_dir, {}), "base scenario")
    draw_design(axes[0, 1], design_scenario(spec, base_dir, rows[1]["params"]), f"best design ({rows[1]['label']})")
    walls_matter = any("wall" in o.metric for o in spec.objectives)
    for r, ls in ((rows[0], "--"), (rows[1], "-")):
        for path in _run_paths(out, r):
            ds = read_netcdf(path)
            t = ds["time"].values * 1e3
            w = mode.energy_scale(ds)
            run = path.stem.split("__", 1)[1]
            label = f"{r['label']}, {run}"
            require(ds, ["wall_force_normal"] if walls_matter else ["v_x"], f"the design report's figure ({path.name})")
            if walls_matter:
                axes[1, 0].plot(t, ds["wall_force_normal"].values.max(axis=1), ls=ls, lw=1, label=label)
            else:
                axes[1, 0].plot(t, np.hypot(ds["v_x"].values, ds["v_y"].values).max(axis=1), ls=ls, lw=1, label=label)
            for name in [f"energy_{str(m).lower()}" for m in dict.fromkeys(ds["medium"].values)] + ["energy_solid"]:
                if name in ds and np.abs(ds[name].values).max() > 0:
                    axes[1, 1].plot(t, ds[name].values / w, ls=ls, lw=1, label=f"{label}: {name[7:]}")
    axes[1, 0].set(xlabel="t [ms]", ylabel="largest wall force [N]" if walls_matter else "largest granule speed [m/s]",
                   title="wall force" if walls_matter else "speed")
    axes[1, 1].set(xlabel="t [ms]", ylabel=mode.energy_label, title=mode.energy_title)
    for ax in axes[1]:
        ax.legend(fontsize=6)
    return _save(fig, out / "best.png")


# ---------------------------------------------------------------- the solid's modes

# modes listed per run in the report's modal accounting
TOP_MODES = 5


def _run_paths(out: Path, row: dict) -> list[Path]:
    """The result files of a re-evaluated design at the tighter accuracy (a spectrum's first
    frequency)."""
    folder = out / "reevaluation" / "cases"
    tag = row["tight"].get("tag", "")
    return sorted(folder.glob(f"{tag}__*.nc")) or sorted(folder.glob(f"{tag}-f000__*.nc"))


def modal_accounting(ds, top: int = TOP_MODES) -> dict | None:
    """Where a run's solid energy went, mode by mode (eqs. 15-16, the paper's Figs. 7-9): each
    mode's share of the time-integrated solid energy, int E_n dt / int E dt, the `top` largest
    with their frequency and kind (`solid.modal.classify_modes`), the modes that hold 90 % of it
    (eq. 16), and the solid's peak and time-averaged energy over the input work. None for a run
    without modal coordinates (no solid, a rigid one, or a large solid stored in nodes)."""
    from ..analysis.modal import modal_coordinates, modal_energies, modes_for_fraction, time_averaged_accumulation, time_averaged_shares
    from ..analysis.reciprocity import input_energy

    if "solid_eta" not in ds or ds.sizes.get("mode", 0) == 0:
        return None
    t, X, Xdot, omega = modal_coordinates(ds)
    E = modal_energies(X, Xdot, omega)
    total = float(np.trapezoid(E.sum(axis=1), t))
    if len(t) < 2 or not total > 0:
        return None
    shares = time_averaged_shares(E, t)
    order = np.argsort(shares)[::-1][:top]
    kinds = _mode_kinds(ds, [int(i) for i in order])
    w = max(input_energy(ds), 1e-300)
    return {"shares": shares, "frequency_Hz": omega / (2 * np.pi),
            "top": [(int(i) + 1, float(omega[i] / (2 * np.pi)), k, float(shares[i])) for i, k in zip(order, kinds)],
            "modes_90": modes_for_fraction(time_averaged_accumulation(E, t), 0.9),
            "solid_peak": float(E.sum(axis=1).max() / w), "solid_mean": total / float(t[-1] - t[0]) / w}


def _mode_kinds(ds, which: list[int]) -> list[str]:
    """The kinds of modes `which` (0-based) of a run's solid, built from its model record."""
    from ..analysis.result_model import result_modes, result_solid
    from ..run import with_model_record
    from ..solid.modal import classify_modes

    try:
        ds = with_model_record(ds)
        return classify_modes(result_solid(ds), result_modes(ds), which)
    except Exception:  # noqa: BLE001 - a drawing aid: the accounting stands without the kinds
        return ["?"] * len(which)


def modal_rows(out: Path, rows: list[dict]) -> list[tuple[str, str, dict]]:
    """(design, run, accounting) for the base and the best design at the tighter accuracy."""
    from ..io.results import read_netcdf

    found = []
    for r in rows[:2]:
        if r["tight"].get("status") != "ok":
            continue
        for path in _run_paths(out, r):
            acc = modal_accounting(read_netcdf(path))
            if acc is not None:
                found.append((r["label"], path.stem.split("__", 1)[1], acc))
    return found


def modes_figure(found: list[tuple[str, str, dict]], out: Path) -> Path | None:
    """modes.png: each run's time-averaged modal shares against the mode's frequency, the base
    and the best design side by side, one panel per run (direction)."""
    if not found:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = list(dict.fromkeys(run for _, run, _ in found))
    fig, axes = plt.subplots(1, len(runs), figsize=(5.5 * len(runs), 4), squeeze=False)
    for ax, run in zip(axes[0], runs):
        for label, rn, acc in found:
            if rn != run:
                continue
            color = "tab:gray" if label == "base" else "tab:blue"
            f, s = acc["frequency_Hz"] / 1e3, acc["shares"]
            ax.vlines(f, 1e-6, np.maximum(s, 1e-6), color=color, lw=1.2 if label == "base" else 0.8,
                      alpha=0.6 if label == "base" else 0.9, label=label)
            for n, fr, _, sh in acc["top"][:3]:
                ax.annotate(str(n), (fr / 1e3, sh), fontsize=6, color=color, xytext=(2, 2), textcoords="offset points")
        ax.set(xscale="log", yscale="log", ylim=(1e-5, 1.5), xlabel="mode frequency [kHz]",
               ylabel="share of the time-integrated solid energy", title=run)
        ax.legend(fontsize=7)
    return _save(fig, out / "modes.png")


def modal_lines(found: list[tuple[str, str, dict]]) -> list[str]:
    """The report's table of the modal accounting."""
    if not found:
        return []
    lines = ["## The solid's modes", "",
             "Each run's solid energy, mode by mode (eqs. 15-16): the share of the time-integrated solid energy "
             "held by each of its largest modes (number, frequency, kind), the modes that hold 90 % of it, and the "
             "solid's peak and time-averaged energy over the input work (tighter accuracy).", "",
             "| design | run | solid peak / mean | modes for 90 % | largest modes: n (f, kind) share |",
             "| --- | --- | --- | --- | --- |"]
    for label, run, acc in found:
        modes = "; ".join(f"{n} ({f / 1e3:.1f} kHz, {k}) {s:.3f}" for n, f, k, s in acc["top"])
        lines.append(f"| {label} | {run} | {acc['solid_peak']:.3f} / {acc['solid_mean']:.3f} | {acc['modes_90']} | {modes} |")
    return lines + [""]


# ---------------------------------------------------------------- report


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def study_speed(study) -> dict:
    """Trials per minute over the study's sessions and the share of a trial spent outside the
    solver: 1 - solver time / launch-to-result time, summed over finished trials. A trial that
    reused a stored case (its values asked again) spent no time in the solver; in a journal
    written before trials were marked `reused`, such a trial shows as a case time longer than
    its launch-to-result time, which a run of its own never has."""
    from optuna.trial import TrialState

    sessions = study.user_attrs.get("sessions", [])
    wall = sum(s["wall_s"] for s in sessions)
    n = sum(s["trials"] for s in sessions)
    ts = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    solver = np.array([t.user_attrs.get("solver_s", np.nan) for t in ts], float)
    turn = np.array([t.user_attrs.get("turnaround_s", np.nan) for t in ts], float)
    case = np.array([t.user_attrs.get("wall_s", np.nan) for t in ts], float)
    reused = np.array([bool(t.user_attrs.get("reused", False)) for t in ts], bool) | (case > turn)
    solver = np.where(reused, 0.0, solver)
    ok = np.isfinite(solver) & np.isfinite(turn) & (turn > 0)
    ran = [t for t, r in zip(ts, reused) if not r and t.user_attrs.get("parts")]
    parts = {k: float(np.median([t.user_attrs["parts"].get(k, np.nan) for t in ran]))
             for k in ("load_s", "build_s", "modes_s", "solver_s", "metrics_s")} if ran else {}
    if ran:  # launch to result beyond the worker's own time: queueing, transfers, the scheduler
        parts["scheduling_s"] = float(np.median([t.user_attrs["turnaround_s"] - t.user_attrs["wall_s"] for t in ran]))
    return {"trials_per_min": 60.0 * n / wall if wall > 0 else math.nan, "trials": n, "wall_s": wall,
            "workers": max((s["workers"] for s in sessions), default=0),
            "outside_solver": float(1.0 - solver[ok].sum() / turn[ok].sum()) if ok.any() else math.nan,
            "median_trial_s": float(np.median(turn[ok])) if ok.any() else math.nan, "reused": int(reused.sum()),
            "parts": parts, "worker_start_s": sum(s.get("start_s", 0.0) for s in sessions)}


def screening_summary(spec: DesignSpec, study) -> dict | None:
    """How a screened study's ranking holds at the design's own accuracy, over its confirmed
    trials (`screening.confirmed_trials`): per trial its screened and confirmed objective values and
    ranks (by the first objective, best first), Kendall's tau between the two orders, the
    screened rank of the confirmed best, and the largest change of an objective (absolute, and
    relative to the confirmed value). None for a study without screening."""
    if spec.screening is None:
        return None
    conf = confirmed_trials(spec, study)
    sign = 1.0 if spec.directions[0] == "minimize" else -1.0
    if not conf:
        return {"rows": [], "tau": math.nan, "best_screened_rank": None, "max_change": math.nan,
                "max_change_rel": math.nan}
    screened = np.array([t.screened_values for t in conf], float)
    full = np.array([t.values for t in conf], float)
    rank = lambda x: np.argsort(np.argsort(sign * x, kind="stable"), kind="stable") + 1  # noqa: E731
    rs, rf = rank(screened[:, 0]), rank(full[:, 0])
    tau = math.nan
    if len(conf) > 1:
        from scipy.stats import kendalltau

        tau = float(kendalltau(screened[:, 0], full[:, 0]).statistic)
    change = np.abs(full - screened)
    return {"rows": [{"trial": t.number, "screened": list(s), "confirmed": list(f), "screened_rank": int(a),
                      "confirmed_rank": int(b)} for t, s, f, a, b in zip(conf, screened, full, rs, rf)],
            "tau": tau, "best_screened_rank": int(rs[int(np.argmin(rf))]), "max_change": float(change.max()),
            "max_change_rel": float((change / np.maximum(np.abs(full), 1e-300)).max())}


def screening_lines(spec: DesignSpec, study) -> list[str]:
    """report.md's section on a screened study (`screening_summary`)."""
    s = screening_summary(spec, study)
    if s is None:
        return []
    lines = ["## Screening", "",
             f"Every trial ran at a looser accuracy ({', '.join(f'`{o}`' for o in spec.screening.overrides)}); the "
             f"{spec.screening.confirm} best were run again at the design's own accuracy, and the best design is the best "
             "of those.", ""]
    if not s["rows"]:
        return lines + ["No trial was confirmed (the study stopped before its confirmations).", ""]
    o = spec.objectives[0]
    lines += [f"| trial | {o.name}, screened | rank | {o.name}, confirmed | rank |", "| --- | --- | --- | --- | --- |"]
    for r in s["rows"]:
        lines.append(f"| {r['trial']} | {r['screened'][0]:.6g} | {r['screened_rank']} | {r['confirmed'][0]:.6g} | "
                     f"{r['confirmed_rank']} |")
    lines += ["", f"The confirmed best was number {s['best_screened_rank']} of the screening; Kendall's tau between the "
              f"two orders {s['tau']:.3f}; the largest change of an objective between the accuracies "
              f"{s['max_change']:.3g} ({100 * s['max_change_rel']:.3g} % of its confirmed value).", ""]
    return lines


def write_report(spec: DesignSpec, study, rows: list[dict], figures: list[Path], out: Path,
                 modal: list | None = None) -> Path:
    """report.md: the study, its speed, the best designs and their metrics against the base
    scenario's, at the study's accuracy and the tighter one, and the exploitation check."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)
    ok = sum(t.state == TrialState.COMPLETE for t in trials)
    failed = [t for t in trials if t.state == TrialState.FAIL]
    sp = study_speed(study)
    lines = [f"# Design study {spec.name!r}", ""]
    if spec.description:
        lines += [spec.description, ""]
    warned = design_warnings(spec, study, best_trials(spec, study))
    if warned:
        lines += ["**Warnings:**", ""] + [f"- {w}" for w in warned] + [""]
    lines += [f"Base scenario `{spec.base}` with {len(spec.overrides)} override(s); mode `{spec.mode}`"
              + study_mode(spec.mode).describe(spec) + ".", "",
              "| variable | range |", "| --- | --- |"]
    for v in spec.variables:
        rng = ", ".join(map(str, v.choices)) if v.choices is not None else \
            f"{v.low:g} to {v.high:g}" + (" (log)" if v.log else "") + (" (integer)" if v.integer else "")
        tied = f" (and {len(v.tied)} tied: {', '.join(f'`{f}`' for f in v.tied)})" if v.tied else ""
        lines.append(f"| `{v.field}`{tied} | {rng} |")
    lines += ["", "| objective | sense |", "| --- | --- |"]
    for o in spec.objectives:
        lines.append(f"| `{o.metric}` | " + (f"{o.direction}" if o.target is None else f"to {o.target:g} (minimise abs(m / target - 1); met within {o.met_within:g})")
                     + " |")
    for c in spec.constraints:
        lines.append(f"| constraint `{c.metric}` | " + " and ".join(
            x for x in ((f">= {c.min:g}" if c.min is not None else ""), (f"<= {c.max:g}" if c.max is not None else "")) if x) + " |")
    lines += ["", f"**Trials:** {len(trials)} ({ok} finished, {len(failed)} failed: "
              f"{sum(t.user_attrs.get('reason') == 'interrupted' for t in failed)} interrupted and replayed). "
              f"Sampler `{spec.sampler}`, seed {spec.seed}.", "",
              f"**Speed:** {sp['trials_per_min']:.1f} trials per minute on {sp['workers']} worker(s) "
              f"({sp['trials']} trials in {sp['wall_s']:.1f} s of this study's sessions); a trial's median "
              f"launch-to-result time {sp['median_trial_s']:.2f} s, of which {100 * sp['outside_solver']:.0f} % outside "
              "the solver (scenario building, compiled kernels' loading, metrics, scheduling)"
              + (f"; {sp['reused']} finished trial(s) asked values already run and reused their case (no solver time)"
                 if sp["reused"] else "") + "."
              + (" A trial's parts, medians: " + ", ".join(f"{k[:-2].replace('_', ' ')} {v:.2f} s" for k, v in sp["parts"].items())
                 + " (load: the scenarios validated and the case's fingerprint; modes: the solid's modes and the "
                   "solver's set-up)." if sp["parts"] else "")
              + (f" The workers took {sp['worker_start_s']:.1f} s to start." if sp["worker_start_s"] else ""), ""]
    lines += screening_lines(spec, study)
    reasons: dict[str, int] = {}
    for t in failed:
        key = str(t.user_attrs.get("reason", "?")).split("\n")[0][:160]
        reasons[key] = reasons.get(key, 0) + 1
    if reasons:
        lines += ["Failed trials, by reason:", ""] + [f"- {n} x {r}" for r, n in sorted(reasons.items(), key=lambda x: -x[1])] + [""]
    lines += ["## Best designs, re-evaluated", "",
              "Each is run again at the study's accuracy and at a tighter one (`design_report.tighter`: "
              "the error-controlled integrator's `rtol` and `ledger_tol` / 10, or a fixed step / 4).", ""]
    head = ["design", *[f"`{v.field}`" for v in spec.variables],
            *[f"{o.name} (study / tighter)" for o in spec.objectives]]
    lines += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        a, b = objective_values(spec, r["study"]), objective_values(spec, r["tight"])
        vals = [_fmt(r["params"].get(v.field, "(base)")) for v in spec.variables]
        lines.append("| " + " | ".join([r["label"], *vals, *[f"{x:.6g} / {y:.6g}" for x, y in zip(a, b)]]) + " |")
    flags = exploited(spec, rows)
    lines += ["", ("**The optimiser did not exploit the tolerance:** every best design's objectives agree at the two "
                   f"accuracies within {100 * EXPLOIT_SHARE:g} % of their value or of their improvement over the base.")
              if not flags else "**Check these designs:** their objectives move with the accuracy:\n\n"
              + "\n".join(f"- {f}" for f in flags), ""]
    names = sorted({k for r in rows if r["tight"].get("status") == "ok" for k in r["tight"]["metrics"]})
    if names:
        lines += ["## Metrics at the tighter accuracy", "", "| metric | " + " | ".join(r["label"] for r in rows) + " |",
                  "| --- |" + " --- |" * len(rows)]
        for m in names:
            lines.append(f"| {m} | " + " | ".join(_fmt(r["tight"].get("metrics", {}).get(m, "")) for r in rows) + " |")
        lines.append("")
    for r in rows:
        for key in ("study", "tight"):
            if r[key].get("status") != "ok":
                lines.append(f"- {r['label']} ({key}): {r[key].get('status')}")
    lines += modal_lines(modal or [])
    if figures:
        lines += ["## Figures", ""] + [f"![{f.stem}]({f.name})" for f in figures] + [""]
    lines += ["Files: `trials.nc` (every trial), " + ("`best.toml`" if len(spec.objectives) == 1 else "`pareto/NN.toml`")
              + " (runnable by `granel run`), `study.journal` (Optuna's journal: a rerun continues it), "
              "`reevaluation/cases/` (the runs above).", ""]
    from ..guard.owners import text_mark
    from ..guard.writing import write_text

    return write_text(out / "report.md", "\n".join([text_mark("<!--"), *lines]))


def write_study_report(spec: DesignSpec, base_dir: Path, study, out: Path, rows: list | None = None) -> list[Path]:
    """Figures, re-evaluation (`rows`, if `reevaluate` ran already) and report.md of a study
    (nothing when no trial finished)."""
    best = best_trials(spec, study)
    if not best:
        return []
    figures = optuna_figures(spec, study, out)
    rows = reevaluate(spec, base_dir, out, best) if rows is None else rows
    modal = modal_rows(out, rows)
    for fig in (best_figure(spec, base_dir, rows, out), modes_figure(modal, out)):
        if fig is not None:
            figures.append(fig)
    return [*figures, write_report(spec, study, rows, figures, out, modal)]


def plan_design(design_file: Path, out: Path):
    """Check `granel design`'s design file and output folder before any computation: (the spec,
    its folder, the unprepared `guard.outputs.OutputPlan` of --out). The folder is one a design
    study writes (it holds study.journal) or new; the design's fields and that each variable
    reaches the runs are checked (`design.check_design`): an invalid one raises a ScenarioError
    naming `design_file` (exit 2), a probe that cannot write raises `NotWritten` (exit 4)."""
    from ..guard.exits import NotWritten
    from ..guard.outputs import OutputPlan
    from .. import scenario as S
    from .design import check_design, load_design
    from .sweep import sweep_inputs

    spec, base_dir = load_design(design_file)
    plan = OutputPlan(inputs=[Path(design_file), *sweep_inputs(spec, base_dir)])
    plan.folder(out, "--out", "design", recognise=lambda p: (p / "study.journal").exists())
    for name in ("trials.nc", "best.toml", "report.md"):
        plan.file(out / name, f"--out (its {name})")
    plan.check()
    try:
        check_design(spec, base_dir)
    except S.ScenarioError as e:
        raise S.ScenarioError(f"{design_file}: {e}") from e
    except OSError as e:
        raise NotWritten("the study", out, e) from e
    return spec, base_dir, plan


def best_rows(spec: DesignSpec, res: dict) -> tuple[list[str], list[list[str]]]:
    """The table `granel design` prints: (header, rows), one row per best trial of `res`
    (`design_study`'s): its number, objective values and variables."""
    header = ["trial", *[f"{o.name} ({o.sense})" for o in spec.objectives], *[v.field for v in spec.variables]]

    def shown(v):
        return f"{v:.5g}" if isinstance(v, float) else str(v)

    rows = [[str(t.number), *[f"{v:.5g}" for v in t.values], *[shown(t.params[v.field]) for v in spec.variables]]
            for t in res["best"]]
    return header, rows


def design_study(spec: DesignSpec, base_dir: Path, out: Path, trials: int | None = None, options=None,
                 reporting=None) -> dict:
    """`granel design`: run (or continue) the study (`design_search.run_design` on the workers
    of `options`, a `design_search.DesignRunOptions`; the design already checked by
    `check_design`), then write its report (`write_study_report`). Returns run_design's dict,
    the report's files added to its "files". `reporting()` is called once the trials are done,
    before the report."""
    from dataclasses import replace

    from .design_search import DesignRunOptions, run_design  # looked up when called: a test may stand in for the engine

    held = {}

    def report_starts():
        if reporting is not None and not held.get("reported"):
            reporting()
        held["reported"] = True

    def finishing(study, client):  # the re-evaluation on the study's own workers
        report_starts()
        best = best_trials(spec, study)
        if best:
            held["rows"] = reevaluate(spec, base_dir, out, best, client)

    options = replace(options or DesignRunOptions(), finishing=finishing)
    res = run_design(spec, base_dir, out, trials, options, check=False)
    report_starts()
    res["files"] += write_study_report(spec, base_dir, res["study"], out, held.get("rows"))
    return res
