"""The `granel` command line (typer + rich): each command parses its options, calls one library
function and prints. Errors travel as exceptions that carry their exit code (`guard.exits`); the
group (`guard.commandline.GuardedGroup`) prints each as one line.
May import: everything."""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import typer
from rich.progress import TextColumn

from . import __version__
from . import scenario as S
from .guard.commandline import GuardedGroup, console, note, print_table, progress_bar, text_argument, why_not_written, written
from .guard.exits import GranelError, NotWritten
from .guard.outputs import check_outputs, picture_file
from .io.units import wall_time_option
from .guard.signals import check_workers

app = typer.Typer(cls=GuardedGroup, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="granel: granular-elastic solid interface simulator")
SCHEDULER = "address of a running dask scheduler, e.g. tcp://host:8786"
WORKERS = "LocalCluster worker processes (ignored with --scheduler)"


def _version(value: bool):
    if value:
        print(f"granel {__version__}")
        raise typer.Exit(0)


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print granel's version and exit")):
    """granel: granular-elastic solid interface simulator."""


# ------------------------------------------------------------------------------------------ helpers


def _elastic(sc) -> bool:
    """Whether the scenario's solid moves (it has modes to solve for before the first step)."""
    from .solid.kinds import is_elastic

    return sc.solid is not None and is_elastic(sc.solid.kind)


def _fail(msg: str, code: int = 2):
    """End the command with `msg` as its one error line and exit `code` (printed by the group once
    the command's progress bars have closed, so that it is the last line on standard error)."""
    raise GranelError(msg, code) from None


def _overrides(solid=None, excite=None, duration=None, dt=None, solver=None, sets=None) -> list[str]:
    """The shortcuts as `key=value` scenario overrides (strings quoted for TOML), read as UTF-8
    whatever the locale (`text_argument`)."""
    quoted = {"solid.kind": solid, "excitations.0.granule": excite, "simulation.duration": duration, "simulation.dt": dt,
              "simulation.solver": solver}
    return [text_argument(f'{key}="{val}"') for key, val in quoted.items() if val is not None] + \
        [text_argument(s) for s in sets or []]


@contextmanager
def _cluster_errors(scheduler, source):
    """A scheduler's error ends the command naming --scheduler (exit 2 or 4), an invalid
    scenario or input file naming `source` (its exit code)."""
    from .studies.sweep import SchedulerError

    try:
        yield
    except SchedulerError as e:
        _fail(f"--scheduler {scheduler}: {e}", e.code)
    except S.ScenarioError as e:
        _fail(f"{source}: {e}", e.code)


def _run_cases(title: str, n: int, run, scheduler, source):
    """Run a study's n cases, `run(progress)`, under a progress bar: (its summary, the failed
    cases); errors as `_cluster_errors`."""
    failed = []
    with progress_bar() as bar:
        task = bar.add_task(title, total=n)

        def progress(r):
            if r.get("status") != "ok":
                failed.append(r)
            bar.update(task, advance=1)

        with _cluster_errors(scheduler, source):
            return run(progress), failed


def _report_failures(failed, n: int, where: str) -> None:
    for r in failed:
        console.print(f"[yellow]{r['tag']}[/]: {r['status']}")
    if failed:
        _fail(f"{len(failed)} of {n} cases failed (listed above{where}); a rerun retries them", 3)


# ----------------------------------------------------------------------------------------- commands


@app.command()
def run(
    scenario: str = typer.Argument(..., help="built-in name (see `granel scenarios`), a TOML file, or - (standard input)"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | string | bending_plate | membrane | rigid | none (a string or membrane needs solid.tension)"),
    excite: Optional[str] = typer.Option(None, help="granule label of the first excitation, e.g. LSGM:3 or SSGM:C"),
    shock: Optional[str] = typer.Option(None, help="weak | moderate | strong (the paper's half-sine levels) or a peak force in N"),
    duration: Optional[str] = typer.Option(None, help="simulated time, e.g. 0.8ms"),
    dt: Optional[str] = typer.Option(None, help="time step, e.g. 4e-8 or 40ns"),
    solver: Optional[str] = typer.Option(None, help="coupled solver: paper | fast"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value (repeatable)"),
    output: Path = typer.Option(Path("granel-out.nc"), "-o", "--output", readable=False, help="result NetCDF file"),
    json_summary: bool = typer.Option(False, "--json-summary", help="print the summary as JSON on stdout"),
    checkpoint_every: Optional[str] = typer.Option(None, help="write a resumable checkpoint at this simulated interval"),
    resume: Optional[Path] = typer.Option(None, readable=False, help="continue a run from its checkpoint (the -o file's .ckpt)"),
    max_wall: Optional[str] = typer.Option(None, "--max-wall", help="stop (exit 3) after this wall time, e.g. 30min, 90s or 2h"),
):
    """Simulate a scenario and write its results to NetCDF."""
    if "dask" not in sys.modules and "xarray" not in sys.modules:  # a fresh process: xarray then takes its no-dask
        sys.modules["dask"] = None  # paths (a run never uses dask; its import's cost: docs/performance.md)
    from .io.results import remove_stale_temporaries
    from .run import plan_run_outputs, run_to_file, summary_rows

    ov = _overrides(solid, excite, duration, dt, solver, set_)
    if checkpoint_every is not None:
        ov.append(f'simulation.checkpoint_every="{checkpoint_every}"')
    implied = ["simulation.adaptive=false"] if dt and solver != "paper" else []  # --dt forces a fixed step
    wall_limit = wall_time_option(max_wall, "--max-wall")
    sc = S.load(scenario, ov, shock=S.shock_value(shock), implied=implied)
    if S.contact_note(sc):
        note(S.contact_note(sc))
    ckpt = plan_run_outputs(output, sc, scenario, resume)
    for tmp in (t for path in (output, ckpt) for t in remove_stale_temporaries(path)):
        console.print(f"removed {tmp}, left by an interrupted run")
    total = sc.simulation.duration
    with progress_bar(counted=False, extra=[TextColumn("t = {task.fields[t]}")]) as bar:
        # until the first step: building the problem and, for an elastic solid, its modes (minutes for a large one)
        task = bar.add_task(f"{sc.name} ({sc.solid.kind if sc.solid else 'rigid'})", total=total,
                            t="0 (setting up: the solid's matrices and modes)" if _elastic(sc) else "0")
        try:  # a stopped run (run.RunStopped) ends with its own line, "run stopped: ...", exit 3
            summary = run_to_file(sc, output, lambda t: bar.update(task, completed=min(t, total), t=f"{t * 1e3:.4f} ms"),
                                  checkpoint=ckpt, resume=resume, max_wall=wall_limit)
        except NotWritten as e:
            _fail(f"-o {output}: could not write the result: {why_not_written(e.cause)}", 4)
    if json_summary:
        print(json.dumps(summary, indent=2))
    print_table(summary_rows(summary), title=f"granel run: {summary['scenario']} ({summary['solid']})", out=console)


@app.command()
def scenarios():
    """List the built-in scenarios."""
    print_table([[name, S.builtin_description(name)] for name in sorted(S.builtin_names())], ["name", "description"])


@app.command()
def show(
    scenario: str = typer.Argument(..., help="built-in name, TOML file, or - (standard input)"),
    output: Path = typer.Option(Path("geometry.png"), "-o", "--output", readable=False, help="PNG or PDF"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | string | bending_plate | membrane | rigid | none (a string or membrane needs solid.tension)"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value (key=- removes it)"),
    resolved: bool = typer.Option(False, "--resolved", help="print the fully resolved scenario (every default) as TOML "
                                                            "instead of drawing"),
):
    """Draw the packing with labels, walls, the solid and the excitations; or, with --resolved,
    print the scenario as granel reads it, every default filled in."""
    sc = S.load(scenario, _overrides(solid, sets=set_))
    if resolved:
        sys.stdout.write(S.to_toml(sc))
        return
    from .viz.plots import plot_geometry

    plot_geometry(sc, picture_file(output, "-o", S.scenario_inputs(scenario, sc)))
    console.print(f"wrote {output}")


@app.command()
def init(
    name: str = typer.Argument(..., help="the scenario's name; writes NAME.toml"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", readable=False, help="the file to write (default NAME.toml)"),
):
    """Write a scenario to start from: the paper's set-up with every field shown, each with its
    description, and the optional ones listed commented out. An existing file is never replaced."""
    from .scenario.template import write_template

    out = write_template(name, output)
    console.print(f"wrote {out}: the paper's set-up, every field shown; `granel show {out} --resolved` prints what granel reads")


@app.command()
def modes(
    scenario: str = typer.Argument("paper", help="built-in name, TOML file, or - (standard input)"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | string | bending_plate | membrane"),
    count: int = typer.Option(12, help="modes to print"),
    json_out: bool = typer.Option(False, "--json", help="print JSON on stdout"),
    plot: Optional[Path] = typer.Option(None, readable=False, help="write the Fig. 6 picture (mesh and modes 1, 4, 7)"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value"),
):
    """Natural periods and kinds (bending / axial / bulk) of the solid's modes."""
    from .studies.natural_modes import mode_rows, scenario_modes

    sc = S.load(scenario, _overrides(solid, sets=set_))
    if plot is not None and S.elastic_solid(sc) is not None:
        picture_file(plot, "--plot", S.scenario_inputs(scenario, sc))
    res = scenario_modes(sc, count, plot)
    if json_out:
        print(json.dumps(res.summary(), indent=2))
        return
    title, header, rows = mode_rows(res)
    print_table(rows, header, title)


@app.command()
def paper(
    out: Path = typer.Option(Path("paper-out"), "--out", readable=False, help="output directory"),
    solver: str = typer.Option("fast", help="fast | paper (the reference algorithm: hours for the strong plate cases)"),
    animations: bool = typer.Option(True, "--animations/--no-animations", help="Appendix C movies of all twelve cases"),
    free_edge: bool = typer.Option(True, "--free-edge/--no-free-edge", help="also rerun the claims with outer_wall = false"),
    reuse: bool = typer.Option(True, "--reuse/--rerun", help="reuse cached, validated results in OUT/runs"),
    workers: int = typer.Option(2, min=1, help="processes rendering the movies"),
):
    """Regenerate the paper: twelve cases, modal analysis, Figs. 1-11, animations, report.md."""
    from .studies.paper import PaperOptions, claim_rows, paper_study, run_count

    if solver not in ("fast", "paper"):
        _fail(f"--solver {solver!r}: choose fast or paper")
    check_workers(workers)
    check_outputs(folder=(out, "--out", "paper", lambda p: (p / "runs").is_dir() and any((p / "runs").glob("*.nc"))))
    with progress_bar() as bar:
        task = bar.add_task("paper cases", total=run_count(free_edge))

        def progress(what, info):
            if isinstance(what, tuple):
                bar.update(task, advance=1, description=f"{'-'.join(what)} ({info if isinstance(info, str) else f'{info:.1f} s'})")
            else:
                bar.update(task, description=f"{what}: {info}")

        options = PaperOptions(solver, reuse, animations, free_edge=free_edge, workers=workers)
        res = paper_study(out, options, progress)
    print_table(claim_rows(res), ["#", "statement", "paper", "granel", "verdict"], "granel vs the paper", show_lines=False)
    # agreement counted only over the statements that could have failed (granel.studies.claims.tally)
    console.print(f"{res['summary']}; report: {res['report']}; total {res['total_s']:.1f} s")


@app.command()
def reciprocity(
    scenario: str = typer.Argument("paper", help="built-in name, TOML file, or - (standard input)"),
    shock: Optional[str] = typer.Option(None, help="weak | moderate | strong, or a peak force in N "
                                        "(default: the scenario's own; the paper's is strong)"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | string | bending_plate | membrane | rigid"),
    a: str = typer.Option("LSGM:3", "--a", help="first excitation/measurement granule"),
    b: str = typer.Option("SSGM:C", "--b", help="second excitation/measurement granule"),
    duration: Optional[str] = typer.Option(None, help="simulated time, e.g. 0.8ms"),
    out: Path = typer.Option(Path("reciprocity"), "--out", readable=False, help="directory for the two runs and the Fig. 3 plot"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value"),
    json_out: bool = typer.Option(False, "--json", help="print the metrics as JSON"),
):
    """Run both directions (shock at A measured at B, and the reverse) and compare."""
    from .studies.reciprocity import metric_rows, plan_reciprocity, run_reciprocity

    if a == b:
        _fail(f"--a and --b are both {a!r}: give two different granules")
    level = S.shock_value(shock)
    # both directions validated before either runs
    scs = {exc: S.load(scenario, _overrides(solid, exc, duration, sets=set_), shock=level) for exc in (b, a)}
    plan_reciprocity(out, scs, scenario)
    with written(f"--out {out}", "the runs"):  # a stopped run (run.RunStopped) ends with its own line, exit 3
        _, m = run_reciprocity(scs, out, running=lambda exc: console.status(f"running with the shock on {exc}"))
    if json_out:
        print(json.dumps(m, indent=2, default=float))
        return
    print_table(*reversed(metric_rows(m, a, b)), "reciprocity")
    console.print(f"nonreciprocity index: {m['nonreciprocity_index']:.4f} (0 = reciprocal); faster: {m['faster_direction']}; "
                  f"figure: {out / 'fig3_velocities.png'}")


@app.command()
def animate(
    result: Path = typer.Argument(..., readable=False, help="a result NetCDF file"),
    output: Path = typer.Option(Path("movie.mp4"), "-o", "--output", readable=False, help=".mp4 (GIF fallback) or .gif"),
    field: str = typer.Option("deformation", help="deformation | energy-density"),
    magnification: Optional[float] = typer.Option(None, help="deformation scale (default: x5000 weak, x1000 moderate, x200 strong)"),
    frames: int = typer.Option(120, help="number of frames"),
    fps: int = typer.Option(20, help="frames per second"),
):
    """Render a movie of a run (Appendix C)."""
    from .guard.reading import check_file
    from .run import load_result
    from .viz.animate import animate as render, check_movie_request

    check_movie_request(output, field, magnification, frames, fps)  # the options first, before anything is read
    check_file(result, "file")
    check_outputs([result], [(output, "--output")])
    ds = load_result(result)
    with written(f"--output {output}", "the movie"), console.status("rendering"):
        path = render(ds, output, field, magnification, frames, fps)
    console.print(f"wrote {path}")


@app.command()
def bench(
    quick: bool = typer.Option(False, "--quick", help="short runs (0.1 ms), no `granel paper` timing"),
    json_out: bool = typer.Option(False, "--json", help="print one JSON object"),
    cases: Optional[str] = typer.Option(None, help="comma list of case tags, e.g. plate-SSGMC-strong, or built-in "
                                        "scenario cases (chain-on-plate)"),
    duration: Optional[str] = typer.Option(None, help="simulated time per case (default 0.8 ms, a scenario case's own; "
                                           "0.1 ms with --quick)"),
    reference: bool = typer.Option(False, "--reference", help="also each method's errors against Newmark at 2.5 ns "
                                   "on the strong SSGM-side plate case and the scenario cases (when among the cases)"),
    fresh: bool = typer.Option(True, "--fresh/--no-fresh", help="time `granel run` in fresh processes"),
):
    """The paper's algorithm and the fast method (its exact integrator, and Newmark at dtau0) side by
    side in one process, on the paper's cases and a chain on a plate in bending: wall times,
    ratios, steps, deviations; fresh-process and `granel paper` times."""
    from .studies.benchmark import bench_rows, check_bench_options, run_bench

    only = check_bench_options(cases, duration)
    res = run_bench(quick=quick, only=only, duration=duration, reference=reference, fresh=fresh,
                    log=lambda s: console.print(s))
    if json_out:
        print(json.dumps(res, indent=2))
        return
    header, rows = bench_rows(res)
    print_table(rows, header, "granel bench (deviations from the paper's algorithm: exact / newmark)")
    console.print(f"totals: paper {res['paper_total_s']:.1f} s, exact {res['exact_total_s']:.2f} s, "
                  f"newmark {res['newmark_total_s']:.2f} s")
    if res.get("paper_study_s") is not None:
        console.print(f"granel paper (no animations): {res['paper_study_s']:.1f} s")


@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., readable=False, help="sweep TOML (see docs/sweeps.md)"),
    out: Path = typer.Option(Path("sweep-out"), "-o", "--out", readable=False, help="output directory"),
    workers: int = typer.Option(2, help=WORKERS),
    scheduler: Optional[str] = typer.Option(None, help=SCHEDULER),
):
    """Run a parameter sweep on dask.distributed; re-running skips finished cases.
    Exit code 3 if any case failed."""
    from .studies.modes import study_mode
    from .studies.sweep import cases, load_sweep, plan_sweep, summary_statistics, sweep_study

    check_workers(workers)
    spec, base_dir = load_sweep(sweep_file)
    plan_sweep(sweep_file, spec, base_dir, out)
    n = len(cases(spec))
    with written(f"--out {out}", "the sweep's results"):
        ds, failed = _run_cases(f"sweep {spec.name}", n, lambda progress: sweep_study(spec, base_dir, out, workers, scheduler,
                                                                                      progress), scheduler, sweep_file)
    print_table(summary_statistics(ds), ["metric", "min", "median", "max"],
                 f"sweep {spec.name}: {n} cases, {n - len(failed)} ok, {len(failed)} failed")
    console.print(f"summary: {out / 'summary.nc'}")
    extra = study_mode(spec.mode).sweep_outputs(spec)
    if extra:
        console.print(f"{extra[0].split('.')[0]}: {', '.join(str(out / name) for name in extra)}")
    _report_failures(failed, n, f"; their status is in {out / 'summary.nc'}")


@app.command()
def spectrum(
    scenario: str = typer.Argument(..., help="scenario TOML or built-in name (its first excitation becomes the drive)"),
    drive: str = typer.Option(..., help="the driven granule, MEDIUM:LABEL (forward direction)"),
    measure: str = typer.Option(..., help="the measured granule, MEDIUM:LABEL"),
    frequencies: str = typer.Option(..., help="START:STOP:COUNT (geometric; --linear for even steps) or a list, "
                                              "e.g. 1kHz:40kHz:20 or 2kHz,5kHz"),
    amplitudes: str = typer.Option(..., help="force amplitudes [N], e.g. 10,100,1000"),
    both_directions: bool = typer.Option(False, "--both-directions", help="also drive MEASURE and measure DRIVE: "
                                                                          "the nonreciprocity"),
    linear: bool = typer.Option(False, "--linear", help="evenly spaced frequencies in START:STOP:COUNT"),
    cycles: float = typer.Option(40.0, help="drive periods per run"),
    window_cycles: float = typer.Option(10.0, help="the last periods analysed"),
    ramp_cycles: float = typer.Option(5.0, help="periods of the drive's smooth ramp-up"),
    samples: int = typer.Option(24, help="outputs per drive period"),
    set_: list[str] = typer.Option([], "--set", help="scenario override field=value (repeatable)"),
    out: Path = typer.Option(Path("spectrum.nc"), "-o", "--out", readable=False, help="the spectrum NetCDF; its figure (.png), report "
                                                                      "(.md) and cases (.cases/) go beside it"),
    workers: int = typer.Option(2, help=WORKERS),
    scheduler: Optional[str] = typer.Option(None, help=SCHEDULER),
):
    """Transmission and nonreciprocity over drive frequency and amplitude: one harmonic run per
    frequency, amplitude and direction, on the sweep engine (re-running the same command reuses
    finished runs). Writes OUT (frequency x amplitude x direction), OUT.png and OUT.md.
    Exit code 3 if any run failed."""
    from .studies.spectrum_report import spectrum_report
    from .studies.spectrum_study import cases_folder, plan_spectrum, run_spectrum
    from .studies.sweep import cases

    check_workers(workers)
    spec = plan_spectrum(scenario, set_, frequencies, amplitudes, out, linear, drive=drive, measure=measure,
                         both_directions=both_directions, cycles=cycles, window_cycles=window_cycles,
                         ramp_cycles=ramp_cycles, samples_per_period=samples)
    n, work = len(cases(spec)), cases_folder(out)
    with written(f"-o {out}", f"the spectrum's runs in {work}"):
        ds, failed = _run_cases(f"spectrum: {n} cases x {2 if both_directions else 1} direction(s)", n,
                                lambda progress: run_spectrum(spec, out, workers, scheduler, progress), scheduler, scenario)
    console.print(spectrum_report(ds), markup=False)  # its [kHz], [dB] are units, not markup
    console.print(f"wrote {out}, {out.with_suffix('.png')}, {out.with_suffix('.md')} (runs in {work})")
    _report_failures(failed, n, "")


@app.command()
def design(
    design_file: Path = typer.Argument(..., readable=False, help="design TOML (see docs/design.md)"),
    out: Path = typer.Option(..., "-o", "--out", readable=False, help="output folder: the study, trials.nc, best.toml or pareto/"),
    trials: Optional[int] = typer.Option(None, "--trials", help="finished trials to reach (default: the design's `trials`)"),
    workers: int = typer.Option(2, help=WORKERS),
    scheduler: Optional[str] = typer.Option(None, help=SCHEDULER),
    timeout: Optional[str] = typer.Option(None, "--timeout", help="stop launching trials after this wall time, e.g. "
                                                                  "30min (a rerun continues the study)"),
):
    """Search a design's variables for its objectives with Optuna, each trial a case of the
    sweep engine on dask.distributed; re-running continues the study. Exit code 3 if no trial
    succeeded."""
    from .guard.outputs import removed_if_refused
    from .studies.design_report import best_rows, design_study, plan_design
    from .studies.design_search import DesignRunOptions

    check_workers(workers)
    if trials is not None and trials < 1:
        _fail(f"--trials {trials}: give a whole number of trials >= 1")
    budget = wall_time_option(timeout, "--timeout")
    with written(f"--out {out}", "the study"):  # an invalid design ends with its own error, naming the file
        spec, base_dir, plan = plan_design(design_file, out)  # the fields, and that each variable reaches the runs
    failed = []
    with removed_if_refused(out), written(f"--out {out}", "the study"):
        plan.prepare()
        with progress_bar() as bar:
            task = bar.add_task(f"design {spec.name}", total=trials or spec.trials)

            def progress(number, status, done, total):
                if status != "ok":
                    failed.append((number, status))
                bar.update(task, completed=done)

            def confirming(done, total):
                bar.update(task, description=f"design {spec.name}: confirming the best at full accuracy", completed=done,
                           total=total)

            options = DesignRunOptions(workers, scheduler, max_wall=budget, progress=progress, confirming=confirming)
            with _cluster_errors(scheduler, design_file):
                res = design_study(spec, base_dir, out, trials, options,
                                   reporting=lambda: bar.update(task, description=f"design {spec.name}: re-evaluating "
                                                                                  "the best designs"))
    ds = res["trials"]
    ok = int((ds["status"].values == "ok").sum())
    header, rows = best_rows(spec, res)
    print_table(rows, header, f"design {spec.name}: {ds.sizes['trial']} trials, {ok} ok; best"
                 + (" (Pareto front)" if len(spec.objectives) > 1 else ""))
    for number, status in failed[:10]:
        console.print(f"[yellow]trial {number}[/]: {status}")
    if len(failed) > 10:
        console.print(f"... and {len(failed) - 10} more failed trials (their reasons are in {out / 'trials.nc'})")
    for w in res["warnings"]:
        console.print(f"[bold yellow]warning:[/] {w}")
    if res["stopped"]:
        console.print(f"--timeout {timeout}: stopped after {ds.sizes['trial']} trials; run the same command to continue")
    console.print("wrote " + ", ".join(str(f) for f in res["files"][:4]) + (" ..." if len(res["files"]) > 4 else ""))
    if ok == 0:
        _fail(f"no trial of {ds.sizes['trial']} succeeded (reasons in {out / 'trials.nc'})", code=3)


@app.command()
def export(
    result: Path = typer.Argument(..., readable=False, help="a result NetCDF file of `granel run`"),
    out: Path = typer.Option(..., "-o", "--out", readable=False, help="output folder (created if missing)"),
    format_: Optional[list[str]] = typer.Option(None, "--format", help="vtk | xdmf | csv | extxyz (repeatable or "
                                                                      "comma separated; default: all four)"),
):
    """Export a run for ParaView (VTU + PVD, XDMF), OVITO (extended XYZ) and spreadsheets (CSV):
    the granules at every output and the plate's or beam's nodal displacement, velocity, element
    energy density and stress (plane stress and von Mises, or the beam's bending stress) at every
    stored solid output."""
    from .run import load_result
    from .viz.export import check_exportable, export_result, parse_formats, plan_export

    formats = parse_formats(format_)
    plan_export(result, out)
    ds = load_result(result)
    check_exportable(ds, formats, result)
    plan_export(result, out, ds)
    with written(f"-o {out}", "the export"), progress_bar("[bold]export", remaining=False, transient=True) as bar:
        task = bar.add_task("export", total=None)
        files = export_result(ds, out, formats, lambda done, total: bar.update(task, completed=done, total=total),
                              name=result)
    console.print(f"wrote {len(files)} files ({', '.join(formats)}) in {out}")


@app.command()
def wavefield(
    result: Path = typer.Argument(..., readable=False, help="a result NetCDF file of `granel run` with a plate or a beam"),
    out: Path = typer.Option(..., "-o", "--out", readable=False, help="output folder: wavefield.nc, kt.png, fk.png, moments.png, "
                                                      "bands.png (and bands.mp4 with --movie)"),
    bands: Optional[str] = typer.Option(None, help="a count of equal wavenumber bands up to --k-max (default 4), or "
                                                   "their edges in rad/m, e.g. 0,200,400,700"),
    k_max: Optional[float] = typer.Option(None, "--k-max", help="largest wavenumber of the spectrum's moments "
                                                                "[rad/m] (default: the elements' resolution limit)"),
    fit: Optional[str] = typer.Option(None, help="the variance's growth-law window START:END, e.g. 0.1ms:0.8ms "
                                                 "(default: from the energy's arrival to the end)"),
    movie: bool = typer.Option(False, "--movie", help="also bands.mp4, the band-filtered fields over time"),
    frames: int = typer.Option(120, help="movie frames"),
    fps: int = typer.Option(20, help="movie frames per second"),
):
    """The solid's wavefield in wavenumber and time (docs/wavefield.md): the kinetic energy E(k, t)
    of its harmonics along the length (sine transform for clamped ends), the band-filtered fields,
    the spectrum's centroid, variance (with its growth exponent) and entropy over time, and the
    frequency-wavenumber map with the analytic dispersion branches (Rayleigh-Lamb for a plate,
    Euler-Bernoulli for a beam). Exit code 2 for a result without a plate or beam."""
    from .guard.writing import storable
    from .studies.wavefield import report_rows, stage_count, wavefield_request, wavefield_study

    req = wavefield_request(result, out, bands, k_max, fit, movie, frames, fps)
    with written(f"-o {out}", "the wavefield"), progress_bar("[bold]wavefield[/] {task.description}", remaining=False,
                                                            transient=True) as bar:
        task = bar.add_task("", total=stage_count(req.options))
        report = wavefield_study(req.ds, out, req.options, lambda what, done, total: bar.update(task, completed=done,
                                                                                              description=what),
                                 name=result, plan=req.plan)
    print_table(report_rows(report), title=f"granel wavefield: {storable(result.name)}")  # stdout may take only UTF-8
    console.print(f"wrote {', '.join(str(p.name) for p in report.files)} in {out}")


@app.command("map")
def map_(
    summary: Path = typer.Argument(..., readable=False, help="a sweep's summary.nc"),
    output: Path = typer.Option(Path("map.png"), "-o", "--output", readable=False, help="PNG or PDF"),
    metric: str = typer.Option("nonreciprocity_index", help="variable to draw"),
    x: Optional[str] = typer.Option(None, help="axis along x (default: the first)"),
    y: Optional[str] = typer.Option(None, help="axis along y (default: the second)"),
):
    """Draw a design map: a metric over two sweep axes (panels over a third)."""
    from .guard.reading import check_file
    from .studies.sweep import plot_map, read_summary

    check_file(summary, "sweep summary")
    picture_file(output, "--output", [summary])
    ds = read_summary(summary)
    try:
        with written(f"--output {output}", "the map"):
            plot_map(ds, output, metric, x, y)
    except ValueError as e:
        _fail(str(e))
    console.print(f"wrote {output}")


def main():  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover - every command above is registered by now
    main()
