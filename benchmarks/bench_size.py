"""Cost against size: whole runs of chains and packings from 10 to 10^5 granules, each in a fresh
process, against a rigid wall and against the paper's plate.

Run: .venv/bin/python benchmarks/bench_size.py [--largest 100000] [--steps 400] [--repeat 3]

For each case a scenario is written and run in a child process that reports:
  - the static equilibrium's Newton iterations and its time (the build timed with
    simulation.equilibrate on, less the same build with it off);
  - the solver's wall time over a fixed number of fixed steps (simulation.adaptive = false, dt
    from granular.scales.safe_time_step), as seconds per granule-step (the median of --repeat
    runs of the child);
  - the child's peak resident memory (getrusage), and the result file's size and write time, both
    per simulated millisecond, at the default outputs (every granule, compression level 1) and
    with the traces of two granules only.

Cases: straight chains of R = 5 mm steel beads pressed by 10 N against a rigid wall, struck at the
far end at 0.1 m/s; hexagonal packings of R = 5 mm in a box (floor and side walls) under gravity,
the top row struck downward; the packings' column counts also against the paper's plate (its
LSGM replaced by the packing). LAMMPS's published serial rate for granular flow is quoted in
docs/performance.md beside these numbers.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

R = 0.005
CHILD = r"""
import json, os, resource, sys, time
from pathlib import Path
from granel import scenario as S
from granel.io.results import write_spec_netcdf
from granel.run import run_problem

path, out = Path(sys.argv[1]), Path(sys.argv[2])
t0 = time.perf_counter()
problem = S.build_problem(S.load(str(path), []))
build_eq = time.perf_counter() - t0
eq = problem.equilibrium or {}
t0 = time.perf_counter()
S.build_problem(S.load(str(path), ["simulation.equilibrate=false"]))
build = time.perf_counter() - t0
spec = run_problem(problem, dataset=False)
t0 = time.perf_counter()
write_spec_netcdf(spec, out)
write_s = time.perf_counter() - t0
traced = out.with_suffix(".traced.nc")
labels = problem.system.labels
S2 = S.load(str(path), [f'simulation.outputs.granules=["{labels[0]}","{labels[-1]}"]'])
spec2 = run_problem(S.build_problem(S2), dataset=False)
write_spec_netcdf(spec2, traced)
print(json.dumps({
    "granules": problem.system.n, "steps": int(spec.attrs["solver_steps"]),
    "solver_s": float(spec.attrs["solver_wall_time_s"]), "equilibrium_iterations": eq.get("equilibrium_iterations"),
    "equilibrium_s": max(build_eq - build, 0.0), "build_s": build, "write_s": write_s,
    "result_bytes": out.stat().st_size, "traced_bytes": traced.stat().st_size,
    "duration_s": float(spec["time"].values[-1]),
    "max_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def chain(n: int, steps: int) -> str:
    """n beads along +x from a wall at x = 0, 10 N pressing them against it, the last struck."""
    dt = 2e-8
    return f"""name = "chain-{n}"
[simulation]
duration = {steps * dt!r}
dt = {dt!r}
adaptive = false
output_every = {steps * dt / 20!r}
equilibrate = true
[solid]
kind = "rigid"
x0 = -1.0
y0 = -1.0
[[media]]
name = "C"
side = "none"
grow = "right"
face_x = 0.0
radii = {[R] * n}
walls = ["face"]
[[excitations]]
granule = "C:{n}"
kind = "constant"
value = 10.0
direction = [-1.0, 0.0]
[[initial_velocities]]
granule = "C:{n}"
v = [-0.1, 0.0]
"""


def packing(n: int, steps: int, solid: str = "box") -> str:
    """About n granules in a hexagonal packing: columns of ~sqrt(n) granules. In a box under
    gravity (solid = "box"), or pressed against the paper's plate (solid = "plate")."""
    rows = max(2, round(math.sqrt(n)))
    cols = [rows, rows - 1] * max(1, round(n / (2 * rows - 1)))
    dt = 2e-8
    head = f"""name = "packing-{n}"
[simulation]
duration = {steps * dt!r}
dt = {dt!r}
adaptive = false
output_every = {steps * dt / 20!r}
"""
    if solid == "plate":
        L = 2 * R * rows
        return head + f"""integrator = "newmark"
[solid]
kind = "plate"
length = {L!r}
[[media]]
name = "P"
side = "left"
radius = {R}
columns = {cols}
[[excitations]]
granule = "P:1"
shock = "strong"
"""
    return head + f"""equilibrate = true
[contact]
mu = 0.0
[solid]
kind = "rigid"
x0 = -10.0
y0 = -10.0
[[media]]
name = "H"
side = "none"
grow = "up"
columns = {cols}
radius = {R}
face_y = 0.0
center_x = 0.0
walls = ["left", "right", "face"]
[[initial_velocities]]
granule = "H:{sum(cols)}"
v = [0.0, -0.1]
""".replace("[simulation]", "gravity = [0.0, -9.81]\n[simulation]", 1)


def run_child(text: str, repeat: int) -> dict:
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.toml"
        path.write_text(text)
        for _ in range(repeat):
            out = subprocess.run([sys.executable, "-c", CHILD, str(path), str(Path(tmp) / "out.nc")],
                                 capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
            if out.returncode:
                return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"}
            results.append(json.loads(out.stdout.strip().splitlines()[-1]))
    best = dict(results[0])
    for key in ("solver_s", "equilibrium_s", "build_s", "write_s", "max_rss_bytes"):
        best[key] = statistics.median(r[key] for r in results)
    return best


def row(name: str, r: dict) -> str:
    if "error" in r:
        return f"{name:<26}{r['error']}"
    per_ms = 1e-3 / r["duration_s"]
    cost = r["solver_s"] / (r["granules"] * r["steps"])
    its = "-" if r["equilibrium_iterations"] is None else str(r["equilibrium_iterations"])
    return (f"{name:<26}{r['granules']:>9}{cost * 1e9:>12.0f}{r['max_rss_bytes'] / 2**20:>10.0f}{its:>8}"
            f"{r['equilibrium_s']:>9.2f}{r['result_bytes'] * per_ms / 2**20:>12.1f}{r['traced_bytes'] * per_ms / 2**20:>11.2f}"
            f"{r['write_s'] * per_ms:>10.2f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--largest", type=int, default=100_000, help="the largest packing (granules)")
    ap.add_argument("--steps", type=int, default=400, help="fixed steps of every run")
    ap.add_argument("--repeat", type=int, default=3, help="children per case (medians)")
    ap.add_argument("--only", choices=("chain", "box", "plate"), default=None)
    a = ap.parse_args()
    print(f"{a.steps} fixed steps of 20 ns, 21 outputs; medians of {a.repeat} fresh processes")
    print(f"{'case':<26}{'granules':>9}{'ns/gr-step':>12}{'RSS MiB':>10}{'Newton':>8}{'eq. [s]':>9}"
          f"{'MiB/sim.ms':>12}{'traced':>11}{'write s/ms':>10}")
    if a.only in (None, "chain"):
        for n in (10, 100, 1000, 10000):
            print(row(f"chain on a wall", run_child(chain(n, a.steps), a.repeat)), flush=True)
    if a.only in (None, "box"):
        for n in (100, 1000, 10000, 100000):
            if n <= a.largest:
                print(row("packing in a box, g", run_child(packing(n, a.steps), a.repeat)), flush=True)
    if a.only in (None, "plate"):
        for n in (100, 1000):
            print(row("packing on the plate", run_child(packing(n, a.steps, "plate"), a.repeat)), flush=True)


if __name__ == "__main__":
    main()
