"""Coupled-solver scaling: seconds per simulated millisecond vs granules and vs solid DOFs.

Run: .venv/bin/python benchmarks/bench_scaling.py [--duration 0.05ms] [--repeat 1]

(a) granules against a proportionally longer plate: the LSGM replaced by a square-ish
    hexagonal medium of R = 5 mm granules (about 1,000 and 10,000), the plate as long as the
    medium's columns (0.2 m and 0.63 m, all its column-0 granules touching it), strong shock
    on LSGM:3. Beyond 8,000 DOFs the exact integrator computes only the modes below its cut-off
    (at most 600 with the automatic one; the first run computes and caches them), Newmark uses
    its sparse-direct path;
(a') the same granule counts against the paper's plate (the solid's cost held fixed);
(b) solid DOFs: the paper's 28 granules against the plate meshed more and more finely.
"""

from __future__ import annotations

import argparse
import time

from granel import scenario as S
from granel.run import run_scenario
from granel.io.units import parse_time


INTEGRATOR = []  # the fast method's solid integrator: exact (default) or newmark


def timed(overrides, duration):
    overrides = [*INTEGRATOR, *overrides]
    sc = S.load("paper", [f'simulation.duration="{duration}"', 'simulation.solver="fast"', *overrides])
    run_scenario(S.load("paper", ['simulation.duration="1us"', 'simulation.solver="fast"', *overrides]))  # modes, compile
    t0 = time.perf_counter()
    ds = run_scenario(sc)
    wall = time.perf_counter() - t0
    return wall, ds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", default="0.02ms")
    ap.add_argument("--integrator", choices=("newmark", "exact"), default="exact")
    ap.add_argument("--only", choices=("a", "a'", "b"), default=None, help="one section")
    a = ap.parse_args()
    INTEGRATOR[:] = [f'simulation.integrator="{a.integrator}"']
    ms = parse_time(a.duration) * 1e3
    if a.only == "a'":
        return granules_on_the_paper_plate(a.duration, ms)
    print(f"(a) granules and a proportionally longer plate ({a.duration} simulated)")
    print(f"{'granules':>10}{'plate [m]':>11}{'solid DOFs':>12}{'modes':>12}{'steps':>8}{'mean step [ns]':>16}"
          f"{'wall [s]':>10}{'s per sim. ms':>15}")
    for n0, ncol in ((20, 50), (63, 160)):
        L = 2 * 0.005 * n0
        ov = ["media.0.radius=0.005", f"media.0.columns={[n0, n0 - 1] * (ncol // 2)}", f"solid.length={L}"]
        wall, ds = timed(ov, a.duration)
        steps = int(ds.attrs["solver_steps"])
        print(f"{ds.sizes['granule']:>10}{L:>11.2f}{int(ds.attrs['solid_dofs']):>12}{_modes(ds):>12}{steps:>8}"
              f"{1e9 * ms * 1e-3 / steps:>16.1f}{wall:>10.2f}{wall / ms:>15.2f}")
    granules_on_the_paper_plate(a.duration, ms)
    print(f"\n(b) cost vs solid DOFs (28 granules, strong shock on SSGM:C, {a.duration} simulated)")
    print(f"{'mesh':>22}{'solid DOFs':>12}{'wall [s]':>10}{'s per sim. ms':>15}")
    for nx, g, mx in ((4, 2.0, 5e-3), (6, 1.6, 2e-3), (8, 1.6, 2.5e-3)):
        ov = ['excitations.0.granule="SSGM:C"', f"solid.mesh.nx={nx}", f"solid.mesh.growth={g}", f"solid.mesh.max_size={mx}"]
        wall, ds = timed(ov, a.duration)
        print(f"{f'nx={nx}, g={g}, max={mx}':>22}{int(ds.attrs['solid_dofs']):>12}{wall:>10.2f}{wall / ms:>15.2f}")


def _modes(ds) -> str:
    """Propagated modes: eigenmodes + residual modes (the exact integrator), or all (Newmark)."""
    if "solver_modes_kept" in ds.attrs:
        return f"{int(ds.attrs['solver_modes_kept'])}+{int(ds.attrs['solver_residual_modes'])}"
    return str(int(ds.attrs["solid_dofs"]))


def granules_on_the_paper_plate(duration, ms):
    print(f"\n(a') cost vs granules (the paper's plate, {duration} simulated, {INTEGRATOR[0]})")
    print(f"{'granules':>10}{'solid DOFs':>12}{'modes':>12}{'steps':>8}{'mean step [ns]':>16}{'wall [s]':>10}"
          f"{'s per sim. ms':>15}{'us per granule-step':>22}")
    rows = []
    for pairs in (0, 50, 526):
        ov = [] if pairs == 0 else ["media.0.radius=0.005", f"media.0.columns={[10, 9] * pairs}"]
        wall, ds = timed(ov, duration)
        n = ds.sizes["granule"]
        steps = int(ds.attrs["solver_steps"])
        kept = _modes(ds)
        rows.append((n, wall / ms))
        print(f"{n:>10}{int(ds.attrs['solid_dofs']):>12}{kept:>12}{steps:>8}{1e9 * ms * 1e-3 / steps:>16.1f}{wall:>10.2f}"
              f"{wall / ms:>15.2f}{1e6 * wall / (steps * n):>22.3f}")
    (n1, c1), (n2, c2) = rows[1], rows[2]
    print(f"cost ratio {c2 / c1:.2f} for granule ratio {n2 / n1:.2f} (linear: equal)")


if __name__ == "__main__":
    main()
