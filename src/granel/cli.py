"""The `granel` command line (typer + rich).
May import: everything."""

from __future__ import annotations

import json
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from . import __version__
from . import scenario as S
from .guard.commandline import GuardedGroup
from .guard.exits import GranelError
from .guard.owners import is_granel_file

app = typer.Typer(cls=GuardedGroup, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="granel: granular-elastic solid interface simulator")
console = Console(stderr=True, soft_wrap=True)


def _version(value: bool):
    if value:
        print(f"granel {__version__}")
        raise typer.Exit(0)


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print granel's version and exit")):
    """granel: granular-elastic solid interface simulator."""


def _fail(msg: str, code: int = 2):
    """End the command with `msg` as its one error line and exit `code`. The line is printed by
    the group (`guard.commandline`) once the command's progress bars and spinners have closed, so
    that it is the last line on standard error."""
    raise GranelError(msg, code) from None


MAX_WORKERS = 1024  # local worker processes a command may start


def _check_workers(workers: int) -> None:
    if not 1 <= workers <= MAX_WORKERS:
        _fail(f"--workers {workers}: give a whole number of worker processes from 1 to {MAX_WORKERS}")


def _overrides(solid=None, excite=None, duration=None, dt=None, solver=None, sets=None) -> list[str]:
    """The CLI shortcuts as `key=value` scenario overrides (string values quoted for TOML)."""
    quoted = {"solid.kind": solid, "excitations.0.granule": excite, "simulation.duration": duration, "simulation.dt": dt,
              "simulation.solver": solver}
    return [f'{key}="{val}"' for key, val in quoted.items() if val is not None] + list(sets or [])


def _shock_level(shock: str | None):
    """`--shock`: a level name (weak, moderate, strong) or a peak force in newtons."""
    if shock is None or shock in S.SHOCK_LEVELS:
        return shock
    try:
        value = float(shock.removesuffix("N"))
    except ValueError:
        _fail(f"--shock {shock!r}: give weak, moderate, strong or a peak force in N, e.g. 500")
    if not np.isfinite(value):
        _fail(f"--shock {shock!r}: the peak force must be finite")
    return value


def _load_or_fail(name: str, overrides: list[str], shock=None, implied=()) -> S.Scenario:
    try:
        return load_scenario(name, overrides, shock, implied)
    except S.ScenarioError as e:
        _fail(str(e), e.code)


def _note_contact_defaults(sc: S.Scenario) -> None:
    """A scenario without [contact] runs with the paper's friction and damping: say so, once."""
    if "contact" not in sc.model_fields_set:
        c = sc.contact
        console.print(f"[yellow]note:[/] no \\[contact] table: the paper's contact law applies (mu = {c.mu:g}, "
                      f"alpha_n = {c.alpha_n:g}, k_s = {c.k_s:g} s/m); write \\[contact] with mu = 0.0 and "
                      "alpha_n = 0.0 for frictionless, undamped contacts")


def load_scenario(name: str, overrides: list[str], shock: str | float | None = None, implied=()) -> S.Scenario:
    """A scenario with overrides; `shock` (a level name or a peak force [N]) replaces the first
    excitation's `shock` and `fmax`. An override of a field the run ignores is refused
    (`scenario.usage`); `implied` overrides (set by a shortcut's meaning) are not checked."""
    from .scenario.usage import check_overrides_used

    raw, base = S.load_raw(name)
    if shock is not None:
        keys = (o.split("=", 1)[0].strip() for o in overrides)
        both = [k for k in keys if k in ("excitations.0.shock", "excitations.0.fmax")]
        if both:
            raise S.ScenarioError(f"--shock and --set {both[0]} both set the first excitation's peak force: give one")
    raw = S.apply_overrides(raw, [*overrides, *implied])
    if shock is not None:
        if not raw.get("excitations"):
            raise S.ScenarioError("--shock: the scenario has no excitation to set")
        exc = raw["excitations"][0]
        exc.pop("fmax", None)
        exc.pop("shock", None)
        exc["shock" if isinstance(shock, str) else "fmax"] = shock
    sc = S.validate(raw, base)
    check_overrides_used(sc, overrides)
    return sc


def _input_and_output(source: Path, output: Path, what: str = "file") -> None:
    """A command's input file must be a readable file (exit 2 or 4), and its --output pass the
    output rules (`guard.outputs`) with that file as input."""
    from .guard.outputs import OutputPlan
    from .guard.reading import check_file

    check_file(source, what)
    plan = OutputPlan(inputs=[source])
    plan.file(output, "--output")
    plan.check().prepare()


def _check_folder(path: Path, option: str, kind: str, inputs=(), recognise=None, prepare: bool = True) -> None:
    """An output folder of the command `kind`, checked before any computation (exit 2 or 4), then
    (`prepare`) made and stamped."""
    from .guard.outputs import OutputPlan

    plan = OutputPlan(inputs=[Path(p) for p in inputs if p is not None])
    plan.folder(path, option, kind, recognise)
    plan.check()
    if prepare:
        plan.prepare()


def _picture_output(output: Path, option: str, inputs=()) -> Path:
    """A picture file to write: a format whose files carry granel's mark (by its suffix), and the
    output rules (`guard.outputs`) with `inputs` as the command's inputs."""
    from .guard.outputs import OutputPlan
    from .guard.owners import PICTURE_FORMATS

    if output.suffix.lower().lstrip(".") not in PICTURE_FORMATS:
        _fail(f"{option} {output}: give a picture file name ending in one of {', '.join('.' + k for k in PICTURE_FORMATS)}")
    plan = OutputPlan(inputs=[Path(p) for p in inputs if p is not None])
    plan.file(output, option)
    plan.check().prepare()
    return output


def _scenario_inputs(scenario: str, sc) -> list:
    """The files a scenario command reads: the scenario file and every file it refers to."""
    return [S.scenario_file(scenario), *S.referenced_files(sc)]


def _wall_seconds(text: str | None, option: str) -> float | None:
    """A wall-time limit: a positive number of seconds, or with a unit (s, min, h)."""
    if text is None:
        return None
    units = {"h": 3600.0, "min": 60.0, "m": 60.0, "s": 1.0}
    t = text.strip().lower()
    scale = 1.0
    for u, f in units.items():
        if t.endswith(u):
            t, scale = t[: -len(u)].strip(), f
            break
    try:
        value = float(t) * scale
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        _fail(f"{option} {text!r}: give a positive wall time, e.g. 90s, 30min or 2h")
    return value


def _check_run_paths(output: Path, sc, scenario: str, resume: Path | None, checkpoints: bool) -> Path:
    """The result and checkpoint paths of `granel run`, checked before any computation (exit 2 or
    4; `guard.outputs`): the checkpoint is the result's name with .ckpt; an existing one is only
    ever replaced or removed by the run that resumes from it."""
    from .guard.outputs import OutputPlan

    source = None if resume is None else (resume if resume.suffix == ".ckpt" or not resume.name
                                          else resume.with_suffix(".ckpt"))
    if source is not None:
        from .guard.outputs import check_name_lengths

        check_name_lengths(source, "--resume")  # a name the file system refuses is a wrong name (exit 2)
    plan = OutputPlan(reserved={".ckpt": "the .ckpt suffix is kept for checkpoints; give the result a .nc name"})
    plan.add_inputs(S.scenario_file(scenario), *S.referenced_files(sc), source)
    plan.file(output, "-o")
    plan.check()
    from .guard.resources import check_disk
    from .scenario.estimate import run_needs

    check_disk(run_needs(sc).result * (2 if checkpoints else 1), output.absolute().parent, f"-o {output}: the result")
    ckpt = output.with_suffix(".ckpt")
    resuming = source is not None and source.exists() and source.resolve() == ckpt.resolve()
    if checkpoints and ckpt.exists() and not resuming:
        _fail(f"{ckpt} exists (the checkpoint of an earlier run?): continue it with --resume {ckpt}, or move it away")
    plan.prepare()
    return ckpt


def _without_dask() -> None:
    """Mark dask as absent for this process, so that xarray takes its no-dask paths: a single
    run never uses dask, but xarray imports it (and distributed) whenever it checks whether an
    array is a dask array (its cost: docs/performance.md)."""
    if "dask" not in sys.modules and "xarray" not in sys.modules:  # only in a fresh process: xarray caches what it found
        sys.modules["dask"] = None


@app.command()
def run(
    scenario: str = typer.Argument(..., help="built-in name (see `granel scenarios`) or a TOML file"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | rigid | none"),
    excite: Optional[str] = typer.Option(None, help="granule label of the first excitation, e.g. LSGM:3 or SSGM:C"),
    shock: Optional[str] = typer.Option(None, help="weak | moderate | strong (the paper's half-sine levels) or a peak force in N"),
    duration: Optional[str] = typer.Option(None, help="simulated time, e.g. 0.8ms"),
    dt: Optional[str] = typer.Option(None, help="time step, e.g. 4e-8 or 40ns"),
    solver: Optional[str] = typer.Option(None, help="coupled solver: paper | fast"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value (repeatable)"),
    output: Path = typer.Option(Path("granel-out.nc"), "-o", "--output", help="result NetCDF file"),
    json_summary: bool = typer.Option(False, "--json-summary", help="print the summary as JSON on stdout"),
    checkpoint_every: Optional[str] = typer.Option(None, help="write a resumable checkpoint at this simulated interval"),
    resume: Optional[Path] = typer.Option(None, help="continue a run from its checkpoint (the -o file's .ckpt)"),
    max_wall: Optional[str] = typer.Option(None, "--max-wall", help="stop (exit 3) after this wall time, e.g. 30min, 90s or 2h"),
):
    """Simulate a scenario and write its results to NetCDF."""
    _without_dask()
    from .guard.exits import NotWritten
    from .io.checkpoint import CheckpointError
    from .run import run_to_file

    ov = _overrides(solid, excite, duration, dt, solver, set_)
    implied = []
    if dt and solver != "paper":
        implied.append("simulation.adaptive=false")  # --dt forces a fixed step
    if checkpoint_every is not None:
        ov.append(f'simulation.checkpoint_every="{checkpoint_every}"')
    wall_limit = _wall_seconds(max_wall, "--max-wall")
    sc = _load_or_fail(scenario, ov, _shock_level(shock), implied)
    _note_contact_defaults(sc)
    ckpt = _check_run_paths(output, sc, scenario, resume, sc.simulation.checkpoint_every > 0)
    from .io.results import remove_stale_temporaries

    for path in (output, ckpt):
        for tmp in remove_stale_temporaries(path):
            console.print(f"removed {tmp}, left by an interrupted run")
    total = sc.simulation.duration
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.percentage:>5.1f}%"),
                  TextColumn("t = {task.fields[t]}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console) as bar:
        task = bar.add_task(f"{sc.name} ({sc.solid.kind if sc.solid else 'rigid'})", total=total, t="0")

        def progress(t):
            bar.update(task, completed=min(t, total), t=f"{t * 1e3:.4f} ms")

        try:  # a stopped run (run.RunStopped) ends with its own line, "run stopped: ...", exit 3
            summary = run_to_file(sc, output, progress, checkpoint=ckpt, resume=resume, max_wall=wall_limit)
        except S.ScenarioError as e:
            _fail(str(e))
        except CheckpointError as e:
            _fail(str(e), e.code)
        except NotWritten as e:
            _fail(f"-o {output}: could not write the result: {e.cause}", code=4)
    if json_summary:
        print(json.dumps(summary, indent=2))
    _print_summary(summary)


def _print_summary(s: dict):
    t = Table(title=f"granel run: {s['scenario']} ({s['solid']})", show_header=False)
    t.add_row("steps", f"{s['steps']}")
    t.add_row("wall time", f"{s['wall_time_s']:.2f} s")
    t.add_row("simulated time", f"{s['simulated_time_s'] * 1e3:.4f} ms")
    if "mean_iterations" in s:
        t.add_row("mean iterations", f"{s['mean_iterations']:.2f}")
    if "min_step" in s:
        t.add_row("smallest step", f"{s['min_step']:.3e} s")
    t.add_row("input work", f"{s['input_work_J']:.6e} J")
    t.add_row("max balance error", f"{s['max_balance_error_J']:.3e} J ({s['max_balance_error_rel']:.2e} of input)")
    for m, p in s["peak_speed"].items():
        t.add_row(f"peak speed {m}", f"{p['m_per_s']:.4f} m/s ({p['granule']})")
    eq = s.get("equilibrium")
    if eq:
        t.add_row("equilibrium", f"{int(eq['loaded_pairs'])} pairs and {int(eq['loaded_walls'])} wall contacts loaded, "
                  f"{int(eq['iterations'])} Newton iterations, residual {eq['residual_N']:.1e} N")
        t.add_row("equilibrium forces", f"largest: pair {eq['max_pair_force_N']:.4g} N, wall {eq['max_wall_force_N']:.4g} N, "
                  f"solid {eq['max_solid_force_N']:.4g} N; deepest overlap {eq['max_overlap_m']:.3e} m")
    t.add_row("output", s.get("output", ""))
    console.print(t)


@app.command()
def scenarios():
    """List the built-in scenarios."""
    t = Table("name", "description")
    for name in sorted(S.builtin_names()):
        raw, _ = S.load_raw(name)
        t.add_row(name, raw.get("description", ""))
    Console().print(t)


@app.command()
def show(
    scenario: str = typer.Argument(..., help="built-in name or TOML file"),
    output: Path = typer.Option(Path("geometry.png"), "-o", "--output", help="PNG or PDF"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | rigid | none"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value (key=- removes it)"),
    resolved: bool = typer.Option(False, "--resolved", help="print the fully resolved scenario (every default) as TOML "
                                                            "instead of drawing"),
):
    """Draw the packing with labels, walls, the solid and the excitations; or, with --resolved,
    print the scenario as granel reads it, every default filled in."""
    sc = _load_or_fail(scenario, _overrides(solid, sets=set_))
    if resolved:
        sys.stdout.write(S.to_toml(sc))
        return
    from .viz.plots import plot_geometry

    _picture_output(output, "-o", _scenario_inputs(scenario, sc))
    plot_geometry(sc, output)
    console.print(f"wrote {output}")


@app.command()
def init(
    name: str = typer.Argument(..., help="the scenario's name; writes NAME.toml"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="the file to write (default NAME.toml)"),
):
    """Write a scenario to start from: the paper's set-up with every field shown, each with its
    description, and the optional ones listed commented out. An existing file is never replaced."""
    from .io.results import atomic_path
    from .scenario.template import template

    if not name.strip() or "/" in name or name.startswith("."):
        _fail(f"NAME {name!r}: give a plain name, e.g. mychain")
    out = output or Path(f"{name}.toml")
    from .guard.outputs import check_folder_writable, check_name_lengths

    check_name_lengths(out, "-o")  # the output rules' checks of a name and its folder (exit 2 or 4)
    check_folder_writable(out.absolute().parent, "-o", out)
    if out.exists():
        _fail(f"{out}: exists; granel init never replaces a file (choose another NAME or -o)")
    try:
        with atomic_path(out) as tmp:
            Path(tmp).write_text(template(name))
    except OSError as e:
        _fail(f"{out}: cannot write it ({e})", 4)
    console.print(f"wrote {out}: the paper's set-up, every field shown; `granel show {out} --resolved` prints what granel reads")


@app.command()
def modes(
    scenario: str = typer.Argument("paper", help="built-in name or TOML file"),
    solid: Optional[str] = typer.Option(None, help="plate | beam"),
    count: int = typer.Option(12, help="modes to print"),
    json_out: bool = typer.Option(False, "--json", help="print JSON on stdout"),
    plot: Optional[Path] = typer.Option(None, help="write the Fig. 6 picture (mesh and modes 1, 4, 7)"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value"),
):
    """Natural periods and kinds (bending / axial / bulk) of the solid's modes."""
    from .studies.natural_modes import scenario_modes

    if count < 1:
        _fail(f"--count {count}: give a whole number of modes >= 1")
    sc = _load_or_fail(scenario, _overrides(solid, sets=set_))
    if sc.solid is None or sc.solid.kind in ("rigid", "none"):
        _fail(f"modes: the solid is {sc.solid.kind if sc.solid else 'none'}; choose --solid plate or --solid beam")
    if plot is not None:
        _picture_output(plot, "--plot", _scenario_inputs(scenario, sc))
    res = scenario_modes(sc, count, plot)
    if json_out:
        print(json.dumps(res.summary(), indent=2))
        return
    model, periods = res.solid, res.modes.periods
    t = Table("mode", "period [ms]", "frequency [kHz]", "kind", title=f"{model.kind}: {model.ndof} DOFs, {model.nelements} elements")
    for k in range(res.shown):
        t.add_row(str(k + 1), f"{periods[k] * 1e3:.5f}", f"{1 / periods[k] / 1e3:.3f}", res.kinds[k])
    Console().print(t)


@app.command()
def paper(
    out: Path = typer.Option(Path("paper-out"), "--out", help="output directory"),
    solver: str = typer.Option("fast", help="fast | paper (the reference algorithm: hours for the strong plate cases)"),
    animations: bool = typer.Option(True, "--animations/--no-animations", help="Appendix C movies of all twelve cases"),
    free_edge: bool = typer.Option(True, "--free-edge/--no-free-edge", help="also rerun the claims with outer_wall = false"),
    reuse: bool = typer.Option(True, "--reuse/--rerun", help="reuse cached, validated results in OUT/runs"),
    workers: int = typer.Option(2, min=1, help="processes rendering the movies"),
):
    """Regenerate the paper: twelve cases, modal analysis, Figs. 1-11, animations, report.md."""
    from .studies.paper import paper_study, run_count

    if solver not in ("fast", "paper"):
        _fail(f"--solver {solver!r}: choose fast or paper")
    _check_workers(workers)
    _check_folder(out, "--out", "paper", recognise=lambda p: (p / "runs").is_dir() and any((p / "runs").glob("*.nc")))
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("paper cases", total=run_count(free_edge))

        def progress(what, info):
            if isinstance(what, tuple):
                bar.update(task, advance=1, description=f"{'-'.join(what)} ({info if isinstance(info, str) else f'{info:.1f} s'})")
            else:
                bar.update(task, description=f"{what}: {info}")

        try:
            res = paper_study(out, solver, reuse, animations, progress, free_edge=free_edge, workers=workers)
        except S.ScenarioError as e:
            _fail(str(e))
    t = Table("#", "statement", "paper", "granel", "verdict", title="granel vs the paper", show_lines=False)
    for k, c in enumerate(res["claims"], 1):
        color = {"agree": "green", "by construction": "cyan"}.get(c["verdict"], "yellow")
        t.add_row(str(k), c["claim"], c["paper"], c["granel"], f"[{color}]{c['verdict']}[/]")
    Console().print(t)
    # agreement counted only over the statements that could have failed (granel.studies.claims.tally)
    console.print(f"{res['summary']}; report: {res['report']}; total {res['total_s']:.1f} s")


@app.command()
def reciprocity(
    scenario: str = typer.Argument("paper", help="built-in name or TOML file"),
    shock: Optional[str] = typer.Option(None, help="weak | moderate | strong, or a peak force in N "
                                        "(default: the scenario's own; the paper's is strong)"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | rigid"),
    a: str = typer.Option("LSGM:3", "--a", help="first excitation/measurement granule"),
    b: str = typer.Option("SSGM:C", "--b", help="second excitation/measurement granule"),
    duration: Optional[str] = typer.Option(None, help="simulated time, e.g. 0.8ms"),
    out: Path = typer.Option(Path("reciprocity"), "--out", help="directory for the two runs and the Fig. 3 plot"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value"),
    json_out: bool = typer.Option(False, "--json", help="print the metrics as JSON"),
):
    """Run both directions (shock at A measured at B, and the reverse) and compare."""
    from .guard.exits import NotWritten
    from .studies.reciprocity import run_reciprocity

    if a == b:
        _fail(f"--a and --b are both {a!r}: give two different granules")
    level = _shock_level(shock)
    # both directions validated before either runs
    scs = {exc: _load_or_fail(scenario, _overrides(solid, exc, duration, sets=set_), level) for exc in (b, a)}
    sc0 = next(iter(scs.values()))
    _check_folder(out, "--out", "reciprocity", inputs=(S.scenario_file(scenario), *S.referenced_files(sc0)),
                  recognise=lambda p: any(is_granel_file(f) for f in p.glob("shock-*.nc")), prepare=False)
    from .guard.resources import check_disk
    from .scenario.estimate import run_needs

    check_disk(sum(run_needs(sc).result for sc in scs.values()), out, f"--out {out}: the two runs")
    _check_folder(out, "--out", "reciprocity", inputs=(S.scenario_file(scenario), *S.referenced_files(sc0)),
                  recognise=lambda p: any(is_granel_file(f) for f in p.glob("shock-*.nc")))
    try:  # a stopped run (run.RunStopped) ends with its own line, exit 3
        _, m = run_reciprocity(scs, out, running=lambda exc: console.status(f"running with the shock on {exc}"))
    except S.ScenarioError as e:
        _fail(str(e))
    except NotWritten as e:
        _fail(f"--out {out}: cannot write {e.what} ({e.cause})", 4)
    if json_out:
        print(json.dumps(m, indent=2, default=float))
        return
    t = Table("metric", f"shock on {b}, measured at {a}", f"shock on {a}, measured at {b}", title="reciprocity")
    f, k = m["forward"], m["backward"]
    t.add_row("arrival at the measured granule [ms]", f"{f['arrival_measured_s'] * 1e3:.4f}", f"{k['arrival_measured_s'] * 1e3:.4f}")
    t.add_row("arrival at the solid [ms]", f"{f['arrival_solid_s'] * 1e3:.4f}", f"{k['arrival_solid_s'] * 1e3:.4f}")
    t.add_row("peak velocity toward the solid [m/s]", f"{f['peak_velocity_m_s']:.4f}", f"{k['peak_velocity_m_s']:.4f}")
    t.add_row("far-medium energy, peak [% input]", f"{100 * f['energy_far_peak_frac']:.2f}", f"{100 * k['energy_far_peak_frac']:.2f}")
    t.add_row("solid energy, peak [% input]", f"{100 * f['solid_energy_peak_frac']:.2f}", f"{100 * k['solid_energy_peak_frac']:.2f}")
    t.add_row("solid spectral centroid [kHz]", f"{f['spectral_centroid_hz'] / 1e3:.2f}", f"{k['spectral_centroid_hz'] / 1e3:.2f}")
    Console().print(t)
    console.print(f"nonreciprocity index: {m['nonreciprocity_index']:.4f} (0 = reciprocal); faster: {m['faster_direction']}; "
                  f"figure: {out / 'fig3_velocities.png'}")


@app.command()
def animate(
    result: Path = typer.Argument(..., help="a result NetCDF file"),
    output: Path = typer.Option(Path("movie.mp4"), "-o", "--output", help=".mp4 (GIF fallback) or .gif"),
    field: str = typer.Option("deformation", help="deformation | energy-density"),
    magnification: Optional[float] = typer.Option(None, help="deformation scale (default: x5000 weak, x1000 moderate, x200 strong)"),
    frames: int = typer.Option(120, help="number of frames"),
    fps: int = typer.Option(20, help="frames per second"),
):
    """Render a movie of a run (Appendix C)."""
    from .viz.animate import MAX_FPS, ResultFileError, animate as _animate, read_result

    # the options first, before anything is read
    if frames < 1:
        _fail(f"--frames {frames}: give a whole number of frames >= 1")
    if not 1 <= fps <= MAX_FPS:
        _fail(f"--fps {fps}: give a whole number of frames per second from 1 to {MAX_FPS}")
    if magnification is not None and not (np.isfinite(magnification) and magnification > 0):
        _fail(f"--magnification {magnification}: give a finite number > 0")
    if field not in ("deformation", "energy-density"):
        _fail(f"--field {field!r}: choose deformation or energy-density")
    if output.suffix.lower() not in (".mp4", ".gif"):
        _fail(f"--output {output}: give a .mp4 or .gif file name")
    _input_and_output(result, output)
    try:
        ds = read_result(result)
    except ResultFileError as e:
        _fail(str(e), e.code)
    try:
        with console.status("rendering"):
            path = _animate(ds, output, field, magnification, frames, fps)
    except OSError as e:
        _fail(f"--output {output}: cannot write the movie ({e})", 4)
    console.print(f"wrote {path}")


@app.command()
def bench(
    quick: bool = typer.Option(False, "--quick", help="short runs (0.1 ms), no `granel paper` timing"),
    json_out: bool = typer.Option(False, "--json", help="print one JSON object"),
    cases: Optional[str] = typer.Option(None, help="comma list of case tags, e.g. plate-SSGMC-strong"),
    duration: Optional[str] = typer.Option(None, help="simulated time per case (default 0.8 ms, 0.1 ms with --quick)"),
    reference: bool = typer.Option(False, "--reference", help="also each method's errors against Newmark at 2.5 ns "
                                   "on the strong SSGM-side plate case (when it is among the cases)"),
    fresh: bool = typer.Option(True, "--fresh/--no-fresh", help="time `granel run` in fresh processes"),
):
    """The paper's algorithm and the fast method (its exact integrator, and Newmark at dtau0) side by
    side in one process: wall times, ratios, steps, deviations; fresh-process and `granel paper`
    times."""
    from .studies.benchmark import run_bench

    only = _bench_cases(cases)
    _bench_duration(duration)
    res = run_bench(quick=quick, only=only, duration=duration, reference=reference,
                    fresh=fresh, log=lambda s: console.print(s))
    if json_out:
        print(json.dumps(res, indent=2))
        return
    t = Table("case", "paper [s]", "exact [s]", "ratio", "steps", "newmark [s]", "ratio", "energy dev [% input]",
              "velocity rel L2", title="granel bench (deviations from the paper's algorithm: exact / newmark)")
    for c in res["cases"]:
        t.add_row(f"{c['solid']}-{c['excite']}-{c['shock']}", f"{c['paper_s']:.2f}", f"{c['exact_s']:.3f}",
                  f"{c['exact_ratio']:.1f}", str(c["exact_steps"]), f"{c['newmark_s']:.3f}", f"{c['newmark_ratio']:.1f}",
                  f"{c['exact_energy_dev_pct']:.4f} / {c['newmark_energy_dev_pct']:.4f}",
                  f"{c['exact_velocity_rel_l2']:.2e} / {c['newmark_velocity_rel_l2']:.2e}")
    Console().print(t)
    console.print(f"totals: paper {res['paper_total_s']:.1f} s, exact {res['exact_total_s']:.2f} s, "
                  f"newmark {res['newmark_total_s']:.2f} s")
    if res.get("paper_study_s") is not None:
        console.print(f"granel paper (no animations): {res['paper_study_s']:.1f} s")


def _bench_cases(cases: str | None) -> list[str] | None:
    """`bench --cases`: paper case tags, checked before any benchmark runs."""
    if cases is None:
        return None
    from .studies.paper import CASES, case_tag

    tags = [case_tag(c) for c in CASES]
    asked = [c.strip() for c in cases.split(",")]
    unknown = [c for c in asked if c not in tags]
    if unknown:
        _fail(f"--cases {cases!r}: no case {unknown[0]!r}; choose from {', '.join(tags)}")
    return asked


def _bench_duration(duration: str | None) -> None:
    """`bench --duration`: a positive simulated time the paper cases can run, checked before any
    benchmark runs (the scenario's own checks: the step, the outputs, the memory)."""
    if duration is None:
        return
    from .guard.exits import InputError
    from .io.units import parse_time
    from .studies.benchmark import check_duration

    try:
        t = parse_time(duration)
    except ValueError:
        t = float("nan")
    if not (np.isfinite(t) and t > 0):
        _fail(f"--duration {duration!r}: give a positive simulated time, e.g. 0.1ms")
    try:
        check_duration(duration)
    except InputError as e:
        _fail(f"--duration {duration}: {e}")


@contextmanager
def _cluster_errors(scheduler, source, write_error: str):
    """A command on a dask cluster ends on a scheduler error (exit 2 or 4), an invalid scenario
    or input file (2, naming `source`) or an unwritable output (4, `write_error`)."""
    from .studies.sweep import SchedulerError

    try:
        yield
    except SchedulerError as e:
        _fail(f"--scheduler {scheduler}: {e}", e.code)
    except S.ScenarioError as e:
        _fail(f"{source}: {e}")
    except OSError as e:
        _fail(f"{write_error} ({e})", 4)


def _run_cases(title: str, n: int, run, scheduler, source, write_error: str):
    """Run a sweep's n cases, `run(progress)`, under a progress bar: (its summary, the failed
    cases). A scheduler, scenario or file error ends the command with its exit code (2 or 4)."""
    failed = []
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console) as bar:
        task = bar.add_task(title, total=n)

        def progress(r):
            if r.get("status") != "ok":
                failed.append(r)
            bar.update(task, advance=1)

        with _cluster_errors(scheduler, source, write_error):
            return run(progress), failed


@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., help="sweep TOML (see docs/sweeps.md)"),
    out: Path = typer.Option(Path("sweep-out"), "-o", "--out", help="output directory"),
    workers: int = typer.Option(2, help="LocalCluster worker processes (ignored with --scheduler)"),
    scheduler: Optional[str] = typer.Option(None, help="address of a running dask scheduler, e.g. tcp://host:8786"),
):
    """Run a parameter sweep on dask.distributed; re-running skips finished cases.
    Exit code 3 if any case failed."""
    _check_workers(workers)
    from .guard.exits import NotWritten
    from .studies.sweep import SweepFileError, cases, load_sweep, sweep_inputs, sweep_study

    try:
        spec, base_dir = load_sweep(sweep_file)
    except SweepFileError as e:
        _fail(str(e), e.code)
    except S.ScenarioError as e:
        _fail(str(e), e.code)
    from .guard.outputs import OutputPlan

    plan = OutputPlan(inputs=[sweep_file, *sweep_inputs(spec, base_dir)])
    plan.folder(out, "--out", "sweep", recognise=lambda p: (p / "cases").is_dir() or is_granel_file(p / "summary.nc"))
    plan.file(out / "summary.nc", "--out (its summary.nc)")
    if spec.mode == "spectrum":
        for suffix in (".nc", ".png", ".md"):
            plan.file(out / f"spectrum{suffix}", f"--out (its spectrum{suffix})")
    plan.check().prepare()
    n = len(cases(spec))
    try:
        ds, failed = _run_cases(f"sweep {spec.name}", n,
                                lambda progress: sweep_study(spec, base_dir, out, workers, scheduler, progress),
                                scheduler, sweep_file, f"--out {out}: cannot write the sweep's results")
    except NotWritten as e:
        _fail(f"--out {out}: cannot write the spectrum ({e.cause})", 4)
    metrics = [v for v in ds.data_vars if v != "status"]
    t = Table("metric", "min", "median", "max", title=f"sweep {spec.name}: {n} cases, {n - len(failed)} ok, {len(failed)} failed")
    for m in metrics:
        v = ds[m].values
        if np.isfinite(v).any():
            t.add_row(m, f"{np.nanmin(v):.4g}", f"{np.nanmedian(v):.4g}", f"{np.nanmax(v):.4g}")
    Console().print(t)
    for r in failed:
        console.print(f"[yellow]{r['tag']}[/]: {r['status']}")
    console.print(f"summary: {out / 'summary.nc'}")
    if spec.mode == "spectrum":
        console.print(f"spectrum: {out / 'spectrum.nc'}, {out / 'spectrum.png'}, {out / 'spectrum.md'}")
    if failed:
        _fail(f"{len(failed)} of {n} cases failed (listed above; their status is in {out / 'summary.nc'}); "
              "a rerun retries them", 3)


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
    out: Path = typer.Option(Path("spectrum.nc"), "-o", "--out", help="the spectrum NetCDF; its figure (.png), report "
                                                                      "(.md) and cases (.cases/) go beside it"),
    workers: int = typer.Option(2, help="LocalCluster worker processes (ignored with --scheduler)"),
    scheduler: Optional[str] = typer.Option(None, help="address of a running dask scheduler, e.g. tcp://host:8786"),
):
    """Transmission and nonreciprocity over drive frequency and amplitude: one harmonic run per
    frequency, amplitude and direction, on the sweep engine (re-running the same command reuses
    finished runs). Writes OUT (frequency x amplitude x direction), OUT.png and OUT.md.
    Exit code 3 if any run failed."""
    from pydantic import ValidationError

    from .guard.exits import NotWritten
    from .studies.spectrum import parse_amplitudes, parse_frequencies, spectrum_report
    from .studies.sweep import cases_folder, run_spectrum, spectrum_sweep
    from .studies.sweep import cases, check_mode

    _check_workers(workers)
    for name, value in (("--cycles", cycles), ("--window-cycles", window_cycles), ("--ramp-cycles", ramp_cycles)):
        if not np.isfinite(value):
            _fail(f"{name} {value}: give a finite number of periods")
    try:
        freqs = parse_frequencies(frequencies, linear)
    except ValueError as e:
        _fail(f"--frequencies {frequencies}: {e}")
    try:
        amps = parse_amplitudes(amplitudes)
    except ValueError as e:
        _fail(f"--amplitudes {amplitudes}: {e}")
    if scenario not in S.builtin_names():
        from .guard.reading import check_file

        if not os.path.lexists(scenario):  # neither a file nor a built-in name
            _fail(f"{scenario}: no such scenario file or built-in scenario ({', '.join(S.builtin_names())})")
        check_file(Path(scenario), "scenario")  # a folder, a FIFO, a dangling link, ...: exit 2 or 4 naming it
    try:
        spec = spectrum_sweep(scenario, set_, freqs, amps, drive=drive, measure=measure, both_directions=both_directions,
                              cycles=cycles, window_cycles=window_cycles, ramp_cycles=ramp_cycles, samples_per_period=samples)
    except ValidationError as e:
        _fail(S._format_validation_error(e).replace("invalid scenario", "invalid option").replace("spectrum.", "--")
              .replace("samples_per_period", "samples").replace("_", "-"))
    if out.suffix != ".nc":
        _fail(f"-o {out}: give a NetCDF file name ending in .nc")
    try:
        check_mode(spec, Path("."), cases(spec)[0])
    except S.ScenarioError as e:
        msg = str(e).replace("spectrum.drive", "--drive").replace("spectrum.measure", "--measure")
        _fail(msg if scenario in msg or "--drive" in msg or "--measure" in msg else f"{scenario}: {msg}")
    work = cases_folder(out)
    from .guard.outputs import OutputPlan
    from .studies.sweep import sweep_inputs

    plan = OutputPlan(inputs=sweep_inputs(spec, Path(".")))
    plan.file(out, "-o")
    plan.file(out.with_suffix(".png"), "-o (its figure)")
    plan.file(out.with_suffix(".md"), "-o (its report)")
    plan.folder(work, "-o (its .cases folder)", "spectrum", recognise=lambda p: (p / "cases").is_dir())
    plan.check().prepare()
    n = len(freqs) * len(amps)
    try:
        ds, failed = _run_cases(f"spectrum: {n} cases x {2 if both_directions else 1} direction(s)", n,
                                lambda progress: run_spectrum(spec, out, workers, scheduler, progress),
                                scheduler, scenario, f"-o {out}: cannot write the spectrum's runs in {work}")
    except NotWritten as e:
        _fail(f"-o {out}: cannot write the spectrum ({e.cause})", 4)
    console.print(spectrum_report(ds), markup=False)  # its [kHz], [dB] are units, not markup
    console.print(f"wrote {out}, {out.with_suffix('.png')}, {out.with_suffix('.md')} (runs in {work})")
    for r in failed:
        console.print(f"[yellow]{r['tag']}[/]: {r['status']}")
    if failed:
        _fail(f"{len(failed)} of {n} cases failed (listed above); a rerun retries them", 3)


@app.command()
def design(
    design_file: Path = typer.Argument(..., help="design TOML (see docs/design.md)"),
    out: Path = typer.Option(..., "-o", "--out", help="output folder: the study, trials.nc, best.toml or pareto/"),
    trials: Optional[int] = typer.Option(None, "--trials", help="finished trials to reach (default: the design's `trials`)"),
    workers: int = typer.Option(2, help="LocalCluster worker processes (ignored with --scheduler)"),
    scheduler: Optional[str] = typer.Option(None, help="address of a running dask scheduler, e.g. tcp://host:8786"),
    timeout: Optional[str] = typer.Option(None, "--timeout", help="stop launching trials after this wall time, e.g. "
                                                                  "30min (a rerun continues the study)"),
):
    """Search a design's variables for its objectives with Optuna, each trial a case of the
    sweep engine on dask.distributed; re-running continues the study. Exit code 3 if no trial
    succeeded."""
    _check_workers(workers)
    if trials is not None and trials < 1:
        _fail(f"--trials {trials}: give a whole number of trials >= 1")
    budget = _wall_seconds(timeout, "--timeout")
    from .guard.outputs import OutputPlan, removed_if_refused
    from .studies.design import DesignFileError, check_design, load_design
    from .studies.design_report import design_study
    from .studies.sweep import sweep_inputs

    try:
        spec, base_dir = load_design(design_file)
    except DesignFileError as e:
        _fail(str(e), e.code)
    plan = OutputPlan(inputs=[design_file, *sweep_inputs(spec, base_dir)])
    plan.folder(out, "--out", "design", recognise=lambda p: (p / "study.journal").exists())
    for name in ("trials.nc", "best.toml", "report.md"):
        plan.file(out / name, f"--out (its {name})")
    plan.check()
    with _cluster_errors(scheduler, design_file, f"--out {out}: cannot write the study"):
        check_design(spec, base_dir)  # the fields, and that each variable reaches the runs: before any folder or bar
    failed = []
    with removed_if_refused(out):
        plan.prepare()
        with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                      TimeElapsedColumn(), TimeRemainingColumn(), console=console) as bar:
            task = bar.add_task(f"design {spec.name}", total=trials or spec.trials)

            def progress(number, status, done, total):
                if status != "ok":
                    failed.append((number, status))
                bar.update(task, completed=done)

            with _cluster_errors(scheduler, design_file, f"--out {out}: cannot write the study"):
                def confirming(done, total):
                    bar.update(task, description=f"design {spec.name}: confirming the best at full accuracy", completed=done,
                               total=total)

                res = design_study(spec, base_dir, out, trials, workers, scheduler, max_wall=budget, progress=progress,
                                   reporting=lambda: bar.update(task, description=f"design {spec.name}: re-evaluating "
                                                                                  "the best designs"),
                                   confirming=confirming)
    ds = res["trials"]
    ok = int((ds["status"].values == "ok").sum())
    t = Table("trial", *[f"{o.name} ({o.sense})" for o in spec.objectives], *[v.field for v in spec.variables],
              title=f"design {spec.name}: {ds.sizes['trial']} trials, {ok} ok; best" +
                    (" (Pareto front)" if len(spec.objectives) > 1 else ""))
    for tr in res["best"]:
        t.add_row(str(tr.number), *[f"{v:.5g}" for v in tr.values],
                  *[f"{tr.params[v.field]:.5g}" if isinstance(tr.params[v.field], float) else str(tr.params[v.field])
                    for v in spec.variables])
    Console().print(t)
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
    result: Path = typer.Argument(..., help="a result NetCDF file of `granel run`"),
    out: Path = typer.Option(..., "-o", "--out", help="output folder (created if missing)"),
    format_: Optional[list[str]] = typer.Option(None, "--format", help="vtk | xdmf | csv | extxyz (repeatable or "
                                                                      "comma separated; default: all four)"),
):
    """Export a run for ParaView (VTU + PVD, XDMF), OVITO (extended XYZ) and spreadsheets (CSV):
    the granules at every output and the plate's or beam's nodal displacement, velocity, element
    energy density and stress (plane stress and von Mises, or the beam's bending stress) at every
    stored solid output."""
    from .viz.export import ExportError, export_result, parse_formats, read_export_result

    try:
        formats = parse_formats(format_)
    except ExportError as e:
        _fail(str(e), e.code)
    from .guard.reading import check_file

    check_file(result, "result file")
    _check_folder(out, "-o", "export", inputs=[result], recognise=lambda p: any(p.glob("*.pvd")) or
                  (p / "traces.csv").exists(), prepare=False)
    try:
        ds = read_export_result(result)
    except ExportError as e:
        _fail(str(e), e.code)
    _check_folder(out, "-o", "export", inputs=[result], recognise=lambda p: any(p.glob("*.pvd")) or
                  (p / "traces.csv").exists())
    try:
        with Progress(TextColumn("[bold]export"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                      TimeElapsedColumn(), console=console, transient=True) as bar:
            task = bar.add_task("export", total=None)
            written = export_result(ds, out, formats, lambda done, total: bar.update(task, completed=done, total=total),
                                    name=result)
    except OSError as e:
        _fail(f"-o {out}: cannot write the export ({e})", 4)
    console.print(f"wrote {len(written)} files ({', '.join(formats)}) in {out}")


@app.command()
def wavefield(
    result: Path = typer.Argument(..., help="a result NetCDF file of `granel run` with a plate or a beam"),
    out: Path = typer.Option(..., "-o", "--out", help="output folder: wavefield.nc, kt.png, fk.png, moments.png, "
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
    from .guard.exits import InputError
    from .guard.outputs import OutputPlan
    from .guard.reading import check_file
    from .guard.writing import storable
    from .io.results import ResultFileError
    from .studies.wavefield import (FILES, MOVIE, WavefieldOptions, check_options, parse_bands, parse_window,
                                    plan_wavefield, read_wavefield_result, stage_count, wavefield_study)

    try:
        band_spec = parse_bands(bands)
    except ValueError as e:
        _fail(f"--bands {bands}: {e}")
    try:
        window = parse_window(fit)
    except ValueError as e:
        _fail(f"--fit {fit}: {e}")
    options = WavefieldOptions(band_spec, k_max, window, movie, frames, fps)
    try:
        check_options(options)
    except InputError as e:
        _fail(str(e))
    check_file(result, "result file")
    plan = OutputPlan(inputs=[result])
    plan.folder(out, "-o", "wavefield", recognise=lambda p: (p / "wavefield.nc").exists())
    for name in FILES + ((MOVIE,) if movie else ()):
        plan.file(out / name, f"-o (its {name})")
    plan.check()
    try:
        ds = read_wavefield_result(result)
        settled = plan_wavefield(ds, options, result)
    except (ResultFileError, InputError) as e:
        _fail(str(e), e.code)
    plan.prepare()
    try:
        with Progress(TextColumn("[bold]wavefield[/] {task.description}"), BarColumn(),
                      TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn(), console=console,
                      transient=True) as bar:
            task = bar.add_task("", total=stage_count(options))
            report = wavefield_study(ds, out, options, lambda what, done, total: bar.update(task, completed=done,
                                                                                          description=what),
                                     name=result, plan=settled)
    except OSError as e:
        _fail(f"-o {out}: cannot write the wavefield ({e})", 4)
    t = Table(show_header=False, title=f"granel wavefield: {storable(result.name)}")  # stdout may take only UTF-8
    t.add_row("variance growth exponent", f"kinetic {report.exponent:.3f} +- {report.stderr:.3f}, modal "
              f"{report.modal_exponent:.3f} +- {report.modal_stderr:.3f} (fit over {report.fit[0] * 1e3:.4f}-"
              f"{report.fit[1] * 1e3:.4f} ms)")
    t.add_row("entropy at the end", f"{report.entropy_end:.3f} nats")
    t.add_row("wavenumbers analysed", f"k <= {report.k_max:.1f} rad/m (elements resolve {report.k_resolved:.1f})")
    t.add_row("ridges on the map", f"{report.ridges} (k >= {report.k_window:.1f} rad/m)")
    t.add_row("time", f"{report.seconds:.2f} s")
    Console().print(t)
    console.print(f"wrote {', '.join(str(p.name) for p in report.files)} in {out}")


@app.command("map")
def map_(
    summary: Path = typer.Argument(..., help="a sweep's summary.nc"),
    output: Path = typer.Option(Path("map.png"), "-o", "--output"),
    metric: str = typer.Option("nonreciprocity_index", help="variable to draw"),
    x: Optional[str] = typer.Option(None, help="axis along x (default: the first)"),
    y: Optional[str] = typer.Option(None, help="axis along y (default: the second)"),
):
    """Draw a design map: a metric over two sweep axes (panels over a third)."""
    from .guard.reading import check_file
    from .studies.sweep import SummaryFileError, plot_map, read_summary

    check_file(summary, "sweep summary")
    _picture_output(output, "--output", [summary])
    try:
        ds = read_summary(summary)
    except SummaryFileError as e:
        _fail(str(e), e.code)
    try:
        plot_map(ds, output, metric, x, y)
    except OSError as e:
        _fail(f"--output {output}: cannot write the map ({e})", 4)
    except ValueError as e:
        _fail(str(e))
    console.print(f"wrote {output}")


def main():  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover - every command above is registered by now
    main()
