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

from .design import TRIAL_CONSTRAINTS, DesignSpec, best_trials, design_scenario, evaluate_trial

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


def reevaluate(spec: DesignSpec, base_dir: Path, out: Path, best: list) -> list[dict]:
    """The base scenario and up to three best designs, each run at the study's accuracy and at
    the tighter one (`tighter`), runs kept in out/reevaluation: [{label, params, study, tight}],
    `study` and `tight` being `run_case` results."""
    folder = out / "reevaluation"
    tight = tighter(design_scenario(spec, base_dir, {}))
    rows = [("base", {})] + [(f"trial {t.number}", dict(t.params)) for t in best[:3]]
    results = []
    for label, params in rows:
        case = {"index": [0], "overrides": {k: v for k, v in params.items()}, "tag": label.replace(" ", "-")}
        r = {"label": label, "params": params}
        for key, extra in (("study", []), ("tight", tight)):
            sj = spec.model_copy(update={"overrides": [*spec.overrides, *extra]}).model_dump_json()
            c = dict(case, tag=f"{case['tag']}-{key}")
            r[key] = evaluate_trial(sj, str(base_dir.resolve()), c, str(folder.resolve()), True)
        results.append(r)
    return results


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
        fig.tight_layout()
        path = out / name
        fig.savefig(path, dpi=130)
        plt.close(fig)
        files.append(path)

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
    from .run import built_models
    from .scenario.build import present_solid
    from .schematics import MM, draw_granules, draw_solid, draw_walls

    system, model = built_models(sc)
    depth = 0.04 * float(np.ptp(system.pos0[:, 1]) + 2 * system.radius.max()) * MM
    if present_solid(sc) is not None and (sc.solid.kind != "rigid" or system.solid_contacts):
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

    from .analysis.reciprocity import input_energy
    from .results import read_netcdf

    if len(rows) < 2 or rows[1]["tight"].get("status") != "ok" or rows[0]["tight"].get("status") != "ok":
        return None
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    draw_design(axes[0, 0], design_scenario(spec, base_dir, {}), "base scenario")
    draw_design(axes[0, 1], design_scenario(spec, base_dir, rows[1]["params"]), f"best design ({rows[1]['label']})")
    folder = out / "reevaluation"
    walls_matter = any("wall" in o.metric for o in spec.objectives)
    for r, ls in ((rows[0], "--"), (rows[1], "-")):
        tag = r["tight"]["tag"]
        paths = sorted((folder / "cases").glob(f"{tag}__*.nc")) or sorted((folder / "cases").glob(f"{tag}-f000__*.nc"))
        for path in paths:  # a spectrum's first frequency
            ds = read_netcdf(path)
            t = ds["time"].values * 1e3
            # a narrowband drive on a preloaded system does little work against the energy the
            # preload stores: there the energies are shown in joules
            w = 1.0 if spec.mode == "spectrum" else max(input_energy(ds), 1e-300)
            run = path.stem.split("__", 1)[1]
            label = f"{r['label']}, {run}"
            if walls_matter:
                axes[1, 0].plot(t, ds["wall_force_normal"].values.max(axis=1), ls=ls, lw=1, label=label)
            else:
                axes[1, 0].plot(t, np.hypot(ds["v_x"].values, ds["v_y"].values).max(axis=1), ls=ls, lw=1, label=label)
            for name in [f"energy_{str(m).lower()}" for m in dict.fromkeys(ds["medium"].values)] + ["energy_solid"]:
                if name in ds and np.abs(ds[name].values).max() > 0:
                    axes[1, 1].plot(t, ds[name].values / w, ls=ls, lw=1, label=f"{label}: {name[7:]}")
    axes[1, 0].set(xlabel="t [ms]", ylabel="largest wall force [N]" if walls_matter else "largest granule speed [m/s]",
                   title="wall force" if walls_matter else "speed")
    axes[1, 1].set(xlabel="t [ms]", ylabel="energy held [J]" if spec.mode == "spectrum" else "energy / input work",
                   title="energy held (tighter accuracy)" + (", first frequency" if spec.mode == "spectrum" else ""))
    for ax in axes[1]:
        ax.legend(fontsize=6)
    fig.tight_layout()
    path = out / "best.png"
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


# ---------------------------------------------------------------- report


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def study_speed(study) -> dict:
    """Trials per minute over the study's sessions and the share of a trial spent outside the
    solver (1 - solver time / launch-to-result time, over finished trials)."""
    from optuna.trial import TrialState

    sessions = study.user_attrs.get("sessions", [])
    wall = sum(s["wall_s"] for s in sessions)
    n = sum(s["trials"] for s in sessions)
    ts = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    solver = np.array([t.user_attrs.get("solver_s", np.nan) for t in ts], float)
    turn = np.array([t.user_attrs.get("turnaround_s", np.nan) for t in ts], float)
    ok = np.isfinite(solver) & np.isfinite(turn) & (turn > 0)
    return {"trials_per_min": 60.0 * n / wall if wall > 0 else math.nan, "trials": n, "wall_s": wall,
            "workers": max((s["workers"] for s in sessions), default=0),
            "outside_solver": float(1.0 - solver[ok].sum() / turn[ok].sum()) if ok.any() else math.nan,
            "median_trial_s": float(np.median(turn[ok])) if ok.any() else math.nan}


def write_report(spec: DesignSpec, study, rows: list[dict], figures: list[Path], out: Path) -> Path:
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
    lines += [f"Base scenario `{spec.base}` with {len(spec.overrides)} override(s); mode `{spec.mode}`"
              + (f", pair {spec.pair[0]} / {spec.pair[1]}" if spec.mode == "reciprocity" else "") + ".", "",
              "| variable | range |", "| --- | --- |"]
    for v in spec.variables:
        rng = ", ".join(map(str, v.choices)) if v.choices is not None else \
            f"{v.low:g} to {v.high:g}" + (" (log)" if v.log else "") + (" (integer)" if v.integer else "")
        lines.append(f"| `{v.field}` | {rng} |")
    lines += ["", "| objective | sense |", "| --- | --- |"]
    for o in spec.objectives:
        lines.append(f"| `{o.metric}` | " + (f"{o.direction}" if o.target is None else f"to {o.target:g} (minimise abs(m / target - 1))")
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
              "the solver (scenario building, compiled kernels' loading, metrics, scheduling).", ""]
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
    if figures:
        lines += ["## Figures", ""] + [f"![{f.stem}]({f.name})" for f in figures] + [""]
    lines += ["Files: `trials.nc` (every trial), " + ("`best.toml`" if len(spec.objectives) == 1 else "`pareto/NN.toml`")
              + " (runnable by `granel run`), `study.journal` (Optuna's journal: a rerun continues it), "
              "`reevaluation/cases/` (the runs above).", ""]
    path = out / "report.md"
    tmp = path.with_name("report.md.tmp")
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
    return path


def write_study_report(spec: DesignSpec, base_dir: Path, study, out: Path) -> list[Path]:
    """Figures, re-evaluation and report.md of a study (nothing when no trial finished)."""
    best = best_trials(spec, study)
    if not best:
        return []
    figures = optuna_figures(spec, study, out)
    rows = reevaluate(spec, base_dir, out, best)
    fig = best_figure(spec, base_dir, rows, out)
    if fig is not None:
        figures.append(fig)
    return [*figures, write_report(spec, study, rows, figures, out)]

