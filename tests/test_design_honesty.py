"""What `granel design` owes its reader (issue 28): a best design at a variable's bound or a
missed target is said so (summary, report.md, trials.nc); a variable that no run depends on is
refused before the study; a changed design names the fields that differ; refusals leave no
folder behind; the speed line's share outside the solver is never negative.

The real studies run the one-granule impact of test_design (a 0.6 ms run): its peak wall force
is Hertz's, F ~ R^(-8/5), so a target force and a radius range give a known best."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from granel.cli import app
from granel.studies.design import (BOUND_SHARE, TARGET_TOLERANCE, DesignFileError, DesignSpec, VariableSpec,
                                   check_variables_matter, load_design)
from granel.studies.design_search import design_differences, open_study
from granel.studies.design_trials import design_warnings
from test_design import TARGET_N, peak_force, write_design

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
CHAIN = str(ROOT / "scenarios" / "designs" / "cutoff-chain.toml")


def _words(text: str) -> str:
    return " ".join(text.split())


# ---------------------------------------------------------------- bounds and targets


def test_a_value_is_at_a_bound_within_its_share_of_the_range():
    """BOUND_SHARE (1 %) of the range, of its logarithm for a log variable; whole bounds for an
    integer one; none for a categorical one."""
    assert BOUND_SHARE == 0.01 and TARGET_TOLERANCE == 0.01
    lin = VariableSpec(field="x", low=0.0, high=2.0)
    assert [lin.bound_of(v) for v in (0.0, 0.02, 0.0201, 1.0, 1.9799, 1.98, 2.0)] == \
        ["low", "low", None, None, None, "high", "high"]
    log = VariableSpec(field="x", low=0.002, high=0.008, log=True)
    inside = 0.002 * 4 ** 0.0101  # 1.01 % of the log range: 0.002028, 0.47 % of the linear one
    assert log.bound_of(0.002 * 4 ** 0.0099) == "low" and log.bound_of(inside) is None
    assert VariableSpec(field="x", low=0.002, high=0.008).bound_of(inside) == "low"
    assert log.bound_of(0.008 / 4 ** 0.0099) == "high"
    ints = VariableSpec(field="n", low=2, high=6, integer=True)
    assert [ints.bound_of(v) for v in (2, 3, 5, 6)] == ["low", None, None, "high"]
    assert VariableSpec(field="m", choices=["a", "b"]).bound_of("a") is None
    assert log.probes() == [0.002, pytest.approx(0.004, rel=1e-15), 0.008] and ints.probes() == [2, 4, 6]


def _study(spec, rows, attrs=None):
    """An in-memory study of finished trials: rows of (params, values, metrics, constraints),
    each trial with the user attributes `attrs[k]` too."""
    import optuna
    from optuna.trial import create_trial

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(directions=spec.directions)
    dists = {v.field: v.distribution() for v in spec.variables}
    for k, (params, values, metrics, cons) in enumerate(rows):
        study.add_trial(create_trial(params=params, distributions=dists, values=values,
                                     user_attrs={"metrics": metrics, "constraints": cons, **(attrs[k] if attrs else {})}))
    return study


def test_a_best_at_a_bound_and_a_missed_target_are_warned(tmp_path):
    """Trial 1 is the best (misfit 0.2, above the 1 % tolerance) at 0.5 % of the log range from
    the low bound: both said, with its numbers; a best at 2 % of the range meeting the target
    (misfit 0.004) gives no warning, unless the objective asks for 0.001."""
    from granel.studies.design_trials import best_trials

    spec, _ = load_design(write_design(tmp_path))
    low = 0.002 * 4 ** 0.005
    study = _study(spec, [({"media.0.radius": 0.005}, [0.5], {"peak_wall_force_N": 1.3}, []),
                          ({"media.0.radius": low}, [0.2], {"peak_wall_force_N": 2.1}, [])])
    warned = design_warnings(spec, study, best_trials(spec, study))
    assert warned == [
        f"media.0.radius = {low:.6g} in the best design (trial 1) is at its low bound 0.002 (within 1 % of the range, "
        "on the log scale): the optimum may lie outside the range",
        "the best design misses the target peak_wall_force_N = 2.6237: trial 1 gives 2.1, a misfit |m / target - 1| "
        "of 0.2 (tolerance 0.01)"]
    inside = 0.002 * 4 ** 0.02
    study = _study(spec, [({"media.0.radius": inside}, [0.004], {"peak_wall_force_N": 2.6342}, [])])
    assert design_warnings(spec, study, best_trials(spec, study)) == []
    strict = spec.model_copy(update={"objectives": [spec.objectives[0].model_copy(update={"tolerance": 1e-3})]})
    assert design_warnings(strict, study, best_trials(strict, study))[0].endswith("of 0.004 (tolerance 0.001)")


def test_a_pareto_front_and_an_infeasible_study_are_warned(tmp_path):
    """On a front, each design appears once, the designs at a bound are counted and a target is
    missed only when every design of the front misses it; a study whose finished trials all break a constraint has no
    best design, and says so."""
    from granel.studies.design_trials import best_trials

    path = write_design(tmp_path, extra='[[objectives]]\nmetric = "input_work_J"\ndirection = "maximize"\n')
    spec, _ = load_design(path)
    rows = [({"media.0.radius": 0.008}, [0.3, 2e-6], {"peak_wall_force_N": 1.8}, []),
            ({"media.0.radius": 0.005}, [0.1, 1e-6], {"peak_wall_force_N": 2.9}, [])]
    study = _study(spec, [*rows, rows[1]])  # a sampler asking for the same values again (NSGA-II does)
    front = best_trials(spec, study)
    assert len(front) == 2 and sorted(t.number for t in front) == [0, 1]  # each design once, its first trial
    warned = design_warnings(spec, study, front)
    assert warned[0].startswith("media.0.radius in 1 of the 2 Pareto designs is at its high bound 0.008")
    assert warned[1].startswith("no design of the Pareto front meets the target peak_wall_force_N = 2.6237: trial 1 "
                                "gives 2.9, a misfit |m / target - 1| of 0.1")
    cons, _ = load_design(write_design(tmp_path, extra='[[constraints]]\nmetric = "granular_mass_kg"\nmax = 0.001\n'))
    study = _study(cons, [({"media.0.radius": 0.005}, [0.1], {"peak_wall_force_N": 2.9}, [3.1])])
    assert design_warnings(cons, study, best_trials(cons, study)) == [
        "no finished trial meets the constraints: there is no best design"]


def test_the_command_says_when_its_best_is_at_a_bound_and_misses_the_target(tmp_path):
    """Radius in [2, 4] mm for a force that needs R = 6.31 mm: the force falls with R, so the best
    of the study is its largest radius, 4 mm (queued as the first trial), at the high bound, and
    its misfit is Hertz's F(4 mm) / target - 1 = 1.0758 (the recorded peak is Hertz's within 5e-4,
    test_design.test_the_closed_form_matches_a_run: 1e-3 in the misfit). Exit 0; the warnings are
    in the summary, in report.md and in trials.nc."""
    from granel.io.results import read_netcdf

    var = '[[variables]]\nfield = "media.0.radius"\nlow = 0.002\nhigh = 0.004\n'
    path = write_design(tmp_path, trials=3, seed=1, variables=var)
    spec, _ = load_design(path)
    out = tmp_path / "out"
    out.mkdir()
    open_study(spec, out).enqueue_trial({"media.0.radius": 0.004})
    res = runner.invoke(app, ["design", str(path), "-o", str(out), "--workers", "1"])
    assert res.exit_code == 0, res.output
    misfit = peak_force(0.004) / TARGET_N - 1
    assert misfit == pytest.approx(1.0758, abs=1e-4)
    ds = read_netcdf(out / "trials.nc")
    best = int(np.nanargmin(ds["objective_peak_wall_force_N_misfit"].values))
    assert ds["var_media.0.radius"].values[best] == 0.004
    assert ds["objective_peak_wall_force_N_misfit"].values[best] == pytest.approx(misfit, rel=2e-3)
    warned = json.loads(ds.attrs["warnings"])
    assert len(warned) == 2
    assert warned[0].startswith("media.0.radius = 0.004 in the best design (trial 0) is at its high bound 0.004")
    assert warned[1].startswith("the best design misses the target peak_wall_force_N = 2.6237: trial 0 gives")
    said = _words(res.output)
    report = _words((out / "report.md").read_text())
    for w in warned:
        assert f"warning: {w}" in said and f"- {w}" in report
    assert "**Warnings:**" in report and "met within 0.01" in report


# ---------------------------------------------------------------- variables no run depends on


def _spec(base, var, mode="run", pair=("C:1", "C:8"), overrides=(), others=()):
    return DesignSpec.model_validate({"base": base, "mode": mode, "pair": list(pair), "overrides": list(overrides),
                                      "variables": [var, *others],
                                      "objectives": [{"metric": "granular_mass_kg", "direction": "minimize"}]})


PAPER = {"mode": "reciprocity", "pair": ("LSGM:3", "SSGM:C")}
ALU = 'materials.alu={E = 70.0e9, rho = 2700.0, nu = 0.33}'
TIED = [f"media.0.radii.{k}" for k in range(1, 8)]


@pytest.mark.parametrize("base, var, kw", [
    (CHAIN, {"field": "media.0.radii.0", "tied": TIED, "low": 0.002, "high": 0.01, "log": True}, {}),
    (CHAIN, {"field": "excitations.1.value", "low": 5.0, "high": 20.0}, {}),            # the preload
    (CHAIN, {"field": "excitations.0.fmax", "low": 0.05, "high": 0.2}, {}),             # the pulse's amplitude
    (CHAIN, {"field": "contact.mu", "low": 0.0, "high": 0.3}, {}),
    (CHAIN, {"field": "materials.steel.E", "low": 1e11, "high": 3e11}, {}),
    (CHAIN, {"field": "simulation.duration", "low": 1e-3, "high": 3e-3}, {}),
    # a pulse's duration on a load that is constant at the base, whose kind is another variable
    (CHAIN, {"field": "excitations.1.tau", "low": 1e-5, "high": 1e-4},
     {"overrides": ["excitations.1.fmax=10.0"], "others": [{"field": "excitations.1.kind", "choices": ["constant", "half_sine"]}]}),
    ("paper", {"field": "media.1.radius", "low": 0.003, "high": 0.007}, PAPER),
    ("paper", {"field": "media.1.columns.1", "low": 2, "high": 6, "integer": True}, PAPER),
    ("paper", {"field": "solid.thickness", "low": 5e-4, "high": 2e-3, "log": True}, PAPER),
    ("paper", {"field": "solid.material", "choices": ["steel", "alu"]}, {**PAPER, "overrides": [ALU]}),
    ("paper", {"field": "solid.thickness", "low": 5e-4, "high": 2e-3}, {**PAPER, "overrides": ['solid.kind="beam"']}),
])
def test_a_variable_the_runs_depend_on_is_kept(base, var, kw):
    check_variables_matter(_spec(base, var, **kw), ROOT)


@pytest.mark.parametrize("base, var, kw, why", [
    (CHAIN, {"field": "excitations.1.tau", "low": 1e-6, "high": 1e-4}, {},
     "excitations.1 is a constant load, which does not use tau"),
    (CHAIN, {"field": "excitations.0.frequency", "low": 1e3, "high": 1e4}, {},
     "excitations.0 is a half_sine load, which does not use frequency"),
    (CHAIN, {"field": "solid.thickness", "low": 1e-3, "high": 2e-3}, {}, "the design has no solid"),
    (CHAIN, {"field": "materials.alu.E", "low": 6e10, "high": 8e10}, {"overrides": [ALU]},
     "no granule and no elastic solid is made of alu"),
    (CHAIN, {"field": "description", "choices": ["a", "b"]}, {}, "the solver never receives it"),
    ("paper", {"field": "excitations.0.granule", "choices": ["LSGM:3", "SSGM:C"]}, PAPER,
     "the design's 'reciprocity' mode sets it in every run"),
    ("paper", {"field": "solid.thickness", "low": 5e-4, "high": 2e-3}, {**PAPER, "overrides": ['solid.kind="rigid"']},
     "the rigid solid does not use thickness"),
    ("paper", {"field": "solid.mesh.nx", "low": 4, "high": 8, "integer": True}, {**PAPER, "overrides": ['solid.kind="beam"']},
     "the beam solid does not use mesh.nx"),
])
def test_a_variable_no_run_depends_on_is_refused(base, var, kw, why):
    with pytest.raises(DesignFileError) as e:
        check_variables_matter(_spec(base, var, **kw), ROOT)
    msg = str(e.value)
    assert msg.startswith(f"variables.0.field = {var['field']!r}: no run of this design depends on it ({why}): its values ")
    assert msg.endswith("build the same granules, loads, solid and solver settings")


@pytest.mark.parametrize("change, says", [
    # a typo'd field: found by the field check (the variable never reaches the scenario)
    (('field = "media.0.radius"', 'field = "media.0.radios"'), "variables.0.field = 'media.0.radios'"),
    # a pulse's duration on a constant load
    (('field = "media.0.radius"\nlow = 0.002\nhigh = 0.008\nlog = true',
      'field = "excitations.1.tau"\nlow = 1e-6\nhigh = 1e-4'),
     "variables.0.field = 'excitations.1.tau': no run of this design depends on it (excitations.1 is a constant load, "
     "which does not use tau): its values 1e-06, 5.05e-05, 0.0001"),
])
def test_a_refused_variable_leaves_no_folder_and_no_progress_bar(tmp_path, change, says):
    """The field checks run before the output folder is made and the progress bar shown."""
    path = write_design(tmp_path, trials=4)
    (tmp_path / "impact.toml").write_text((tmp_path / "impact.toml").read_text() + (
        '[[excitations]]\ngranule = "G:1"\nkind = "constant"\nvalue = 0.5\ndirection = [-1.0, 0.0]\n'))
    path.write_text(path.read_text().replace(*change))
    out = tmp_path / "out" / "deeper"
    res = runner.invoke(app, ["design", str(path), "-o", str(out), "--workers", "1"])
    assert res.exit_code == 2, res.output
    assert says in _words(res.output)
    assert "0/4" not in res.output and not (tmp_path / "out").exists()


def test_an_unusable_scheduler_leaves_no_folder(tmp_path):
    path = write_design(tmp_path, trials=2)
    res = runner.invoke(app, ["design", str(path), "-o", str(tmp_path / "out"), "--scheduler", "not an address"])
    assert res.exit_code == 2 and "not a scheduler address" in _words(res.output)
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- what defines a study


def test_a_changed_design_names_each_field_that_differs(tmp_path):
    """name, description, trials and a target's tolerance define no study: the folder's study
    continues (and stores the new values); seed and a bound do: the refusal names both, with
    the stored and the new values."""
    path = write_design(tmp_path, trials=5, seed=2)
    spec, _ = load_design(path)
    out = tmp_path / "out"
    out.mkdir()
    open_study(spec, out)
    text = path.read_text()
    relabelled = (text.replace('name = "inverse"', 'name = "renamed"\ndescription = "the same study, described"')
                  .replace("trials = 5", "trials = 50").replace(f"target = {TARGET_N}", f"target = {TARGET_N}\ntolerance = 0.002"))
    path.write_text(relabelled)
    again, _ = load_design(path)
    study = open_study(again, out)
    assert study.user_attrs["design"]["description"] == "the same study, described"
    path.write_text(relabelled.replace("seed = 2", "seed = 3").replace("high = 0.008", "high = 0.009"))
    changed, _ = load_design(path)
    with pytest.raises(DesignFileError) as e:
        open_study(changed, out)
    assert "(seed: 2 there, 3 here; variables.0.high: 0.008 there, 0.009 here)" in str(e.value)
    res = runner.invoke(app, ["design", str(path), "-o", str(out), "--workers", "1"])
    assert res.exit_code == 2 and "seed: 2 there, 3 here; variables.0.high: 0.008 there, 0.009 here" in _words(res.output)
    assert not (out / "trials.nc").exists()


def test_fields_a_stored_design_lacks_count_as_their_defaults(tmp_path):
    """A design stored by an older granel (no `tolerance`, no `tied`, no `population`) is this
    one while the new fields sit at their defaults; a count of variables that changed is named."""
    spec, _ = load_design(write_design(tmp_path))
    mine = json.loads(spec.model_dump_json())
    older = {k: v for k, v in mine.items() if k != "population"}
    older["objectives"] = [{k: v for k, v in o.items() if k != "tolerance"} for o in mine["objectives"]]
    older["variables"] = [{k: v for k, v in o.items() if k != "tied"} for o in mine["variables"]]
    assert design_differences(older, mine) == []
    tied = {**mine, "variables": [{**mine["variables"][0], "tied": ["media.0.gap"]}]}
    assert design_differences(older, tied) == [("variables.0.tied", [], ["media.0.gap"])]
    two = {**mine, "variables": mine["variables"] * 2}
    assert design_differences(mine, two) == [("variables (count)", 1, 2)]


# ---------------------------------------------------------------- the speed line


def test_an_old_journal_with_reused_cases_gives_no_negative_share(tmp_path):
    """Before trials were marked `reused`, a trial whose values had been run carried its stored
    case's times (0.5 s in the solver) with a launch-to-result time of 0.05 s: three of them and
    one fresh trial read 1 - 2.0 / 0.85 = -135 % outside the solver. A case time longer than the
    launch-to-result time marks them: 1 - 0.5 / 0.85 = 41 %."""
    from granel.studies.design_report import study_speed

    spec, _ = load_design(write_design(tmp_path))
    study = _study(spec, [({"media.0.radius": r}, [0.1], {}, []) for r in (0.004, 0.005, 0.005, 0.005)],
                   [{"solver_s": 0.5, "wall_s": 0.6, "turnaround_s": turn} for turn in (0.7, 0.05, 0.05, 0.05)])
    study.set_user_attr("sessions", [{"wall_s": 2.0, "trials": 4, "workers": 1}])
    sp = study_speed(study)
    assert sp["reused"] == 3
    assert sp["outside_solver"] == pytest.approx(1 - 0.5 / 0.85, rel=1e-12)


def test_repeated_values_reuse_their_case_with_no_solver_time(tmp_path):
    """Six trials over two radii (a categorical variable) run at most two cases: the other trials
    reuse them, marked `reused` in trials.nc with no solver time; every fresh trial spends at most
    its case time in the solver and at most its launch-to-result time in its case, so the share
    outside the solver lies in [0, 1] and the report says how many trials reused a case."""
    from granel.studies.design_search import DesignRunOptions, run_design
    from granel.studies.design_report import study_speed, write_study_report

    var = '[[variables]]\nfield = "media.0.radius"\nchoices = [0.004, 0.006]\n'
    spec, base = load_design(write_design(tmp_path, trials=6, seed=1, variables=var))
    res = run_design(spec, base, tmp_path / "out", options=DesignRunOptions(workers=1))
    ds = res["trials"]
    reused = ds["reused"].values
    assert ds.sizes["trial"] == 6 and (ds["status"].values == "ok").all() and reused.sum() >= 4
    solver, wall, turn = (ds[k].values for k in ("solver_s", "wall_s", "turnaround_s"))
    assert (solver[reused] == 0).all() and (wall[reused] <= turn[reused]).all()
    fresh = ~reused
    assert (solver[fresh] > 0).all() and (solver[fresh] <= wall[fresh]).all() and (wall[fresh] <= turn[fresh]).all()
    sp = study_speed(res["study"])
    assert sp["reused"] == reused.sum()
    assert 0 <= sp["outside_solver"] <= 1
    assert sp["outside_solver"] == pytest.approx(1 - solver.sum() / turn.sum(), rel=1e-12)
    write_study_report(spec, base, res["study"], tmp_path / "out")
    report = _words((tmp_path / "out" / "report.md").read_text())
    assert f"{int(reused.sum())} finished trial(s) asked values already run and reused their case" in report
