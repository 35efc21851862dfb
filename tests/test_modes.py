"""Study modes (`studies.modes`): the runs each mode makes for a case, the metrics it declares
and reports, the fingerprint of its cases (the one stored cases were written with), a design
trial's cases, and the registry's refusal of an unknown mode."""

import hashlib
import json
import math
from pathlib import Path

import pytest

from granel import __version__
from granel import scenario as S
from granel.studies.design import DesignSpec
from granel.studies.modes import MODES, StudyMode, study_mode
from granel.studies.sweep import (METRIC_RULES, CaseSpec, SweepSpec, case_fingerprint, case_scenarios, cases,
                                  check_mode, load_sweep, run_case)

CHAIN = Path(__file__).resolve().parents[1] / "scenarios" / "narrowband" / "precompressed-chain.toml"
RIGID = ['solid.kind="rigid"', 'simulation.duration="0.005ms"']
SPECTRUM = {"drive": "C:1", "measure": "C:20", "cycles": 20, "window_cycles": 5}


def spectrum_spec(both=True, frequencies=(8000.0,)):
    return SweepSpec.model_validate({"base": str(CHAIN), "mode": "spectrum", "spectrum": {**SPECTRUM, "both_directions": both},
                                     "axes": [{"field": "excitations.0.frequency", "values": list(frequencies)}]})


def reciprocity_spec():
    return SweepSpec.model_validate({"base": "paper", "overrides": RIGID, "mode": "reciprocity",
                                     "axes": [{"field": "contact.mu", "values": [0.2]}]})


def run_spec():
    return SweepSpec.model_validate({"base": "paper", "overrides": RIGID, "mode": "run",
                                     "axes": [{"field": "contact.mu", "values": [0.2]}]})


# ---------------------------------------------------------------- the registry


def test_the_registry_names_the_three_modes_and_refuses_another(tmp_path):
    assert list(MODES) == ["reciprocity", "run", "spectrum"]
    assert all(isinstance(m, StudyMode) and m.name == k for k, m in MODES.items())
    with pytest.raises(ValueError, match=r"^mode = 'sweepy': not a study mode; choose from 'reciprocity', 'run', 'spectrum'$"):
        study_mode("sweepy")
    path = tmp_path / "s.toml"
    path.write_text('mode = "sweepy"\n[[axes]]\nfield = "contact.mu"\nvalues = [0.1]\n')
    with pytest.raises(S.ScenarioError) as e:
        load_sweep(path)
    assert str(e.value) == (f"invalid sweep {path}: mode = 'sweepy': Input should be 'reciprocity', 'run' or "
                            "'spectrum'")


def test_a_mode_must_implement_the_interface():
    class Half(StudyMode):
        name = "half"

        def scenarios(self, spec, base, overrides, values, check_usage=True):
            return []

    with pytest.raises(TypeError, match="measure"):
        Half()


# ---------------------------------------------------------------- each mode's runs


def test_run_mode_runs_the_scenario_once_with_the_case_values():
    spec = run_spec()
    [(key, sc)] = case_scenarios(spec, Path("."), cases(spec)[0])
    assert key == "run"
    assert sc.contact.mu == 0.2 and sc.excitations[0].granule == S.load("paper").excitations[0].granule
    assert sc.simulation.duration == pytest.approx(5e-6)


def test_reciprocity_mode_shocks_each_granule_of_the_pair_forward_first():
    spec = reciprocity_spec()
    runs = case_scenarios(spec, Path("."), cases(spec)[0])
    assert [k for k, _ in runs] == ["shock-SSGMC", "shock-LSGM3"]
    assert [sc.excitations[0].granule for _, sc in runs] == ["SSGM:C", "LSGM:3"]
    assert all(sc.contact.mu == 0.2 for _, sc in runs)


@pytest.mark.parametrize("both, keys", [(True, ["fwd", "bwd"]), (False, ["fwd"])])
def test_spectrum_mode_drives_each_end_at_the_case_frequency(both, keys):
    spec = spectrum_spec(both)
    runs = case_scenarios(spec, Path("."), cases(spec)[0])
    assert [k for k, _ in runs] == keys
    assert [sc.excitations[0].granule for _, sc in runs] == ["C:1", "C:20"][: len(keys)]
    for _, sc in runs:
        e = sc.excitations[0]
        assert (e.kind, e.frequency, e.ramp_cycles) == ("harmonic", 8000.0, 5.0)
        assert sc.simulation.duration == pytest.approx(20 / 8000.0, rel=1e-12)  # cycles / f
        assert sc.simulation.output_every == pytest.approx(1 / (8000.0 * 24), rel=1e-12)


def test_spectrum_mode_refuses_a_frequency_that_is_not_positive_naming_the_field():
    spec = spectrum_spec()
    with pytest.raises(S.ScenarioError, match=r"excitations.0.frequency: a drive frequency must be positive, got -5.0"):
        case_scenarios(spec, Path("."), {"index": [0], "overrides": {"excitations.0.frequency": -5.0}, "tag": "t"})


def test_only_the_spectrum_mode_checks_its_settings_before_running():
    for spec in (run_spec(), reciprocity_spec(), spectrum_spec()):
        assert check_mode(spec, Path("."), cases(spec)[0]) is None
    bad = spectrum_spec().model_copy(update={"spectrum": spectrum_spec().spectrum.model_copy(update={"drive": "C:99"})})
    with pytest.raises(S.ScenarioError, match=r"^spectrum.drive = 'C:99': no such granule in "):
        check_mode(bad, Path("."), cases(bad)[0])


# ---------------------------------------------------------------- metric names and units


def test_each_mode_declares_its_metrics_with_units():
    run = study_mode("run").metric_units(run_spec())
    assert len(run) == 15 and run["cutoff_Hz"] == "Hz" and run["input_work_J"] == "J"
    assert run["peak_wall_force_N"] == "N" and run["granular_mass_kg"] == "kg" and run["footprint_m2"] == "m^2"
    rec = study_mode("reciprocity").metric_units(reciprocity_spec())
    assert len(rec) == 21 and rec["nonreciprocity_index"] == "1" and rec["arrival_bwd_s"] == "s"
    assert {"peak_contact_force_fwd_N", "peak_contact_force_bwd_N", "peak_wall_force_fwd_N", "peak_wall_force_bwd_N"} < set(rec)
    both = study_mode("spectrum").metric_units(spectrum_spec(True))
    assert len(both) == 2 * 13 + 1 + 2 + 6 and both["mobility_bwd"] == "m/(N s)" and both["nonreciprocity_db"] == "dB"
    one = study_mode("spectrum").metric_units(spectrum_spec(False))
    assert len(one) == 13 + 2 + 3 and "peak_wall_force_N" in one and "nonreciprocity_db" not in one


@pytest.mark.parametrize("make", [reciprocity_spec, lambda: spectrum_spec(True, (22000.0,))], ids=["reciprocity", "spectrum"])
def test_a_case_reports_exactly_the_declared_metrics(tmp_path, make):
    spec = make()
    r = run_case(spec.model_dump_json(), ".", cases(spec)[0], str(tmp_path), keep_runs=False)
    assert r["status"] == "ok", r
    assert set(r["metrics"]) == set(study_mode(spec.mode).metric_units(spec)) and len(r["metrics"]) in (21, 35)
    assert all(math.isfinite(v) for k, v in r["metrics"].items() if k.startswith("peak_") or k.startswith("mobility"))


# ---------------------------------------------------------------- fingerprints


def stored_fingerprint(spec, scenarios, case):
    """The fingerprint stored cases carry: this payload, hashed as it always was."""
    payload = {"granel_version": __version__, "metric_rules": METRIC_RULES, "mode": spec.mode, "pair": list(spec.pair),
               "spectrum": spec.spectrum.model_dump() if spec.spectrum is not None else None,
               "sweep_overrides": list(spec.overrides), "case_overrides": case["overrides"],
               "scenarios": {key: S.to_toml(sc) for key, sc in scenarios},
               "inputs": {key: S.input_digests(sc) for key, sc in scenarios if S.input_digests(sc)}}
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()


@pytest.mark.parametrize("make", [run_spec, reciprocity_spec, spectrum_spec], ids=["run", "reciprocity", "spectrum"])
def test_a_case_stored_with_its_fingerprint_is_reused_without_running(tmp_path, make):
    spec = make()
    case = cases(spec)[0]
    scenarios = case_scenarios(spec, Path("."), case)
    fp = stored_fingerprint(spec, scenarios, case)
    assert case_fingerprint(spec, scenarios, case) == fp
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / f"{case['tag']}.json").write_text(json.dumps(
        {"tag": case["tag"], "index": [0], "overrides": case["overrides"], "fingerprint": fp, "status": "ok",
         "metrics": {"stored": 1.25}, "wall_s": 3.5}))
    r = run_case(spec.model_dump_json(), ".", case, str(tmp_path))
    assert r["metrics"] == {"stored": 1.25} and r["wall_s"] == 3.5
    assert not list((tmp_path / "cases").glob("*.nc"))  # nothing ran


# ---------------------------------------------------------------- design trials


def design_spec(mode, **extra):
    base = {"base": str(CHAIN), "mode": mode, "pair": ["C:1", "C:20"],
            "variables": [{"field": "excitations.0.amplitude", "low": 0.05, "high": 0.5}],
            "objectives": [{"metric": "peak_wall_force_N" if mode == "run" else "nonreciprocity_db",
                            "direction": "minimize"}]}
    return DesignSpec.model_validate({**base, **extra})


def test_a_trial_is_one_case_or_a_spectrum_band():
    case = {"index": [7], "overrides": {"excitations.0.amplitude": 0.1}, "tag": "trial-abc"}
    run = design_spec("run")
    assert study_mode("run").trial_cases(run, case) == [(case, "")]
    assert study_mode("run").trial_metric_units(run) == study_mode("run").metric_units(run)
    band = design_spec("spectrum", spectrum=SPECTRUM, frequencies=[8000.0, 9500.0])
    parts = study_mode("spectrum").trial_cases(band, case)
    assert [(c["tag"], c["index"], c["overrides"]["excitations.0.frequency"], w) for c, w in parts] == [
        ("trial-abc-f000", [7, 0], 8000.0, "at 8000 Hz"), ("trial-abc-f001", [7, 1], 9500.0, "at 9500 Hz")]
    assert all(c["overrides"]["excitations.0.amplitude"] == 0.1 for c, _ in parts)


def test_a_band_combines_its_frequencies_metrics():
    band = design_spec("spectrum", spectrum=SPECTRUM, frequencies=[8000.0, 9500.0])
    per = [{"mobility_fwd": 1e-3, "mobility_bwd": 1e-4, "transmissibility_fwd": 0.1, "transmissibility_bwd": 1.0,
            "steady_fwd": 1.0, "steady_bwd": 0.0, "balance_fwd": 1e-7, "balance_bwd": 2e-7, "nonreciprocity_db": 20.0,
            "granular_mass_kg": 0.08, "footprint_m2": 1e-3, "peak_wall_force_fwd_N": 3.0, "peak_wall_force_bwd_N": 1.0,
            "peak_contact_force_fwd_N": 5.0, "peak_contact_force_bwd_N": 6.0, "peak_solid_force_fwd_N": 0.0,
            "peak_solid_force_bwd_N": 0.0},
           {"mobility_fwd": 1e-2, "mobility_bwd": 1e-2, "transmissibility_fwd": 1.0, "transmissibility_bwd": 1.0,
            "steady_fwd": 1.0, "steady_bwd": 1.0, "balance_fwd": 3e-7, "balance_bwd": 1e-7, "nonreciprocity_db": 0.0,
            "granular_mass_kg": 0.08, "footprint_m2": 1e-3, "peak_wall_force_fwd_N": 2.0, "peak_wall_force_bwd_N": 4.0,
            "peak_contact_force_fwd_N": 7.0, "peak_contact_force_bwd_N": 6.0, "peak_solid_force_fwd_N": 0.0,
            "peak_solid_force_bwd_N": 0.0}]
    m = study_mode("spectrum").trial_metrics(band, per)
    assert m["mobility_fwd_db"] == pytest.approx(-50.0) and m["mobility_fwd_db_max"] == pytest.approx(-40.0)
    assert m["mobility_bwd_db"] == pytest.approx(-60.0) and m["transmissibility_fwd_db"] == pytest.approx(-10.0)
    assert m["steady_share_bwd"] == 0.5 and m["balance_fwd"] == 3e-7
    assert (m["nonreciprocity_db"], m["nonreciprocity_db_min"], m["nonreciprocity_db_max"]) == (10.0, 0.0, 20.0)
    assert (m["peak_wall_force_fwd_N"], m["peak_wall_force_bwd_N"], m["granular_mass_kg"]) == (3.0, 4.0, 0.08)
    assert m["peak_contact_force_fwd_N"] == 7.0 and m["footprint_m2"] == 1e-3
    assert set(m) == set(study_mode("spectrum").trial_metric_units(band)) and len(m) == 23
