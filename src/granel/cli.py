"""The `granel` command line (typer + rich)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from . import scenario as S
from .units import parse_time

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False, help="granel: granular-elastic solid interface simulator")
console = Console(stderr=True)


def _fail(msg: str, code: int = 2):
    console.print(f"[bold red]error:[/] {msg}")
    raise typer.Exit(code)


def _overrides(solid, excite, shock, fmax, duration, dt, output_every, solver, sets) -> list[str]:
    ov = []
    if solid:
        ov.append(f'solid.kind="{solid}"')
    if excite:
        ov.append(f'excitations.0.granule="{excite}"')
    if shock:
        ov.append(f'excitations.0.shock="{shock}"')
        ov.append("excitations.0.fmax=nan")  # cleared below
    if fmax is not None:
        ov.append(f"excitations.0.fmax={fmax}")
    if duration:
        ov.append(f'simulation.duration="{duration}"')
    if dt:
        ov.append(f'simulation.dt="{dt}"')
    if output_every:
        ov.append(f'simulation.output_every="{output_every}"')
    if solver:
        ov.append(f'simulation.solver="{solver}"')
    return ov + list(sets or [])


def load_scenario(name: str, overrides: list[str]) -> S.Scenario:
    raw, base = S.load_raw(name)
    raw = S.apply_overrides(raw, [o for o in overrides if o != "excitations.0.fmax=nan"])
    if "excitations.0.fmax=nan" in overrides and raw.get("excitations"):
        raw["excitations"][0].pop("fmax", None)  # a named shock replaces an explicit fmax
    sc = S.validate(raw, base)
    sc._base = base
    return sc


@app.command()
def run(
    scenario: str = typer.Argument(..., help="built-in name (see `granel scenarios`) or a TOML file"),
    solid: Optional[str] = typer.Option(None, help="plate | beam | rigid"),
    excite: Optional[str] = typer.Option(None, help="granule label of the first excitation, e.g. LSGM:3 or SSGM:C"),
    shock: Optional[str] = typer.Option(None, help="weak | moderate | strong (the paper's half-sine levels)"),
    fmax: Optional[float] = typer.Option(None, help="peak force of the first excitation [N]"),
    duration: Optional[str] = typer.Option(None, help="simulated time, e.g. 0.8ms"),
    dt: Optional[str] = typer.Option(None, help="time step, e.g. 4e-8 or 40ns"),
    output_every: Optional[str] = typer.Option(None, help="output interval, e.g. 1us"),
    solver: Optional[str] = typer.Option(None, help="coupled solver: paper | fast"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value (repeatable)"),
    output: Path = typer.Option(Path("granel-out.nc"), "-o", "--output", help="result NetCDF file"),
    json_summary: bool = typer.Option(False, "--json-summary", help="print the summary as JSON on stdout"),
    checkpoint_every: Optional[str] = typer.Option(None, help="write a resumable checkpoint at this simulated interval"),
    resume: Optional[Path] = typer.Option(None, help="continue a run from its checkpoint (the -o file's .ckpt)"),
):
    """Simulate a scenario and write its results to NetCDF."""
    from .results import write_netcdf
    from .run import run_scenario, summarize

    if shock is not None and shock not in S.SHOCK_LEVELS:
        _fail(f"--shock {shock!r}: choose weak, moderate or strong")
    if shock is not None and fmax is not None:
        _fail("--shock and --fmax are exclusive")
    ov = _overrides(solid, excite, shock, fmax, duration, dt, output_every, solver, set_)
    if checkpoint_every:
        ov.append(f'simulation.checkpoint_every="{checkpoint_every}"')
    try:
        sc = load_scenario(scenario, ov)
    except S.ScenarioError as e:
        _fail(str(e))
    total = sc.simulation.duration
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.percentage:>5.1f}%"),
                  TextColumn("t = {task.fields[t]}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console) as bar:
        task = bar.add_task(f"{sc.name} ({sc.solid.kind if sc.solid else 'rigid'})", total=total, t="0")

        def progress(t, steps=0):
            bar.update(task, completed=min(t, total), t=f"{t * 1e3:.4f} ms")

        try:
            ds = run_scenario(sc, progress, checkpoint=output.with_suffix(".ckpt"), resume=resume)
        except S.ScenarioError as e:
            _fail(str(e))
        except RuntimeError as e:
            _fail(f"run stopped: {e}", code=3)
    write_netcdf(ds, output)
    summary = summarize(ds)
    summary["output"] = str(output)
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
    solid: Optional[str] = typer.Option(None, help="plate | beam | rigid"),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="override any field: key.path=value"),
):
    """Draw the packing with labels, walls, the solid and the excitations."""
    from .plots import plot_geometry

    try:
        sc = load_scenario(scenario, _overrides(solid, None, None, None, None, None, None, None, set_))
    except S.ScenarioError as e:
        _fail(str(e))
    plot_geometry(sc, output)
    console.print(f"wrote {output}")


def main():  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()


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
    from .solid.build import build_solid
    from .solid.modal import classify_modes, modal_analysis

    try:
        sc = load_scenario(scenario, _overrides(solid, None, None, None, None, None, None, None, set_))
    except S.ScenarioError as e:
        _fail(str(e))
    if sc.solid is None or sc.solid.kind == "rigid":
        _fail("modes: the solid is rigid; choose --solid plate or --solid beam")
    system, _, _ = S.build_granular(sc, sc.base)
    model = build_solid(sc, system)
    want = max(count, 7 if plot else 0)
    md = modal_analysis(model, min(want, model.ndof) if want < model.ndof else None)
    n = min(count, md.count)
    kinds = classify_modes(model, md, range(max(n, min(7, md.count))))
    out = {
        "solid": model.kind,
        "dofs": model.ndof,
        "elements": model.nelements,
        "periods_ms": [float(p) for p in md.periods[:n] * 1e3],
        "kinds": kinds[:n],
        "modes_computed": md.count,
    }
    if plot:
        from .plots import plot_modes

        which = tuple(k for k in (0, 3, 6) if k < md.count)
        plot_modes(model, md, kinds, which, plot)
        out["plot"] = str(plot)
    if json_out:
        print(json.dumps(out, indent=2))
        return
    t = Table("mode", "period [ms]", "frequency [kHz]", "kind", title=f"{model.kind}: {model.ndof} DOFs, {model.nelements} elements")
    for k in range(n):
        t.add_row(str(k + 1), f"{md.periods[k] * 1e3:.5f}", f"{1 / md.periods[k] / 1e3:.3f}", kinds[k])
    Console().print(t)
