"""The reciprocity study of `granel reciprocity`: one shock from each end of a pair of granules,
both runs kept, compared (`analysis.reciprocity.reciprocity_metrics`) and drawn (Fig. 3)."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

from .. import run as R
from .. import scenario as S
from ..analysis.reciprocity import reciprocity_metrics
from ..guard.exits import NotWritten
from ..io.results import write_netcdf
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
        runs[excited] = ds
    forward, backward = runs.values()
    metrics = reciprocity_metrics(forward, backward)
    try:
        fig3_velocities(forward, backward, out / "fig3_velocities")
    except OSError as e:
        raise NotWritten("the figure", out / "fig3_velocities.png", e) from e
    return runs, metrics
