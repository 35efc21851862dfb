"""`granel bench`: the paper's algorithm and the fast method (its default exact integrator, and
modal Newmark at dtau0) on the same cases, in one process, with every figure beside its ratio.

Deviations from the paper's algorithm say how close two discretisations are, not how accurate
they are. With `reference=True` the strong SSGM-side plate case is also run by modal Newmark at a
fixed 2.5 ns, a near-converged reference, and each method's errors against it are reported
(docs/performance.md, "Accuracy", gives how far each is from a converged solution)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..analysis.balance import relative_balance_error
from ..guard.exits import InputError
from ..scenario.estimate import check_needs
from .paper import CASES, case_scenario, case_tag

# the three methods on the one core: the paper's algorithm, the fast method with its default
# exact integrator, and with modal Newmark at dtau0
METHODS = {"paper": ("paper", []), "exact": ("fast", []), "newmark": ("fast", ['simulation.integrator="newmark"'])}
REFERENCE_CASE = ("plate", "SSGM:C", "strong")
# built-in scenarios beyond the paper's set-up, run by every method as the paper's cases are (their own
# duration unless --duration says; --quick: 0.1 ms); with --reference each against Newmark at 2.5 ns
SCENARIO_CASES = ("chain-on-plate",)


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
    from ..analysis.reciprocity import directed_velocity, excitation_of, measured_along

    label, _ = excitation_of(a)
    measured = "SSGM:C" if label.startswith("LSGM") else "LSGM:3"
    d = measured_along(a, measured)
    n = min(a.sizes["time"], b.sizes["time"])
    sel = a["time"].values[:n] <= tmax + 1e-12
    va = directed_velocity(a, measured, d)[:n][sel]
    vb = directed_velocity(b, measured, d)[:n][sel]
    den = np.linalg.norm(va)
    return float(np.linalg.norm(vb - va) / den) if den > 0 else 0.0


def errors(ds, ref) -> dict:
    """A run against a reference of the same case: the largest energy difference (LSGM, SSGM,
    solid) over the input, the relative L2 difference of the excited granule's velocity and of the
    measured one in the other medium (3 <-> C) over the whole run, and the run's balance (13)."""
    from ..analysis.reciprocity import directed_velocity, excitation_of

    w = float(ref["input_work"].values.max())
    out = {"energy": max(float(np.abs(ds[k].values - ref[k].values).max()) / w
                         for k in ("energy_lsgm", "energy_ssgm", "energy_solid"))}
    lab, d = excitation_of(ref)
    for key, g in (("v_excited", lab), ("v_far", "SSGM:C" if lab.startswith("LSGM") else "LSGM:3")):
        a, b = directed_velocity(ds, g, d), directed_velocity(ref, g, d)
        out[key] = float(np.linalg.norm(a - b) / np.linalg.norm(b))
    out["balance"] = relative_balance_error(ds)
    return out


def scenario_deviations(a, b) -> tuple[float, float]:
    """Two runs of one scenario: the largest difference of every energy the runs store (the media,
    the solid, the walls, gravity's) over the input work [%], and the relative L2 difference of
    the excited granule's velocity along its load."""
    from ..analysis.reciprocity import directed_velocity, excitation_of

    n = min(a.sizes["time"], b.sizes["time"])
    w = float(b["input_work"].values.max())
    names = [k for k in b.data_vars if k.startswith("energy_") and k in a.data_vars]
    energy = max(float(np.abs(a[k].values[:n] - b[k].values[:n]).max()) / w for k in names)
    label, d = excitation_of(b)
    va, vb = directed_velocity(a, label, d)[:n], directed_velocity(b, label, d)[:n]
    return 100 * energy, float(np.linalg.norm(va - vb) / np.linalg.norm(vb))


def scenario_case(name: str, solver: str, extra=()):
    """A built-in scenario (`SCENARIO_CASES`) under `solver` with `extra` overrides."""
    from .. import scenario as S

    return S.load(name, [f'simulation.solver="{solver}"', *extra])


def _bench_scenarios(only, duration, quick, reference, log) -> list[dict]:
    """The rows of the scenario cases (`SCENARIO_CASES`), as the paper's: each method's time and
    steps, its ratio to the paper's algorithm and its deviation from it; with `reference`, each
    method's errors against Newmark at a fixed 2.5 ns (energies over the input, the excited
    granule's velocity, the balance (13))."""
    from ..run import run_scenario

    rows = []
    for name in SCENARIO_CASES:
        if only and name not in only:
            continue
        dur = duration or ("0.1ms" if quick else None)
        span = [f'simulation.duration="{dur}"'] if dur else []
        for solver, extra in METHODS.values():  # compile and cache the modes outside the timings
            run_scenario(scenario_case(name, solver, ['simulation.duration="2us"', *extra]))
        res, row = {}, {"tag": name}
        for method, (solver, extra) in METHODS.items():
            t0 = time.perf_counter()
            res[method] = run_scenario(scenario_case(name, solver, [*span, *extra]))
            row[method + "_s"] = time.perf_counter() - t0
            row[method + "_steps"] = int(res[method].attrs["solver_steps"])
        for method in ("exact", "newmark"):
            row[method + "_ratio"] = row["paper_s"] / row[method + "_s"]
            row[method + "_energy_dev_pct"], row[method + "_velocity_rel_l2"] = scenario_deviations(res[method],
                                                                                                  res["paper"])
        if reference:
            ref = run_scenario(scenario_case(name, "fast", [*span, 'simulation.dt="2.5ns"',
                                                            'simulation.integrator="newmark"']))
            row["reference"] = {}
            for method in METHODS:
                energy, velocity = scenario_deviations(res[method], ref)
                row["reference"][method] = {"energy": energy / 100, "v_excited": velocity,
                                            "balance": relative_balance_error(res[method])}
                log(f"{name} against Newmark at 2.5 ns: {method}: energies {energy / 100:.1e}, velocity "
                    f"{velocity:.1e}, balance {row['reference'][method]['balance']:.1e}")
        log(f"{name}: paper {row['paper_s']:.2f} s, exact {row['exact_s']:.3f} s (ratio {row['exact_ratio']:.1f}, "
            f"{row['exact_steps']} steps), newmark {row['newmark_s']:.3f} s (ratio {row['newmark_ratio']:.1f})")
        rows.append(row)
    return rows


def fresh_run_seconds(case, duration: str | None = None) -> float:
    """Wall time of a `granel run` of a paper case in a fresh process (imports, compiled-code
    cache, modes, run, NetCDF write)."""
    solid, exc, shock = case
    with tempfile.TemporaryDirectory() as d:
        cmd = [sys.executable, "-m", "granel", "run", "paper", "--solid", solid, "--excite", exc, "--shock", shock,
               "-o", str(Path(d) / "r.nc")]
        if duration:
            cmd += ["--duration", duration]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        return time.perf_counter() - t0


def check_duration(duration: str) -> None:
    """Whether the cases can run for `duration`: the reference case under the paper's algorithm
    loaded with it (the scenario's own checks: the step, the outputs) and its memory
    (`scenario.estimate.check_needs`). InputError saying why not."""
    check_needs(case_scenario(REFERENCE_CASE, "paper", [f'simulation.duration="{duration}"']))


def run_bench(quick=False, only=None, duration=None, reference=False, fresh=True, log=print) -> dict:
    from ..run import run_scenario

    dur = duration or ("0.1ms" if quick else "0.8ms")
    out = {"duration": dur, "cases": []}
    # compile and cache the modes outside the timings (the methods share the cost otherwise)
    for solver, extra in METHODS.values():
        for solid in ("plate", "beam"):
            run_scenario(case_scenario((solid, "SSGM:C", "weak"), solver, ['simulation.duration="2us"', *extra]))
    results = {}
    for case in CASES:
        if only and case_tag(case) not in only:
            continue
        res, row = {}, {"tag": case_tag(case), "solid": case[0], "excite": case[1], "shock": case[2]}
        for name, (solver, extra) in METHODS.items():
            sc = case_scenario(case, solver, [f'simulation.duration="{dur}"', *extra])
            t0 = time.perf_counter()
            res[name] = run_scenario(sc)
            row[name + "_s"] = time.perf_counter() - t0
            row[name + "_steps"] = int(res[name].attrs["solver_steps"])
        row["paper_min_step"] = float(res["paper"].attrs["solver_min_step"])
        for name in ("exact", "newmark"):
            row[name + "_ratio"] = row["paper_s"] / row[name + "_s"]
            row[name + "_energy_dev_pct"] = energy_deviation_pct(res["paper"], res[name])
            row[name + "_velocity_rel_l2"] = velocity_rel_l2(res["paper"], res[name])
        results[case] = res
        out["cases"].append(row)
        log(f"{case_tag(case)}: paper {row['paper_s']:.2f} s, exact {row['exact_s']:.3f} s (ratio {row['exact_ratio']:.1f}, "
            f"{row['exact_steps']} steps), newmark {row['newmark_s']:.3f} s (ratio {row['newmark_ratio']:.1f}); against "
            f"the paper: energy {row['exact_energy_dev_pct']:.4f} / {row['newmark_energy_dev_pct']:.4f} %, velocity L2 "
            f"{row['exact_velocity_rel_l2']:.2e} / {row['newmark_velocity_rel_l2']:.2e}")
    out["scenario_cases"] = _bench_scenarios(only, duration, quick, reference, log)
    for name in METHODS:
        out[name + "_total_s"] = sum(r[name + "_s"] for r in [*out["cases"], *out["scenario_cases"]])
    if reference and REFERENCE_CASE in results:
        ref = run_scenario(case_scenario(REFERENCE_CASE, "fast", [f'simulation.duration="{dur}"', 'simulation.dt="2.5ns"',
                                                                  'simulation.integrator="newmark"']))
        out["reference"] = {name: errors(results[REFERENCE_CASE][name], ref) for name in METHODS}
        for name, e in out["reference"].items():
            log(f"{case_tag(REFERENCE_CASE)} against Newmark at 2.5 ns: {name}: energies {e['energy']:.1e}, velocities "
                f"{e['v_excited']:.1e} / {e['v_far']:.1e}, balance {e['balance']:.1e}")
    if fresh:
        out["fresh_run_s"] = fresh_run_seconds(REFERENCE_CASE, None if dur == "0.8ms" else dur)
        out["fresh_short_run_s"] = fresh_run_seconds(("beam", "SSGM:C", "strong"), "0.01ms")
        log(f"fresh `granel run`: {case_tag(REFERENCE_CASE)} {out['fresh_run_s']:.2f} s, beam 0.01 ms "
            f"{out['fresh_short_run_s']:.2f} s")
    out["paper_study_s"] = None
    if not quick:
        from .paper import PaperOptions, paper_study

        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            paper_study(d, PaperOptions("fast", reuse=False, animations=False))
            out["paper_study_s"] = time.perf_counter() - t0
    return out


def check_bench_options(cases: str | None, duration: str | None) -> list[str] | None:
    """`granel bench --cases` (paper case tags or built-in scenario cases, comma separated) and
    `--duration` (a positive
    simulated time the paper cases can run: the scenario's own checks), checked before any
    benchmark runs; returns the cases asked for (None: all). InputError naming the option."""
    from ..io.units import parse_time

    only = None
    if cases is not None:
        tags = [case_tag(c) for c in CASES] + list(SCENARIO_CASES)
        only = [c.strip() for c in cases.split(",")]
        unknown = [c for c in only if c not in tags]
        if unknown:
            raise InputError(f"--cases {cases!r}: no case {unknown[0]!r}; choose from {', '.join(tags)}")
    if duration is not None:
        try:
            t = parse_time(duration)
        except ValueError:
            t = float("nan")
        if not (np.isfinite(t) and t > 0):
            raise InputError(f"--duration {duration!r}: give a positive simulated time, e.g. 0.1ms")
        try:
            check_duration(duration)
        except InputError as e:
            raise InputError(f"--duration {duration}: {e}") from None
    return only


def bench_rows(res: dict) -> tuple[list[str], list[list[str]]]:
    """`granel bench`'s table of `run_bench`'s cases: (header, rows)."""
    header = ["case", "paper [s]", "exact [s]", "ratio", "steps", "newmark [s]", "ratio", "energy dev [% input]",
              "velocity rel L2"]
    rows = [[c["tag"], f"{c['paper_s']:.2f}", f"{c['exact_s']:.3f}", f"{c['exact_ratio']:.1f}",
             str(c["exact_steps"]), f"{c['newmark_s']:.3f}", f"{c['newmark_ratio']:.1f}",
             f"{c['exact_energy_dev_pct']:.4f} / {c['newmark_energy_dev_pct']:.4f}",
             f"{c['exact_velocity_rel_l2']:.2e} / {c['newmark_velocity_rel_l2']:.2e}"]
            for c in [*res["cases"], *res.get("scenario_cases", [])]]
    return header, rows
