"""The functions the commands call (issue 29: a command parses, checks, calls one function and
prints), each on its own: what it writes, what it returns, and the errors by which the command
tells its failures apart."""

from __future__ import annotations

import math
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import pytest

import granel.run as R
import granel.studies.spectrum as SP
import granel.studies.sweep as SW
import granel.studies.spectrum_report as SR
import granel.studies.spectrum_study as SS
from granel import scenario as S
from granel.analysis.reciprocity import reciprocity_metrics
from granel.guard.exits import FILES, STOPPED, GranelError, InputError, NotWritten
from granel.guard.outputs import STAMP, OutputPlan, removed_if_refused
from granel.io.results import read_netcdf
from granel.studies.reciprocity import run_path, run_reciprocity

SHORT = ['solid.kind="rigid"', 'simulation.duration="0.005ms"']


def rigid(excited: str) -> S.Scenario:
    return S.load("paper", [*SHORT, f'excitations.0.granule="{excited}"'])


def stopped(*args, **kwargs):
    raise RuntimeError("boom")


# ------------------------------------------------------------------------- granel run


def test_run_to_file_writes_the_result_and_returns_its_summary(tmp_path):
    sc = S.load("paper", [*SHORT, 'simulation.checkpoint_every="0.002ms"'])
    out, ckpt = tmp_path / "r.nc", tmp_path / "r.ckpt"
    times = []
    summary = R.run_to_file(sc, out, times.append, checkpoint=ckpt)
    np.testing.assert_equal(summary, {**R.summarize(read_netcdf(out)), "output": str(out)})
    assert times and times[-1] == pytest.approx(5e-6)
    assert not ckpt.exists()  # the result replaces the checkpoint


def test_run_to_file_tells_a_stopped_run_from_a_failed_write(tmp_path, monkeypatch):
    (tmp_path / "folder.nc").mkdir()
    with pytest.raises(NotWritten) as e:
        R.run_to_file(rigid("SSGM:C"), tmp_path / "folder.nc")
    assert e.value.code == FILES and e.value.what == "the result" and isinstance(e.value.cause, OSError)
    monkeypatch.setattr(R, "run_scenario", stopped)
    with pytest.raises(R.RunStopped, match="^run stopped: boom$") as e:
        R.run_to_file(rigid("SSGM:C"), tmp_path / "r.nc")
    assert e.value.code == STOPPED and not (tmp_path / "r.nc").exists()


# ------------------------------------------------------------------------- granel reciprocity


def test_run_reciprocity_writes_both_runs_and_returns_their_metrics(tmp_path):
    scenarios = {"SSGM:C": rigid("SSGM:C"), "LSGM:3": rigid("LSGM:3")}  # the forward run first
    entered = []
    runs, metrics = run_reciprocity(scenarios, tmp_path, running=lambda exc: entered.append(exc) or nullcontext())
    assert entered == ["SSGM:C", "LSGM:3"] and list(runs) == entered
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["fig3_velocities.pdf", "fig3_velocities.png", "shock-LSGM3.nc", "shock-SSGMC.nc"]
    assert run_path(tmp_path, "LSGM:3") == tmp_path / "shock-LSGM3.nc"
    for excited, ds in runs.items():
        np.testing.assert_array_equal(read_netcdf(run_path(tmp_path, excited))["v_x"].values, ds["v_x"].values)
    np.testing.assert_equal(metrics, reciprocity_metrics(runs["SSGM:C"], runs["LSGM:3"]))  # NaN where nothing arrives
    np.testing.assert_equal(metrics, reciprocity_metrics(read_netcdf(tmp_path / "shock-SSGMC.nc"),
                                                         read_netcdf(tmp_path / "shock-LSGM3.nc")))


def test_run_reciprocity_names_the_stopped_run_and_the_failed_write(tmp_path, monkeypatch):
    scenarios = {"SSGM:C": rigid("SSGM:C"), "LSGM:3": rigid("LSGM:3")}
    (tmp_path / "shock-SSGMC.nc").mkdir()
    with pytest.raises(NotWritten) as e:
        run_reciprocity(scenarios, tmp_path)
    assert e.value.what == "the run" and e.value.path == tmp_path / "shock-SSGMC.nc"
    monkeypatch.setattr(R, "run_scenario", stopped)
    with pytest.raises(R.RunStopped, match="^run with the shock on SSGM:C stopped: boom$"):
        run_reciprocity(scenarios, tmp_path)


# ------------------------------------------------------------------------- granel modes


def test_scenario_modes_build_only_the_granules_and_the_solid(tmp_path, monkeypatch):
    from granel.solid.modal import classify_modes, modal_analysis
    from granel.studies.natural_modes import scenario_modes

    sc = S.load("paper", ['solid.kind="beam"'])
    solid = S.build_problem(sc).solid
    reference = modal_analysis(solid, 3)

    def refuse(sc):
        raise AssertionError("the whole problem was built")

    monkeypatch.setattr(S, "build_problem", refuse)
    res = scenario_modes(sc, 3)
    assert res.shown == 3 and res.plot is None and res.solid.ndof == solid.ndof
    np.testing.assert_allclose(res.modes.periods[:3], reference.periods, rtol=1e-9)
    assert res.kinds == classify_modes(solid, reference, range(3)) == ["bending"] * 3
    assert res.summary() == {"solid": "beam", "dofs": solid.ndof, "elements": solid.nelements,
                             "periods_ms": [float(p) for p in res.modes.periods[:3] * 1e3], "kinds": ["bending"] * 3,
                             "modes_computed": res.modes.count}
    drawn = scenario_modes(sc, 2, tmp_path / "fig6.png")  # Fig. 6 draws mode 7: seven are computed
    assert drawn.modes.count >= 7 and len(drawn.kinds) == 7 and drawn.shown == 2
    assert (tmp_path / "fig6.png").stat().st_size > 0 and drawn.summary()["plot"] == str(tmp_path / "fig6.png")


def test_an_unbuildable_solid_is_a_scenario_error_naming_the_solid(monkeypatch):
    import granel.scenario.build as B

    def clamped(recipe):
        raise ValueError("a contact on a clamped node")

    sc = S.load("paper", ['solid.kind="beam"'])
    system, _, _ = S.build_granular(sc, sc.base)
    monkeypatch.setattr(B, "build_solid_model", clamped)
    with pytest.raises(S.ScenarioError, match="^solid: a contact on a clamped node$"):
        S.build_solid(sc, system)
    with pytest.raises(S.ScenarioError, match="^solid: a contact on a clamped node$"):
        S.build_problem(sc)


# ------------------------------------------------------------------------- granel spectrum and sweep


def test_spectrum_sweep_is_a_sweep_in_spectrum_mode_over_frequency_and_amplitude(tmp_path, monkeypatch):
    spec = SS.spectrum_sweep("paper", ['solid.kind="rigid"'], [1e3, 2e3], [10.0], drive="LSGM:3", measure="SSGM:C",
                             both_directions=True, cycles=20.0, window_cycles=5.0, ramp_cycles=2.0,
                             samples_per_period=16)
    assert spec.mode == "spectrum" and spec.overrides == ['solid.kind="rigid"']
    assert (spec.name, spec.base) == ("spectrum of paper", "paper")
    assert [(a.field, a.values) for a in spec.axes] == [(SP.FREQUENCY_FIELD, [1e3, 2e3]), (SP.AMPLITUDE_FIELD, [10.0])]
    assert spec.spectrum.runs() == [("fwd", "LSGM:3", "SSGM:C"), ("bwd", "SSGM:C", "LSGM:3")]
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="window"):
        SS.spectrum_sweep("paper", [], [1e3], [10.0], drive="LSGM:3", measure="SSGM:C", cycles=4.0)
    monkeypatch.chdir(tmp_path)
    spec = SS.spectrum_sweep("mine.toml", [], [1e3], [10.0], drive="LSGM:3", measure="SSGM:C")
    assert (spec.name, spec.base) == ("spectrum of mine", str(tmp_path.resolve() / "mine.toml"))  # by its absolute path


def _written(calls):
    def write(summary, spectrum, path, *chain):  # chain: the runs' linearised chain and why there is none
        calls.append(("write", summary, path))
        raise PermissionError(13, "denied")

    return write


def test_run_spectrum_runs_the_cases_beside_the_spectrum_then_writes_it(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(SW, "run_spec", lambda spec, base, out, *a: calls.append(("run", base, out)) or "summary")
    monkeypatch.setattr(SS, "write_spectrum", _written(calls))
    spec = SS.spectrum_sweep("paper", [], [1e3], [10.0], drive="LSGM:3", measure="SSGM:C")
    path = tmp_path / "sp.nc"
    with pytest.raises(NotWritten) as e:
        SS.run_spectrum(spec, path)
    assert calls == [("run", Path("."), tmp_path / "sp.cases"), ("write", "summary", path)]
    assert SS.cases_folder(path) == tmp_path / "sp.cases"
    assert e.value.what == "the spectrum" and isinstance(e.value.cause, PermissionError)


def test_sweep_study_writes_the_spectrum_of_a_spectrum_sweep_only(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(SW, "run_spec", lambda spec, base_dir, out, *a: calls.append(("run", out)) or "summary")
    monkeypatch.setattr(SR, "write_spectrum", _written(calls))  # spectrum mode writes it (`StudyMode.finish_sweep`)
    plain = SW.SweepSpec.model_validate({"base": "paper", "axes": [{"field": "contact.mu", "values": [0.1]}]})
    assert SW.sweep_study(plain, tmp_path, tmp_path / "out") == "summary" and calls == [("run", tmp_path / "out")]
    calls.clear()
    spec = SS.spectrum_sweep("paper", [], [1e3], [10.0], drive="LSGM:3", measure="SSGM:C")
    with pytest.raises(NotWritten) as e:
        SW.sweep_study(spec, tmp_path, tmp_path / "out")
    assert calls == [("run", tmp_path / "out"), ("write", "summary", tmp_path / "out" / "spectrum.nc")]
    assert e.value.path == tmp_path / "out" / "spectrum.nc"


# ------------------------------------------------------------------------- granel design


def test_design_study_reports_after_the_trials(tmp_path, monkeypatch):
    import granel.studies.design_report as DR
    import granel.studies.design_search as D

    calls = []

    def run_design(spec, base_dir, out, trials=None, options=None, check=True):  # a study stopped early: no `finishing`
        calls.append(("trials", trials, options.workers, options.scheduler, options.max_wall, check))
        options.progress(0, "ok", 1, 1)
        options.confirming(1, 1)
        return {"study": "study", "files": ["trials.nc"]}

    def write_study_report(spec, base_dir, study, out, rows=None):
        calls.append(("report", study, rows))
        return ["report.md"]

    monkeypatch.setattr(D, "run_design", run_design)
    monkeypatch.setattr(DR, "write_study_report", write_study_report)
    options = D.DesignRunOptions(1, None, max_wall=9.0, progress=lambda *a: calls.append(("progress", a)),
                                 confirming=lambda *a: calls.append(("confirm", a)))
    res = DR.design_study("spec", tmp_path, tmp_path / "out", 3, options, reporting=lambda: calls.append("reporting"))
    assert calls == [("trials", 3, 1, None, 9.0, False), ("progress", (0, "ok", 1, 1)), ("confirm", (1, 1)), "reporting",
                     ("report", "study", None)]
    assert res["files"] == ["trials.nc", "report.md"]


@pytest.mark.parametrize("before", ["new", "empty", "written"])
def test_a_refused_command_leaves_no_folder_it_made(tmp_path, before):
    out = tmp_path / "out"
    if before != "new":
        out.mkdir()
    if before == "written":
        (out / "trials.nc").write_text("x")
    with pytest.raises(GranelError), removed_if_refused(out):
        plan = OutputPlan()
        plan.folder(out, "--out", "design", recognise=lambda p: True)
        plan.check().prepare()
        raise GranelError("refused")
    assert out.exists() == (before != "new")


@pytest.mark.parametrize("how", ["wrote", "crashed"])
def test_a_folder_is_removed_only_empty_and_only_on_a_refusal(tmp_path, how):
    out = tmp_path / "out"
    with pytest.raises(GranelError if how == "wrote" else RuntimeError), removed_if_refused(out):
        plan = OutputPlan()
        plan.folder(out, "--out", "design")
        plan.check().prepare()
        if how == "wrote":
            (out / "trials.nc").write_text("x")
            raise GranelError("refused")
        raise RuntimeError("not a refusal")
    assert (out / STAMP).exists()


# ------------------------------------------------------------------------- granel paper, bench, export


def test_paper_run_count_is_what_the_study_reports():
    from granel.studies.paper import CASES, run_count

    lsgm = [c for c in CASES if c[1] == "LSGM:3"]
    assert run_count(False) == len(CASES) == 12 and run_count(True) == 2 * len(CASES) + len(lsgm) == 30


def test_bench_check_duration_refuses_what_the_cases_cannot_run():
    from granel.studies.benchmark import check_duration

    check_duration("2us")
    with pytest.raises(InputError, match="output intervals"):
        check_duration("0.0123456789ms")
    with pytest.raises(InputError, match="memory"):
        check_duration("100s")


def test_bench_runs_the_chain_on_a_plate_beside_the_papers_cases():
    """`granel bench --cases chain-on-plate --reference` for 0.2 ms: the chain on the plate in
    bending by the three methods, their deviations from the paper's algorithm and their errors
    against Newmark at 2.5 ns (energies over the input, the struck bead's velocity, the balance
    (13)) within what each integrator promises: the exact one its rtol, 1e-5 (measured 1.2e-6);
    the fixed 40 ns steps (paper, Newmark) the second-order phase error (w dt)^2 / 12 = 1.3e-5 of
    a 20 us Hertz collision (measured 1.5e-9: the solid's excited modes are slow)."""
    from granel.studies.benchmark import bench_rows, check_bench_options, run_bench

    only = check_bench_options("chain-on-plate", "0.2ms")
    res = run_bench(quick=True, only=only, duration="0.2ms", reference=True, fresh=False, log=lambda s: None)
    assert res["cases"] == [] and [r["tag"] for r in res["scenario_cases"]] == ["chain-on-plate"]
    row = res["scenario_cases"][0]
    assert row["exact_steps"] > 0 and row["paper_s"] > 0 and row["exact_ratio"] == row["paper_s"] / row["exact_s"]
    phase = (2 * math.pi * 40e-9 / 20e-6) ** 2 / 12
    for method, e in row["reference"].items():
        tol = 1e-5 if method == "exact" else phase
        assert e["energy"] < tol and e["v_excited"] < tol and e["balance"] < tol, (method, e)
    assert bench_rows(res)[1][0][0] == "chain-on-plate"
    with pytest.raises(InputError, match="no case 'chain-on-cord'"):
        check_bench_options("chain-on-cord", None)


def test_export_reports_its_progress_to_the_total(tmp_path):
    from granel.analysis.result_model import result_solid
    from granel.viz.export import count_steps, export_result

    ds = R.load_result(R.run_to_file(rigid("SSGM:C"), tmp_path / "r.nc")["output"])
    seen = []
    export_result(ds, tmp_path / "exp", ["csv", "extxyz"], lambda done, total: seen.append((done, total)))
    total = count_steps(ds, result_solid(ds), ["csv", "extxyz"])
    assert seen == [(k, total) for k in range(total + 1)]
