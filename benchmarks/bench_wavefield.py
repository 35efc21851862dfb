"""`granel wavefield` on a 0.8 ms plate result (issue 31: at most BOUND_S on this machine).

Run: .venv/bin/python benchmarks/bench_wavefield.py [--runs 3] [--result RESULT.nc] [--json]

Without --result, one `granel run paper --solid plate` (the paper's strong LSGM-side shock, 0.8 ms,
801 stored solid outputs) is made first, untimed (it fills the caches: kernels, the plate, its
modes). Then `granel wavefield RESULT -o DIR` runs `--runs` times in fresh processes, each into a
new folder: wall times, their median, and the stages' times of one in-process run (reading, the
solid and its modes, the analysis, the files). Bound: a median of at most BOUND_S.

Timings on a shared machine are noisy: the median is what counts.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BOUND_S = 10.0
CASE = ["paper", "--solid", "plate", "--duration", "0.8ms"]


def _granel(*args) -> list[str]:
    return [sys.executable, "-m", "granel", *map(str, args)]


def _timed(args) -> float:
    start = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def stages(result: Path, out: Path) -> dict:
    """The stages of one in-process `wavefield_study` [s]."""
    from granel.studies.wavefield import WavefieldOptions, read_wavefield_result, wavefield_study

    starts = []  # (stage, when it began)

    def progress(what, done, total):
        starts.append((what, time.perf_counter()))

    start = time.perf_counter()
    ds = read_wavefield_result(result)
    read = time.perf_counter() - start
    report = wavefield_study(ds, out, WavefieldOptions(), progress, name=result)
    ends = [t for _, t in starts[1:]] + [start + read + report.seconds]
    return {"read_s": read, "study_s": report.seconds, "steps_s": {w: e - t for (w, t), e in zip(starts, ends)}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--result", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        result = a.result
        if result is None:
            result = d / "plate.nc"
            subprocess.run(_granel("run", *CASE, "-o", result), check=True, stdout=subprocess.DEVNULL)
        _timed(_granel("wavefield", result, "-o", d / "warm"))  # untimed: the modes' and figures' caches
        times = [_timed(_granel("wavefield", result, "-o", d / f"out{k}")) for k in range(a.runs)]
        inside = stages(result, d / "inside")
    median = statistics.median(times)
    res = {"times_s": times, "median_s": median, "bound_s": BOUND_S, "within_bound": median <= BOUND_S, **inside}
    if a.json:
        print(json.dumps(res, indent=2))
        return
    verdict = "ok" if median <= BOUND_S else "EXCEEDED"
    print(f"granel wavefield on a 0.8 ms plate result: median {median:.2f} s over {a.runs} fresh processes "
          f"({', '.join(f'{t:.2f}' for t in times)}); bound {BOUND_S:.0f} s: {verdict}")
    print(f"in one process: reading {inside['read_s']:.2f} s, the study {inside['study_s']:.2f} s:")
    for k, v in inside["steps_s"].items():
        print(f"  {k}: {v:.2f} s")


if __name__ == "__main__":
    main()
