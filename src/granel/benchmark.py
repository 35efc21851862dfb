"""`granel bench`: the paper's algorithm and the fast method (Newmark, and the exact modal
integrator) on the same cases, in one process. Accuracy columns are differences from the paper's
algorithm, which is itself about 1.6e-3 off a converged solution at its 40 ns (docs/performance.md
measures against converged references)."""

from __future__ import annotations

import tempfile
import time

import numpy as np

from .report import CASES, case_scenario, case_tag


def energy_deviation_pct(a, b) -> float:
    """Largest difference of the normalised energy curves (LSGM, SSGM, solid) [% of input]."""
    n = min(a.sizes["time"], b.sizes["time"])
    wa, wb = float(a["input_work"].values.max()), float(b["input_work"].values.max())
    dev = 0.0
    for k in ("energy_lsgm", "energy_ssgm", "energy_solid"):
        dev = max(dev, float(np.abs(a[k].values[:n] / wa - b[k].values[:n] / wb).max()))
    return 100 * dev


def velocity_rel_l2(a, b, tmax=4e-4) -> float:
    """Relative L2 difference of the measured granule's velocity over the first 0.4 ms. The
    measured granule is the one opposite the excited one (3 <-> C), as in Fig. 3."""
    from .analysis.reciprocity import directed_velocity, excitation_of, toward_solid
    import tomllib

    label, _ = excitation_of(a)
    measured = "SSGM:C" if label.startswith("LSGM") else "LSGM:3"
    d = toward_solid(tomllib.loads(a.attrs["scenario"]), measured)
    n = min(a.sizes["time"], b.sizes["time"])
    sel = a["time"].values[:n] <= tmax + 1e-12
    va = directed_velocity(a, measured, d)[:n][sel]
    vb = directed_velocity(b, measured, d)[:n][sel]
    den = np.linalg.norm(va)
    return float(np.linalg.norm(vb - va) / den) if den > 0 else 0.0


def run_bench(quick=False, only=None, duration=None, log=print) -> dict:
    from .run import run_scenario

    dur = duration or ("0.1ms" if quick else "0.8ms")
    out = {"duration": dur, "cases": []}
    # the three methods on the one core: the paper's algorithm, the fast method with Newmark (its
    # default) and with the exact modal integrator (error-controlled steps)
    methods = {"paper": ("paper", []), "fast": ("fast", []), "exact": ("fast", ['simulation.integrator="exact"'])}
    # compile and cache the modes outside the timings (the methods share the cost otherwise)
    for solver, extra in methods.values():
        for solid in ("plate", "beam"):
            run_scenario(case_scenario((solid, "SSGM:C", "weak"), solver, ['simulation.duration="2us"', *extra]))
    for case in CASES:
        if only and case_tag(case) not in only:
            continue
        res = {}
        for name, (solver, extra) in methods.items():
            sc = case_scenario(case, solver, [f'simulation.duration="{dur}"', *extra])
            t0 = time.perf_counter()
            res[name] = run_scenario(sc)
            res[name + "_s"] = time.perf_counter() - t0
        row = {"solid": case[0], "excite": case[1], "shock": case[2], "paper_s": res["paper_s"], "fast_s": res["fast_s"],
               "ratio": res["paper_s"] / res["fast_s"], "energy_dev_pct": energy_deviation_pct(res["paper"], res["fast"]),
               "velocity_rel_l2": velocity_rel_l2(res["paper"], res["fast"]),
               "paper_steps": int(res["paper"].attrs["solver_steps"]), "fast_steps": int(res["fast"].attrs["solver_steps"]),
               "paper_min_step": float(res["paper"].attrs["solver_min_step"]),
               "exact_s": res["exact_s"], "exact_ratio": res["paper_s"] / res["exact_s"],
               "exact_steps": int(res["exact"].attrs["solver_steps"]),
               "exact_energy_dev_pct": energy_deviation_pct(res["paper"], res["exact"]),
               "exact_velocity_rel_l2": velocity_rel_l2(res["paper"], res["exact"])}
        out["cases"].append(row)
        log(f"{case_tag(case)}: paper {row['paper_s']:.2f} s, fast {row['fast_s']:.3f} s (ratio {row['ratio']:.1f}), "
            f"exact {row['exact_s']:.3f} s (ratio {row['exact_ratio']:.1f}, {row['exact_steps']} steps); against the paper: "
            f"energy {row['energy_dev_pct']:.4f} / {row['exact_energy_dev_pct']:.4f} %, velocity L2 "
            f"{row['velocity_rel_l2']:.2e} / {row['exact_velocity_rel_l2']:.2e}")
    out["paper_total_s"] = None
    if not quick:
        from .report import paper_study

        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            paper_study(d, "fast", reuse=False, animations=False)
            out["paper_total_s"] = time.perf_counter() - t0
    return out
