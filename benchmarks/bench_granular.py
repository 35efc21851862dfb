"""Granular RK4 throughput: granule-steps per second (one RK4 step = one step).

Run: .venv/bin/python benchmarks/bench_granular.py [--repeat 5]
Prints medians over repeats for the paper's 28 granules (rigid solid, strong shock on
SSGM:C) and for a ~10,000-granule hexagonal block hit by a striker.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from granel import scenario as S
from granel.granular.packing import hexagonal_block, medium_from_table
from granel.granular.system import ContactLaw, Stepper, build_system, initial_state
from granel.granular.materials import STEEL


def paper_case():
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"'])
    system, state, _ = S.build_granular(sc)
    return system, state, 4e-8, 5000


def block_case(nx=100, ny=100):
    pos = hexagonal_block(nx, ny, 0.005)
    med = medium_from_table("B", [dict(label=str(i), x=x, y=y, radius=0.005) for i, (x, y) in enumerate(pos)], STEEL)
    system = build_system([med], ContactLaw())
    v = np.zeros((system.n, 2))
    v[: nx, 1] = 1.0  # the bottom row strikes upward
    return system, initial_state(system, v), 4e-8, 200


def measure(make, repeat):
    rates = []
    for _ in range(repeat):
        system, state, dt, steps = make()
        stepper = Stepper(system)
        stepper.advance(state, dt, 2)  # compile / warm
        t0 = time.perf_counter()
        stepper.advance(state, dt, steps)
        rates.append(system.n * steps / (time.perf_counter() - t0))
    return system.n, statistics.median(rates), rates


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    print(f"{'case':<28}{'granules':>10}{'granule-steps/s (median)':>28}{'min':>12}{'max':>12}")
    results = {}
    for name, make in (("paper, 28 granules", paper_case), ("hexagonal block 100x100", block_case)):
        n, med, rates = measure(make, a.repeat)
        results[name] = med
        print(f"{name:<28}{n:>10}{med:>28.3e}{min(rates):>12.3e}{max(rates):>12.3e}")
    r = list(results.values())
    print(f"ratio large/small throughput: {r[1] / r[0]:.2f}")


if __name__ == "__main__":
    main()
