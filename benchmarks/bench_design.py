"""A design campaign end to end: `granel design` of the built-in diode study in a fresh process,
from empty caches (the mode cache and numba's), on 2 workers.

Run: .venv/bin/python benchmarks/bench_design.py [--trials 200] [--workers 2] [--warm]

Reports the wall time of the whole command (check, workers' start, compilation, trials,
confirmations, re-evaluation, figures, report), trials per minute over the study's session, the
median trial and its parts (load, build, modes of a new mesh, solver, metrics, scheduling), the
workers' start, the first trial's launch-to-result time (it waits for compilation), and how the
screening's ranking held at full accuracy (Kendall's tau over the confirmed trials, the largest
change of the objective). `--warm` keeps this machine's compiled kernels (numba's cache), the
mode cache still empty: what a campaign after another one sees. The issue's bound: 200 trials in at most 5 minutes on 2 workers from empty caches.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "scenarios" / "designs" / "diode.toml"


def campaign(trials: int, workers: int, warm: bool, design: Path) -> dict:
    with tempfile.TemporaryDirectory(prefix="granel-bench-design-") as tmp:
        env = dict(os.environ)
        env["GRANEL_CACHE"] = str(Path(tmp) / "cache")
        if not warm:
            env["NUMBA_CACHE_DIR"] = str(Path(tmp) / "numba")
        out = Path(tmp) / "out"
        cmd = [sys.executable, "-m", "granel", "design", str(design), "-o", str(out), "--trials", str(trials),
               "--workers", str(workers)]
        start = time.perf_counter()
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if done.returncode != 0:
            raise SystemExit(f"granel design failed ({done.returncode}):\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
        return {"wall_s": wall, **study_figures(design, out)}


def study_figures(design: Path, out: Path) -> dict:
    from granel.studies.design import load_design
    from granel.studies.design_search import open_study
    from granel.studies.design_report import screening_summary, study_speed

    spec, _ = load_design(design)
    study = open_study(spec, out)
    speed = study_speed(study)
    trials = sorted(study.get_trials(deepcopy=False), key=lambda t: t.datetime_start)
    first = trials[0].user_attrs.get("turnaround_s", float("nan")) if trials else float("nan")
    scr = screening_summary(spec, study) or {}
    confirm_s = [c.get("wall_s", float("nan")) for c in study.user_attrs.get("confirmed", {}).values()]
    return {"trials": speed["trials"], "study_wall_s": speed["wall_s"], "trials_per_min": speed["trials_per_min"],
            "median_trial_s": speed["median_trial_s"], "parts": speed["parts"],
            "worker_start_s": speed["worker_start_s"], "first_trial_s": first,
            "confirmations": len(confirm_s), "confirmation_s": sorted(confirm_s),
            "kendall_tau": scr.get("tau"), "best_screened_rank": scr.get("best_screened_rank"),
            "max_change": scr.get("max_change"), "max_change_rel": scr.get("max_change_rel")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--warm", action="store_true", help="keep this machine's compiled kernels")
    ap.add_argument("--design", type=Path, default=DESIGN)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    res = campaign(a.trials, a.workers, a.warm, a.design)
    if a.json:
        print(json.dumps(res, indent=2))
        return
    print(f"granel design {a.design.name}: {res['trials']} trials on {a.workers} workers "
          f"({'compiled kernels, empty mode cache' if a.warm else 'empty caches'}): {res['wall_s']:.1f} s end to end, "
          f"{res['trials_per_min']:.1f} trials/min over the study's session ({res['study_wall_s']:.1f} s)")
    print(f"  median trial {res['median_trial_s']:.2f} s; parts: "
          + ", ".join(f"{k[:-2]} {v:.2f} s" for k, v in res["parts"].items()))
    print(f"  workers' start {res['worker_start_s']:.1f} s; first trial {res['first_trial_s']:.1f} s (compilation)")
    print(f"  {res['confirmations']} confirmations at full accuracy: "
          + ", ".join(f"{s:.1f}" for s in res["confirmation_s"]) + " s")
    print(f"  screening: Kendall's tau {res['kendall_tau']:.3f}, the confirmed best was screened rank "
          f"{res['best_screened_rank']}, largest change {res['max_change']:.3g} ({100 * res['max_change_rel']:.2f} %)")


if __name__ == "__main__":
    main()
