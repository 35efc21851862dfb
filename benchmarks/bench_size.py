"""Cost against size: whole runs of chains and packings from 10 to 10^5 granules, each in a fresh
process, against a rigid wall and against the paper's plate.

Run: .venv/bin/python benchmarks/bench_size.py [--largest 100000] [--steps 400] [--repeat 3]

For each case a scenario is written and run in a child process that reports:
  - the static equilibrium's Newton iterations and its time (the build timed with
    simulation.equilibrate on, less the same build with it off);
  - the solver's wall time over a fixed number of fixed steps of 20 ns (simulation.adaptive =
    false), after a short warm-up run that loads the compiled kernels, as seconds per
    granule-step (the median of --repeat runs of the child);
  - the child's peak resident memory (getrusage), and the result file's bytes per output, per
    accepted step and fixed (their storage sizes), uncompressed, with every granule and with the
    traces of two granules only, and its write time;
  - (c) what compression saves and costs on the paper's 0.8 ms run (everything moves there): the
    file's size and write time at gzip levels 0, 1, 4 and 9.

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
problem = S.build_problem(S.load(str(path), ["simulation.outputs.compression=0"]))
build_eq = time.perf_counter() - t0
eq = problem.equilibrium or {}
every = S.load(str(path), []).simulation.output_every
t0 = time.perf_counter()
warm = S.build_problem(S.load(str(path), ["simulation.equilibrate=false", f"simulation.duration={2 * every!r}"]))
build = time.perf_counter() - t0
run_problem(warm, dataset=False)  # the compiled kernels loaded (or compiled) before the timed run
spec = run_problem(problem, dataset=False)
t0 = time.perf_counter()
write_spec_netcdf(spec, out)
write_s = time.perf_counter() - t0
traced = out.with_suffix(".traced.nc")
labels = problem.system.labels
if problem.system.n <= 20000:  # two traces cost the same at any size: measured on the smaller cases
    S2 = S.load(str(path), [f'simulation.outputs.granules=["{labels[0]}","{labels[-1]}"]', "simulation.outputs.steps=false",
                            "simulation.outputs.compression=0"])
    spec2 = run_problem(S.build_problem(S2), dataset=False)
    write_spec_netcdf(spec2, traced)
import h5netcdf


def split(path):
    # bytes stored per output (variables along time), per accepted step, and the rest
    parts = {"time": 0, "step": 0, "rest": 0}
    with h5netcdf.File(path, "r") as f:
        for v in f.variables.values():
            dims = v.dimensions
            key = dims[0] if dims and dims[0] in ("time", "step") else "rest"
            parts[key] += v._h5ds.id.get_storage_size()
    return parts


full, small = split(out), split(traced) if traced.exists() else {"time": float("nan")}
print(json.dumps({
    "per_output": full["time"] / spec["time"].values.size, "per_output_traced": small["time"] / spec["time"].values.size,
    "per_step": full["step"] / max(int(spec.attrs["solver_steps"]), 1), "fixed": full["rest"],
    "granules": problem.system.n, "steps": int(spec.attrs["solver_steps"]),
    "solver_s": float(spec.attrs["solver_wall_time_s"]), "equilibrium_iterations": eq.get("equilibrium_iterations"),
    "equilibrium_s": max(build_eq - build, 0.0), "build_s": build, "write_s": write_s,
    "result_bytes": out.stat().st_size,
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
    return (head + f"""equilibrate = true
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
""").replace("[simulation]", "gravity = [0.0, -9.81]\n[simulation]", 1)


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
        return f"{name:<22}{r['error']}"
    cost = r["solver_s"] / (r["granules"] * r["steps"])
    its = "-" if r["equilibrium_iterations"] is None else str(r["equilibrium_iterations"])
    outputs_per_ms = 1000  # at the default output_every, 1 us
    return (f"{name:<22}{r['granules']:>9}{cost * 1e9:>11.0f}{r['max_rss_bytes'] / 2**20:>9.0f}{its:>7}"
            f"{r['equilibrium_s']:>8.2f}{r['per_output'] / 1024:>12.1f}{r['per_output_traced'] / 1024:>9.2f}"
            f"{r['per_step']:>9.0f}{r['fixed'] / 2**20:>9.2f}{outputs_per_ms * r['per_output'] / 2**20:>12.1f}"
            f"{r['write_s'] / r['result_bytes'] * 2**20 * 1e3:>10.1f}")


def compression(repeat: int) -> None:
    """The paper's 0.8 ms run written at gzip levels 0, 1, 4 and 9: size, ratio, write time."""
    import time

    from granel import scenario as S
    from granel.io.results import write_spec_netcdf
    from granel.run import run_scenario

    spec = run_scenario(S.load("paper", []), dataset=False)
    print(f"\n(c) the paper's run, 0.8 ms, {spec['time'].values.size} outputs, {int(spec.attrs['solver_steps'])} steps")
    print(f"{'gzip level':>10}{'MiB':>9}{'of level 0':>12}{'write [s]':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        sizes = {}
        for level in (0, 1, 4, 9):
            spec.compression = level
            times = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                write_spec_netcdf(spec, Path(tmp) / "r.nc")
                times.append(time.perf_counter() - t0)
            sizes[level] = (Path(tmp) / "r.nc").stat().st_size
            print(f"{level:>10}{sizes[level] / 2**20:>9.2f}{sizes[level] / sizes[0]:>12.3f}{statistics.median(times):>11.2f}",
                  flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--largest", type=int, default=100_000, help="the largest packing (granules)")
    ap.add_argument("--steps", type=int, default=400, help="fixed steps of every run")
    ap.add_argument("--repeat", type=int, default=3, help="children per case (medians)")
    ap.add_argument("--only", choices=("chain", "box", "plate", "compression"), default=None)
    a = ap.parse_args()
    print(f"{a.steps} fixed steps of 20 ns, 21 outputs; medians of {a.repeat} fresh processes. Result: KiB per "
          "output (every granule; two traced), bytes per step, the fixed part (model record, scenario) in MiB, MiB "
          "per simulated ms at one output a microsecond, write time in ms per MiB")
    print(f"{'case':<22}{'granules':>9}{'ns/gr-st':>11}{'RSS MiB':>9}{'Newton':>7}{'eq. s':>8}{'KiB/out':>12}"
          f"{'traced':>9}{'B/step':>9}{'fixed':>9}{'MiB/sim.ms':>12}{'ms/MiB':>10}")
    if a.only in (None, "chain"):
        for n in (10, 100, 1000, 10000):
            print(row(f"chain on a wall", run_child(chain(n, a.steps), a.repeat)), flush=True)
    if a.only in (None, "box"):
        for n in (100, 1000, 10000, 100000):
            if n <= a.largest:
                print(row("packing in a box, g", run_child(packing(n, a.steps), a.repeat)), flush=True)
    if a.only in (None, "compression"):
        compression(a.repeat)
    if a.only in (None, "plate"):
        for n in (100, 1000):
            print(row("packing on the plate", run_child(packing(n, a.steps, "plate"), a.repeat)), flush=True)


if __name__ == "__main__":
    main()
