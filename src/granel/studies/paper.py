"""`granel paper`: the twelve cases, the modal analysis, every figure (1-11), the Appendix C
animations and a report that sets each of the paper's statements beside granel's measured number
(`granel.studies.claims`), on the walled geometry and, for comparison, on the free-edge variant."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from .. import scenario as S
from .claims import CASES, case_tag, claims, fig11_measures, measurements, summary_line, tally, verdict_flips
from ..io.results import read_netcdf, with_every_granule, write_netcdf

FREE_EDGE = ("media.0.outer_wall=false", "media.1.outer_wall=false")
# the paper's own ambiguity: whether the SSGM has an outer wall when the LSGM is shocked (MODEL.md)
NO_SSGM_WALL = ("media.1.outer_wall=false",)
FIG11_CASE = ("plate", "SSGM:C", "strong")
FIG11_WINDOW = 2e-4  # the window of the paper's Fig. 11, 0-0.2 ms

# The paper's own slips that the model had to resolve: (where, what the paper prints, what granel does)
ERRATA = (
    ("Fig. 3 caption", "calls granule 3 part of the SSGM and granule C part of the LSGM",
     "granule 3 is in the LSGM and C in the SSGM, as in the text and Fig. 1(b); the legends name both"),
    ("Eq. (15)", "writes the modal kinetic energy with K: 1/2 Xdot_n^2 phi_n' K phi_n",
     "uses M there: with mass-normalised modes E_n = 1/2 (Xdot_n^2 + w_n^2 X_n^2), which sums to eq. (11)"),
    ("Sec. IV, on Fig. 5(c)", "says the asymmetric energy density excites \"the symmetric axial modes\"",
     "reads bulk modes: the symmetric family of Fig. 6(d); the axial mode 4 is antisymmetric and stays unexcited"),
    ("Sec. IV, on Fig. 7", "says the axial mode \"has no counterpart in the thin plate model\"",
     "reads the beam model: the beam has no axial (u_y) degree of freedom"),
    ("App. B", "refers the contact labels 10, 11, 12, J, K, L to Fig. 10(b)", "uses the labels of Fig. 1(b)"),
)


def case_scenario(case, solver: str = "fast", extra=()) -> S.Scenario:
    solid, exc, shock = case
    return S.load("paper", [f'solid.kind="{solid}"', f'excitations.0.granule="{exc}"', f'excitations.0.shock="{shock}"',
                            f'simulation.solver="{solver}"', *extra])


def _cached(path: Path, sc: S.Scenario):
    """A stored result of exactly this scenario that reached its duration, else None (one of an
    earlier granel gets its model record, `run.with_model_record`)."""
    from ..io.results import check_result_schema
    from ..run import with_model_record

    if not path.exists():
        return None
    try:
        ds = read_netcdf(path)
        check_result_schema(ds, path)
    except Exception:  # noqa: BLE001 - truncated, corrupt, foreign, damaged: run it again
        return None
    if ds.attrs.get("scenario") == S.to_toml(sc) and float(ds["time"].values[-1]) >= sc.simulation.duration * (1 - 1e-9):
        try:
            return with_every_granule(with_model_record(ds, path))
        except Exception:  # noqa: BLE001 - its model does not fit it: run it again
            return None
    return None


def run_case(sc: S.Scenario, path: Path, reuse: bool):
    """(Dataset, wall seconds or 'cached'): run `sc` into `path`, or reuse the stored result."""
    from ..run import run_scenario

    ds = _cached(path, sc) if reuse else None
    if ds is not None:
        return ds, "cached"
    t0 = time.perf_counter()
    ds = run_scenario(sc)
    wall = time.perf_counter() - t0
    path.parent.mkdir(parents=True, exist_ok=True)
    write_netcdf(ds, path)
    return with_every_granule(ds), wall


def run_cases(out: Path, solver="fast", reuse=True, progress=None, extra=(), subdir="runs") -> tuple[dict, dict]:
    """Run (or reuse) the twelve cases into OUT/subdir; returns ({case: Dataset}, {case: wall seconds or 'cached'})."""
    runs, walls = {}, {}
    for case in CASES:
        runs[case], walls[case] = run_case(case_scenario(case, solver, extra), Path(out) / subdir / f"{case_tag(case)}.nc", reuse)
        if progress:
            progress(case, walls[case])
    return runs, walls


def _spawn_pool():
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn"))


def _fig11_path(out, reuse, extra, window):
    """`fig11_run` in a worker process: (path of the stored run, how it was obtained)."""
    _, how = fig11_run(Path(out), reuse, extra, window)
    return fig11_path(Path(out), window), how


def fig11_path(out: Path, window=FIG11_WINDOW) -> Path:
    return Path(out) / "runs" / f"paper-solver-{case_tag(FIG11_CASE)}-0-{window * 1e3:g}ms.nc"


def fig11_run(out: Path, reuse=True, extra=(), window=FIG11_WINDOW):
    """The paper's algorithm itself on the strong SSGM-side plate case over Fig. 11's window.
    Returns (Dataset, how it was obtained)."""
    sc = case_scenario(FIG11_CASE, "paper", [*extra, f"simulation.duration={window!r}"])
    path = fig11_path(out, window)
    ds, wall = run_case(sc, path, reuse)
    how = f"cached run {path.parent.name}/{path.name}" if wall == "cached" else f"run now in {wall:.0f} s ({path.parent.name}/{path.name})"
    return ds, how


# ---------------------------------------------------------------- the report


def _cell(text) -> str:
    """Text for a Markdown table cell: a '|' (|lambda|, |balance error|) would end the cell."""
    return str(text).replace("|", "\\|")


def _verdict_cell(c) -> str:
    """The verdict, with the reason when the statement holds (or should hold) by construction."""
    if c.by_construction:
        return f"**{c.verdict}**: {_cell(c.construction)}"
    if c.construction:
        return f"**{c.verdict}** (expected by construction, so a bug of granel: {_cell(c.construction)})"
    return f"**{c.verdict}**"


def _claims_table(rows) -> list[str]:
    lines = ["| # | where | statement | paper | granel | rule | verdict |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for k, c in enumerate(rows, 1):
        cells = (c.where, c.claim, c.paper, c.granel, c.rule)
        lines.append(f"| {k} | " + " | ".join(_cell(x) for x in cells) + f" | {_verdict_cell(c)} |")
    return lines


def _flips_table(flips, base: str, variant: str) -> list[str]:
    """The statements whose verdict changes between two variants: verdicts and granel's values."""
    lines = [f"| # | where | statement | verdict {base} | verdict {variant} | value {base} | value {variant} |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for f in flips:
        lines.append(f"| {f.number} | {_cell(f.where)} | {_cell(f.claim)} | **{f.base_verdict}** | **{f.variant_verdict}** | "
                     f"{_cell(f.base_value)} | {_cell(f.variant_value)} |")
    return lines


def _cases_table(m: dict, walls: dict) -> list[str]:
    lines = ["| case | wall [s] | solid arrival [ms] | solid peak [% input] at [ms] | dissipated [% input] | modes for 90 / 99 % | max balance error [rel] |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for case in CASES:
        c = m["cases"].get(case_tag(case))
        if c is None:
            continue
        w = walls.get(case, "")
        w = f"{w:.2f}" if isinstance(w, float) else str(w)
        lines.append(f"| {case_tag(case)} | {w} | {c['solid_arrival_ms']:.4f} | {100 * c['solid_peak_frac']:.2f} at {c['solid_peak_time_ms']:.3f} | "
                     f"{100 * c['dissipated_frac']:.1f} | {c['modes_90']} / {c['modes_99']} | {c['max_balance_error_rel']:.1e} |")
    return lines


def _free_edge_table(walled, free) -> list[str]:
    lines = ["| # | statement | three walls | free edge |", "| --- | --- | --- | --- |"]
    other = {(c.where, c.claim): c for c in free}
    for k, a in enumerate(walled, 1):
        b = other.get((a.where, a.claim))
        if b is None:
            lines.append(f"| {k} | {_cell(a.claim)} | {_cell(a.granel)}: **{a.verdict}** | not checked (changed) |")
            continue
        changed = " (changed)" if a.verdict != b.verdict else ""
        lines.append(f"| {k} | {_cell(a.claim)} | {_cell(a.granel)}: **{a.verdict}** | {_cell(b.granel)}: **{b.verdict}**{changed} |")
    return lines


def _variant_section(rows, variant_rows) -> list[str]:
    """The paper's ambiguity about the SSGM's outer wall, as a variant: which verdicts flip when it
    is removed in the cases shocked from the LSGM (the SSGM's outer column is then the far edge)."""
    flips = verdict_flips(rows, variant_rows)
    t, tf = tally(rows), tally(variant_rows)
    to_agree = sum(f.variant_verdict == "agree" for f in flips)
    to_differ = sum(f.variant_verdict == "differ" for f in flips)
    lines = ["", "## The paper's ambiguity: the SSGM's outer wall, as a variant", "",
             "The paper says \"three of the four boundaries of each granular medium are clamped\" (Sec. II: top, bottom and",
             "outer, the fourth being the solid) yet excites the interface \"from the free edge of either the LSGM or SSGM\";",
             "whether the SSGM has an outer wall when the shock comes from the LSGM is left open (MODEL.md section 1).",
             "granel keeps it; the variant removes it (`media.1.outer_wall = false`) in the six LSGM-shocked cases (runs in",
             "`runs-no-ssgm-wall/`; the SSGM-shocked cases are those above). The statements whose verdict flips:", "",
             *_flips_table(flips, "with the wall", "without"), "",
             f"{len(flips)} of {len(rows)} verdicts flip without the SSGM's outer wall: {to_agree} to agree, {to_differ} to "
             f"differ. {_both_counts(t, tf, 'with the wall', 'without')}. "
             + ("Neither reading makes every checked statement agree." if t["differ"] and tf["differ"] else "")]
    return lines


def _both_counts(t: dict, tf: dict, base: str = "with the outer walls", variant: str = "without") -> str:
    """The agreement counts of the walled runs (`t`) and a variant (`tf`), in one sentence."""
    held = (f"{t['by_construction']} hold by construction in both" if t["by_construction"] == tf["by_construction"]
            else f"by construction: {t['by_construction']} {base}, {tf['by_construction']} {variant}")
    return (f"Checked statements that agree: {t['agree']} of {t['checked']} {base}, "
            f"{tf['agree']} of {tf['checked']} {variant} ({held})")


def write_report(out: Path, m: dict, walls: dict, figures: list, total_s: float, solver: str, m_free: dict | None = None,
                 m_variant: dict | None = None) -> Path:
    rows = claims(m)
    free_rows = claims(m_free) if m_free is not None else None
    variant_rows = claims(m_variant) if m_variant is not None else None
    held = [(k, c) for k, c in enumerate(rows, 1) if c.by_construction]
    lines = ["# granel vs Wang, Tawfick & Vakakis, Phys. Rev. E 104, 044906 (2021)", "",
             f"Generated by `granel paper` with the `{solver}` solver on the paper's geometry with three rigid walls per",
             "granular medium (top, bottom, outer; MODEL.md section 1). Every number below is computed from the result",
             "files in `runs/`; none is typed in. The rules are explained once in `granel.studies.claims`: \"about X\" agrees",
             "within +-30 %, a range agrees inside it, a three-figure number within 1 %, a comparison when it holds.",
             "A statement that follows from the model's symmetry, a bound the solver enforces or a rule granel applies",
             "could not have come out otherwise: its verdict is \"by construction\", with the reason, and it is not",
             "counted as agreement.", "",
             "## Claims", "", *_claims_table(rows), "", f"**{summary_line(rows)}.**"
             + (" By construction, not counted: " + "; ".join(f"#{k} ({c.where})" for k, c in held) + "." if held else "")]
    if variant_rows is not None:
        lines += _variant_section(rows, variant_rows)
    lines += ["", "## The twelve cases", "", *_cases_table(m, walls), "",
              "Arrival at the solid: the first time its energy reaches 1 % of its peak. Arrival at a granule: the first",
              "time its velocity toward the solid reaches 5 % of its peak. Modes for 90 / 99 %: eq. (16)."]
    if free_rows is not None:
        changed = len(verdict_flips(rows, free_rows))
        lines += ["", "## What the outer walls change: the free-edge variant", "",
                  "The same twelve cases with `outer_wall = false` on both media (runs in `runs-free-edge/`): the outer",
                  "column is free, and after the wave passes the outer granules fly off at constant speed. Every statement,",
                  f"with the walls and without. {_both_counts(tally(rows), tally(free_rows))}; {changed} verdicts change.", "",
                  *_free_edge_table(rows, free_rows)]
    lines += ["", "## Errata: the paper's slips and what granel does", "", "| where | the paper | granel |", "| --- | --- | --- |"]
    lines += [f"| {w} | {p} | {g} |" for w, p, g in ERRATA]
    if "fig11" in m:
        f = m["fig11"]
        lines += ["", "## Fig. 11", "", f"From the paper's own algorithm (fixed point A4, step by B1), {f['source']}: {f['steps']} steps over "
                  f"0-{f['window_ms']:g} ms, smallest {f['min_step']:.3g} s."]
    lines += ["", "## Figures and animations", ""]
    for f in figures:
        lines.append(f"- [{Path(f).name}]({Path(f).relative_to(out)})")
    lines += ["", f"Total wall time of `granel paper`: {total_s:.1f} s."]
    from ..guard.owners import MARK, text_mark
    from ..guard.writing import write_text

    path = write_text(out / "report.md", "\n".join([text_mark("<!--"), *lines]) + "\n")
    dump = {"written_by": MARK, "measurements": m, "claims": [c.row() for c in rows],
            "summary": tally(rows) | {"line": summary_line(rows)}}
    if free_rows is not None:
        dump["free_edge"] = {"measurements": m_free, "claims": [c.row() for c in free_rows],
                             "summary": tally(free_rows) | {"line": summary_line(free_rows)},
                             "flips": [f.row() for f in verdict_flips(rows, free_rows)]}
    if variant_rows is not None:
        dump["no_ssgm_outer_wall"] = {"claims": [c.row() for c in variant_rows],
                                      "summary": tally(variant_rows) | {"line": summary_line(variant_rows)},
                                      "flips": [f.row() for f in verdict_flips(rows, variant_rows)]}
    write_text(out / "measurements.json", json.dumps(dump, indent=1, default=_jsonable))
    return path


def _jsonable(x):
    import numpy as np

    if isinstance(x, np.ndarray):
        return x[:50].tolist()  # the accumulation curves: their head is what the claims read
    if isinstance(x, np.generic):
        return x.item()
    return str(x)


# ---------------------------------------------------------------- the study


def movie_jobs(out: Path, frames: int) -> list[tuple]:
    """Appendix C in full: deformation and energy-density movies of all twelve cases."""
    return [(out / "runs" / f"{case_tag(c)}.nc", out / "animations" / f"{case_tag(c)}-{field}.mp4", field, None, frames, 20)
            for c in CASES for field in ("deformation", "energy-density")]


def run_count(free_edge: bool = True) -> int:
    """The runs `paper_study` reports one by one to its progress: the twelve cases and, with
    `free_edge`, their reruns without the outer walls and the LSGM-shocked cases without the
    SSGM's outer wall."""
    variants = len(CASES) + sum(case[1].startswith("LSGM") for case in CASES) if free_edge else 0
    return len(CASES) + variants


@dataclass(frozen=True)
class PaperOptions:
    """How `granel paper` runs: the solver of the cases ("fast" or "paper"), whether stored
    validated runs are reused, the movies (and their frame count), the free-edge and no-outer-wall
    variants of the claims, the window of Fig. 11 [s], the worker processes, and `extra`
    overrides of every case's scenario (e.g. a shorter duration for a smoke test)."""

    solver: str = "fast"
    reuse: bool = True
    animations: bool = True
    extra: tuple = ()
    frames: int = 120
    free_edge: bool = True
    fig11_window: float = FIG11_WINDOW
    workers: int = 2


def paper_study(out: str | Path, options: PaperOptions = PaperOptions(), progress=None) -> dict:
    """Everything `granel paper` does, as `options` say; returns a summary dict."""
    solver, reuse, extra, workers = options.solver, options.reuse, tuple(options.extra), options.workers
    fig11_window = options.fig11_window
    from ..analysis.result_model import result_solid
    from ..solid.modal import classify_modes
    from ..solid.mode_cache import all_modes

    t0 = time.perf_counter()
    out = Path(out)
    figdir = out / "figures"
    # the paper's algorithm for Fig. 11 runs in a second process while the cases run here
    pool = _spawn_pool() if workers > 1 else None
    fig11_job = pool.submit(_fig11_path, out, reuse, tuple(extra), fig11_window) if pool else None
    runs, walls = run_cases(out, solver, reuse, progress, extra)
    m = measurements(runs)
    model = result_solid(runs[("plate", "LSGM:3", "strong")])
    modes = all_modes(model)
    kinds = classify_modes(model, modes, range(7))
    m["modes"] = {"periods_ms": [float(x) for x in modes.periods[:7] * 1e3], "kinds": kinds}
    if fig11_job is not None:
        path, how = fig11_job.result()
        pool.shutdown()
        ds11 = read_netcdf(path)
    else:
        ds11, how = fig11_run(out, reuse, extra, fig11_window)
    if progress:
        progress("Fig. 11: paper's algorithm", how)
    m["fig11"] = fig11_measures(ds11, fig11_window) | {"source": how}
    m_free = m_variant = None
    if options.free_edge:
        runs_free, _ = run_cases(out, solver, reuse, progress, (*extra, *FREE_EDGE), subdir="runs-free-edge")
        m_free = measurements(runs_free) | {"modes": m["modes"], "fig11": m["fig11"]}
        runs_variant = dict(runs)
        for case in CASES:
            if case[1].startswith("LSGM"):
                runs_variant[case], _ = run_case(case_scenario(case, solver, (*extra, *NO_SSGM_WALL)),
                                                 out / "runs-no-ssgm-wall" / f"{case_tag(case)}.nc", reuse)
                if progress:
                    progress(case, "no SSGM outer wall")
        m_variant = measurements(runs_variant) | {"modes": m["modes"], "fig11": m["fig11"]}
    figs = _figures(figdir, runs, model, modes, kinds, ds11, how, fig11_window)
    if progress:
        progress("figures", len(figs))
    if options.animations:
        from ..run import load_result
        from ..viz.animate import render_movies

        figs += render_movies(movie_jobs(out, options.frames), workers=workers, read=load_result)
        if progress:
            progress("animations", len(CASES) * 2)
    total = time.perf_counter() - t0
    report = write_report(out, m, walls, [f for f in figs if str(f).endswith((".png", ".mp4", ".gif"))], total, solver, m_free,
                          m_variant)
    rows = claims(m)
    res = {"report": str(report), "total_s": total, "claims": [c.row() for c in rows], "summary": summary_line(rows),
           "walls": {case_tag(k): v for k, v in walls.items()}}
    if m_free is not None:
        res["free_edge_flips"] = [f.row() for f in verdict_flips(rows, claims(m_free))]
    if m_variant is not None:
        res["no_ssgm_wall_flips"] = [f.row() for f in verdict_flips(rows, claims(m_variant))]
    return res


def _figures(figdir, runs, model, modes, kinds, ds11, how, window) -> list:
    from ..viz import figures as F
    from ..viz.plots import plot_modes
    from ..viz.schematics import fig1_geometry, fig2_meshes

    sc = case_scenario(("plate", "LSGM:3", "strong"))
    figs = []
    figs += fig1_geometry(sc, figdir / "fig1_geometry")
    figs += fig2_meshes(sc, figdir / "fig2_meshes")
    figs += F.fig3_velocities(runs[("plate", "SSGM:C", "strong")], runs[("plate", "LSGM:3", "strong")], figdir / "fig3_velocities")
    figs += F.fig4_energies(runs, figdir / "fig4_energies")
    figs += F.fig5_energy_density(runs, figdir / "fig5_energy_density")
    figs.append(plot_modes(model, modes, kinds, (0, 3, 6), figdir / "fig6_modes.png"))
    figs += F.fig7_modal_accumulation(runs, figdir / "fig7_modal_accumulation")
    figs += F.fig8_solid_partition(runs, figdir / "fig8_solid_energy_partition")
    figs += F.fig9_time_averaged(runs, figdir / "fig9_time_averaged_modes")
    figs += F.fig10_friction_law(figdir / "fig10_friction_law")
    figs += F.fig11_eigenvalues(ds11, figdir / "fig11_eigenvalues", tmax=window, source=how)
    return figs


def claim_rows(res: dict) -> list[list[str]]:
    """`granel paper`'s table: each statement, the paper's value, granel's and the verdict (rich
    markup colours it)."""
    rows = []
    for k, c in enumerate(res["claims"], 1):
        color = {"agree": "green", "by construction": "cyan"}.get(c["verdict"], "yellow")
        rows.append([str(k), c["claim"], c["paper"], c["granel"], f"[{color}]{c['verdict']}[/]"])
    return rows
