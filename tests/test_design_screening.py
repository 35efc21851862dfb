"""A screened design study (`[screening]`): every trial at a looser accuracy, the best run again
at the design's own, and the best design the best of those confirmations.

The design is test_design's impact: one granule pushed into a rigid wall, its peak wall force
the objective (Hertz's, closed form). The screening samples the run every 5 us instead of every
1 us, so the screened peak force misses the peak of a 60 us impact by up to (pi 5/60)^2 / 8 of
it, about 0.9 %: screened and confirmed values differ, as a looser accuracy makes them.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from granel.cli import app
from test_design import write_design

runner = CliRunner()
SCREEN = '\n[screening]\noverrides = [\'simulation.output_every="5us"\', "simulation.rtol=1e-4"]\nconfirm = 3\n'


@pytest.mark.parametrize("overrides, says", [
    ("['media.0.radius=0.004']", "screening.overrides.0 = 'media.0.radius=0.004': a screening sets simulation fields only"),
    ("['simulation.rtol']", "screening.overrides.0"),
    ("[]", "screening.overrides"),
    ("['simulation.rtol=-1']", "simulation.rtol"),
])
def test_a_bad_screening_is_refused_before_anything_runs(tmp_path, overrides, says):
    path = write_design(tmp_path, trials=4, extra=f"\n[screening]\noverrides = {overrides}\n")
    res = runner.invoke(app, ["design", str(path), "-o", str(tmp_path / "out"), "--workers", "1"])
    assert res.exit_code == 2, res.output
    assert says in " ".join(res.output.split())
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # a design study, its report and a rerun on a cluster (about 25 s)
def test_the_best_are_confirmed_at_the_design_s_accuracy(tmp_path):
    """8 screened trials, the 3 best confirmed: the confirmations are the 3 best by screened
    misfit, each confirmed value is what an unscreened trial of the same values gives (the same
    run, so equal to the last bit), the reported best is the best confirmation, and the report
    and trials.nc show both fidelities."""
    from granel.studies.screening import screened_ranking
    from granel.studies.design import DesignSpec, load_design
    from granel.studies.design_search import DesignRunOptions, run_design
    from granel.studies.design_trials import evaluate_trial, trial_case
    from granel.studies.design_report import design_study

    spec, base = load_design(write_design(tmp_path, trials=8, seed=3, extra=SCREEN))
    res = design_study(spec, base, tmp_path / "out", options=DesignRunOptions(workers=1))
    study = res["study"]
    confirmed = study.user_attrs["confirmed"]
    ranked = screened_ranking(spec, study)
    assert sorted(confirmed) == sorted(str(t.number) for t in ranked[:3])
    full = DesignSpec.model_validate({**json.loads(spec.model_dump_json()), "screening": None})
    differ = 0
    for t in ranked[:3]:
        r = evaluate_trial(full.model_dump_json(), str(base), trial_case(spec, t.number, t.params),
                           str(tmp_path / "direct"))
        value = abs(r["metrics"]["peak_wall_force_N"] / 2.6237 - 1)  # the objective: the misfit to its target
        assert confirmed[str(t.number)]["values"] == [value]
        differ += value != t.values[0]
    assert differ == 3  # the screened values are another accuracy's
    best = res["best"][0]
    assert best.values[0] == min(c["values"][0] for c in confirmed.values())
    ds = res["trials"]
    var = "confirmed_peak_wall_force_N_misfit"
    assert np.isfinite(ds[var].values).sum() == 3
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Screening" in report and "Kendall" in report
    for t in ranked[:3]:
        assert f"| {t.number} |" in report
    # a rerun of the finished study confirms nothing again
    again = run_design(spec, base, tmp_path / "out", options=DesignRunOptions(workers=1))
    assert again["study"].user_attrs["confirmed"] == confirmed
