"""The reciprocity study of `granel reciprocity`: one shock from each end of a pair of granules,
both runs kept, compared (`analysis.reciprocity.reciprocity_metrics`) and drawn (Fig. 3)."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

from .. import run as R
from .. import scenario as S
from ..analysis.reciprocity import reciprocity_metrics
from ..guard.exits import NotWritten
from ..io.results import with_every_granule, write_netcdf
from ..viz.figures import fig3_velocities


def run_path(out: Path, excited: str) -> Path:
    """The result file of the run with the shock on granule `excited` (e.g. shock-LSGM3.nc)."""
    return Path(out) / f"shock-{excited.replace(':', '')}.nc"


def run_reciprocity(scenarios: dict[str, S.Scenario], out: Path, running=None) -> tuple[dict, dict]:
    """Run both directions into folder `out` and compare them. `scenarios` holds the two runs'
    validated scenarios by the granule each shocks, the forward run's first (its shock on B,
    measured at A). Each result is written to `run_path`, the metrics are
    `reciprocity_metrics(forward, backward)`, and Fig. 3 goes to out/fig3_velocities.png.
    `running(granule)`, if given, is a context manager around each run (a status line). Returns
    (the results by shocked granule, the metrics). A RuntimeError of a run is `run.RunStopped`,
    a failed write `guard.exits.NotWritten` ("the run" or "the figure")."""
    out = Path(out)
    running = running or (lambda excited: nullcontext())
    runs = {}
    for excited, sc in scenarios.items():
        try:
            with running(excited):
                ds = R.run_scenario(sc)
        except RuntimeError as e:
            raise R.RunStopped(f"run with the shock on {excited}", e) from e
        path = run_path(out, excited)
        try:
            write_netcdf(ds, path)
        except OSError as e:
            raise NotWritten("the run", path, e) from e
        runs[excited] = with_every_granule(ds)
    forward, backward = runs.values()
    metrics = reciprocity_metrics(forward, backward)
    try:
        fig3_velocities(forward, backward, out / "fig3_velocities")
    except OSError as e:
        raise NotWritten("the figure", out / "fig3_velocities.png", e) from e
    return runs, metrics


def plan_reciprocity(out: Path, scenarios: dict[str, S.Scenario], source: str) -> None:
    """The output folder of `granel reciprocity`, checked before any computation (its inputs:
    the scenario `source` and the files it names; the disk for both runs) and then made."""
    from ..guard.outputs import OutputPlan
    from ..guard.owners import is_granel_file
    from ..guard.resources import check_disk
    from ..scenario.estimate import run_needs

    first = next(iter(scenarios.values()))
    plan = OutputPlan(inputs=[p for p in (S.scenario_file(source), *S.referenced_files(first)) if p is not None])
    plan.folder(out, "--out", "reciprocity", recognise=lambda p: any(is_granel_file(f) for f in p.glob("shock-*.nc")))
    plan.check()
    check_disk(sum(run_needs(sc).result for sc in scenarios.values()), out, f"--out {out}: the two runs")
    plan.prepare()


def metric_rows(m: dict, a: str, b: str) -> tuple[list[str], list[list[str]]]:
    """`granel reciprocity`'s table of `reciprocity_metrics` (forward: shock on b): (header, rows)."""
    f, k = m["forward"], m["backward"]
    rows = [("arrival at the measured granule [ms]", "arrival_measured_s", 1e3, ".4f"),
            ("arrival at the solid [ms]", "arrival_solid_s", 1e3, ".4f"),
            ("peak velocity toward the solid [m/s]", "peak_velocity_m_s", 1.0, ".4f"),
            ("far-medium energy, peak [% input]", "energy_far_peak_frac", 100.0, ".2f"),
            ("solid energy, peak [% input]", "solid_energy_peak_frac", 100.0, ".2f"),
            ("solid spectral centroid [kHz]", "spectral_centroid_hz", 1e-3, ".2f")]
    return (["metric", f"shock on {b}, measured at {a}", f"shock on {a}, measured at {b}"],
            [[label, format(f[key] * s, fmt), format(k[key] * s, fmt)] for label, key, s, fmt in rows])
