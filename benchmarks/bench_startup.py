"""Start-up costs: a fresh `granel run` and the cold compile of granel's kernels.

Run: .venv/bin/python benchmarks/bench_startup.py [--runs 5] [--no-fresh] [--no-compile] [--workers 1]

(a) fresh run: `granel run` of the strong SSGM-side plate case (the paper's plate, SSGM:C, strong
    shock, 0.8 ms) in `--runs` fresh processes, each timed beside a fresh process that only imports
    the stack (numpy, scipy.sparse, numba, xarray); medians, and their ratio. One untimed run first
    fills the caches (compiled kernels, modes). Bound: a median of at most FRESH_BOUND_S.
(b) cold compile: `granel design` of a design's first trial (`--design`, default diode; --trials 1)
    with numba's cache pointed at an empty folder, against the same with that cache filled (both
    after an untimed run that caches the trial's modes): the difference is the compile. With
    `--workers 2 --trials 2` the workers share the empty cache: one compiles, the other waits for
    it and loads. Bound: the first trial's compile at most COMPILE_BOUND_S.

Timings on a shared machine are noisy: the medians and the paired baseline are what count.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FRESH_BOUND_S = 1.5
COMPILE_BOUND_S = 60.0
CASE = ["paper", "--solid", "plate", "--excite", "SSGM:C", "--shock", "strong"]
STACK = "import numpy, scipy.sparse, numba, xarray"
ROOT = Path(__file__).resolve().parent.parent


def _timed(args, env=None) -> float:
    start = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    return time.perf_counter() - start


def _granel(*args) -> list[str]:
    return [sys.executable, "-m", "granel", *args]


def fresh_run(runs: int) -> dict:
    """(a): medians of `granel run` and of the bare stack import, alternated in fresh processes."""
    with tempfile.TemporaryDirectory() as d:
        out = str(Path(d) / "run.nc")
        _timed(_granel("run", *CASE, "-o", out))  # caches: kernels, modes, the plate
        run_s, bare_s = [], []
        for _ in range(runs):
            bare_s.append(_timed([sys.executable, "-c", STACK]))
            run_s.append(_timed(_granel("run", *CASE, "-o", out)))
    run, bare = statistics.median(run_s), statistics.median(bare_s)
    return {"run_s": run_s, "bare_import_s": bare_s, "run_median_s": run, "bare_import_median_s": bare,
            "ratio": run / bare, "bound_s": FRESH_BOUND_S, "within_bound": run <= FRESH_BOUND_S}


def _design(design: str, out: Path, cache: Path, workers: int, trials: int) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return _timed(_granel("design", design, "-o", str(out), "--trials", str(trials), "--workers", str(workers)), env)


def cold_compile(design: str, workers: int) -> dict:
    """(b): a design's first trial(s) with an empty and with a filled numba cache."""
    trials = max(1, workers)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        _design(design, d / "warmup", d / "warm-cache", 1, 1)  # the trial's modes, and a filled kernel cache
        cold = _design(design, d / "cold", d / "cold-cache", workers, trials)
        warm = _design(design, d / "warm", d / "warm-cache", workers, trials)
    return {"design": design, "workers": workers, "trials": trials, "cold_s": cold, "warm_s": warm,
            "compile_s": cold - warm, "bound_s": COMPILE_BOUND_S, "within_bound": cold - warm <= COMPILE_BOUND_S}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--design", default=str(ROOT / "scenarios" / "designs" / "diode.toml"))
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--no-fresh", action="store_true")
    ap.add_argument("--no-compile", action="store_true")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    res = {}
    if not a.no_fresh:
        res["fresh_run"] = f = fresh_run(a.runs)
        if not a.json:
            print(f"(a) fresh granel run: median {f['run_median_s']:.2f} s over {a.runs} "
                  f"(bare import {f['bare_import_median_s']:.2f} s, ratio {f['ratio']:.2f}); "
                  f"bound {FRESH_BOUND_S} s: {'ok' if f['within_bound'] else 'EXCEEDED'}")
    if not a.no_compile:
        res["cold_compile"] = c = cold_compile(a.design, a.workers)
        if not a.json:
            print(f"(b) design first trial ({c['workers']} worker(s)): cold {c['cold_s']:.1f} s, cached "
                  f"{c['warm_s']:.1f} s, compile {c['compile_s']:.1f} s; bound {COMPILE_BOUND_S:.0f} s: "
                  f"{'ok' if c['within_bound'] else 'EXCEEDED'}")
    if a.json:
        print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
