"""The claims table's honesty (issue 28): statements that hold by construction are marked so, with
a reason, and agreement is counted only over the statements that could have failed; the paper's
ambiguous outer walls are shown as a table of the verdicts that flip. Synthetic measurements and
small claim lists: nothing here runs the twelve cases."""

import copy
import json
import math

import numpy as np
import pytest
import xarray as xr

from granel.studies import claims as C
from granel.studies.claims import Claim, claims, construction_facts, summary_line, tally, verdict_flips

BALANCE = "the energies plus the dissipated work sum to the input at every instant (all twelve cases)"
AXIAL = "the antisymmetric axial mode 4 is not excited by the symmetric shocks (plate, six cases)"
EIGEN = "the friction eigenvalues stay below unity (paper's algorithm, strong shock on the SSGM, plate)"
BY_CONSTRUCTION = {BALANCE, AXIAL, EIGEN}


def fake_case(solid, side, shock) -> dict:
    """Plausible numbers of one run, every key the claims read."""
    lsgm = side == "LSGM3"
    k = C.SHOCKS.index(shock)
    acc = np.minimum(1.0, np.linspace(0.8, 1.2, 3000))
    return {"solid_arrival_ms": (0.2, 0.14, 0.1)[k] if lsgm else 0.03, "solid_peak_frac": 0.2,
            "solid_peak_time_ms": 0.2 if lsgm else 0.05, "solid_peak_width_ms": 0.16 if lsgm else 0.03,
            "ssgm_peak_time_ms": 0.2 if lsgm else 0.05, "lsgm_peak_time_ms": 0.3, "far_peak_frac": 0.3,
            "dissipated_frac": (0.1, 0.2, 0.3)[k] + (0 if lsgm else 0.4), "dissipation_half_time_ms": 0.3 if lsgm else 0.2,
            "max_balance_error_rel": 4e-7, "potential_over_kinetic_at_peak": 50.0, "potential_dominance": 0.97,
            "potential_dominance_after_peak": 0.5, "accumulation": acc, "modes_90": (3, 40, 100)[k] * (1 if lsgm else 3),
            "modes_99": 2000, "mode_shares": np.array([0.5, 1e-20, 0.1, 1e-19, 0.05, 0.01, 0.01]),
            "at_peak_accumulation": {6: 0.5 if lsgm else 0.1, 100: 0.75 if lsgm else 0.6, 1000: 0.99 if lsgm else 0.85},
            "spectral_centroid_khz": 10.0,
            "construction": {"balance_bound_rel": 8.1e-7, "ledger_tol": 8e-7, "mirror_symmetric": True}}


def fake_measurements() -> dict:
    m = {"cases": {f"{s}-{e}-{k}": fake_case(s, e, k) for s in C.SOLIDS for e in ("LSGM3", "SSGMC") for k in C.SHOCKS}}
    # modal accumulation: the LSGM side gathers faster, more so with the level (the nonreciprocity claim)
    for k, g in zip(C.SHOCKS, (0.05, 0.1, 0.15)):
        m["cases"][f"plate-SSGMC-{k}"]["accumulation"] = m["cases"][f"plate-SSGMC-{k}"]["accumulation"] - g
    fig3 = {"v_3C_arrival_ms": 0.09, "v_C3_arrival_ms": 0.12}
    for key in ("0.4-0.8", "0.6-0.8"):
        fig3 |= {f"zc_3C_khz_{key}": 5.0, f"zc_C3_khz_{key}": 11.0, f"dom_3C_khz_{key}": 4.5, f"dom_C3_khz_{key}": 9.5}
    m["fig3"] = {"plate-strong": fig3}
    m["beam_vs_plate"] = {f"{e}-{k}": (2.0 if e == "LSGM3" else 8.0) + i for e in ("LSGM3", "SSGMC") for i, k in enumerate(C.SHOCKS)}
    m["modes"] = {"periods_ms": [0.2044, 0.08, 0.045, 0.0395, 0.03, 0.022, 0.01984],
                  "kinds": ["bending"] * 3 + ["axial"] + ["bending"] * 2 + ["bulk"]}
    m["fig11"] = {"max_lambda": {"LSGM:10": 0.3, "SSGM:J": 0.5}, "min_step": 1.56e-10, "steps": 1000, "window_ms": 0.2,
                  "solver": "paper", "lambda_cap": 0.5, "source": "synthetic"}
    return m


def by_claim(rows):
    return {c.claim: c for c in rows}


# ---------------------------------------------------------------- the classification


def test_by_construction_statements_have_a_reason_and_are_not_counted():
    rows = claims(fake_measurements())
    assert len(rows) == 42
    held = [c for c in rows if c.by_construction]
    assert {c.claim for c in held} == BY_CONSTRUCTION
    for c in held:
        assert c.verdict == "by construction" and c.agree
        assert len(c.construction) > 40  # a reason, printed in the report
        row = c.row()
        assert row["verdict"] == "by construction" and row["checked"] is False and row["construction"] == c.construction
    # every other statement could have failed, and says nothing of construction
    assert all(c.checked and not c.construction for c in rows if c.claim not in BY_CONSTRUCTION)
    t = tally(rows)
    agree = sum(c.verdict == "agree" for c in rows)
    assert t == {"total": 42, "checked": 39, "agree": agree, "differ": 39 - agree, "by_construction": 3}
    assert agree == sum(c.agree for c in rows) - 3  # the three held statements are not counted as agreement
    assert summary_line(rows) == f"{agree} of 39 checked statements agree; 3 hold by construction"
    # the same counts from the rows `granel paper` returns and the cli prints
    assert tally([c.row() for c in rows]) == t and summary_line([c.row() for c in rows]) == summary_line(rows)


def test_the_classification_is_read_from_the_runs():
    """Without the guarantee (a solver that enforces no balance bound, a load off the axis, a
    step rule that does not cap lambda), the same statement is checked against data."""
    m = fake_measurements()
    for case in m["cases"].values():
        case["construction"]["balance_bound_rel"] = math.nan  # e.g. --solver paper: Newmark and a fixed point
    m["cases"]["plate-LSGM3-weak"]["construction"]["mirror_symmetric"] = False
    m["fig11"]["lambda_cap"] = math.nan
    rows = by_claim(claims(m))
    for name in BY_CONSTRUCTION:
        assert rows[name].checked and rows[name].verdict == "agree" and not rows[name].construction
    assert tally(rows.values())["by_construction"] == 0
    # a bound looser than the rule's does not make the statement hold by construction either
    m = fake_measurements()
    m["cases"]["beam-SSGMC-strong"]["construction"]["balance_bound_rel"] = 2e-3
    assert by_claim(claims(m))[BALANCE].checked


def test_a_statement_expected_by_construction_that_fails_is_counted_as_differ():
    m = fake_measurements()
    m["cases"]["plate-SSGMC-strong"]["max_balance_error_rel"] = 5e-3  # the bound did not hold: a bug, not physics
    m["cases"]["plate-SSGMC-strong"]["mode_shares"][3] = 1e-3
    rows = by_claim(claims(m))
    for name in (BALANCE, AXIAL):
        assert rows[name].verdict == "differ" and rows[name].checked and rows[name].construction
    assert tally(rows.values())["checked"] == 41 and tally(rows.values())["by_construction"] == 1
    assert summary_line(rows.values()).endswith("; 1 holds by construction")


def test_construction_facts_of_the_paper_scenario():
    """The symmetry and the solver's bound read from a result's scenario and model record: the
    paper's shocks on granules 3 and C are on the axis, with or without the outer walls; granule
    2 is not."""
    from granel import scenario as S
    from granel.io.model import model_record, with_record
    from granel.io.results import wall_names
    from granel.studies.paper import FREE_EDGE, case_scenario

    def ds_of(sc, solver="fast"):
        """A result of `sc` at rest, as far as the facts read it."""
        problem = S.build_problem(sc)
        system = problem.system
        t, zero = np.linspace(0, 1e-4, 5), np.zeros((5, system.n))
        attrs = {"scenario": S.to_toml(sc), "solver_name": solver, "solver_integrator": "exact", "solver_adaptive": 1,
                 "solver_ledger_tol": sc.simulation.ledger_tol}
        ds = xr.Dataset({"input_work": ("time", np.linspace(0, 1e-3, 5)), "v_x": (("time", "granule"), zero),
                         "v_y": (("time", "granule"), zero), "omega": (("time", "granule"), zero),
                         "medium": ("granule", np.array([system.media[k] for k in system.medium_index], object))},
                        coords={"time": t, "granule": list(system.labels), "wall": wall_names(system),
                                "contact": [c.name for c in problem.solid.contacts]}, attrs=attrs)
        return with_record(ds, model_record(system, problem.solid))

    f = construction_facts(ds_of(case_scenario(("plate", "LSGM:3", "strong"))))
    assert f["mirror_symmetric"] and f["ledger_tol"] == 8e-7 and 8e-7 <= f["balance_bound_rel"] < 1e-3
    assert construction_facts(ds_of(case_scenario(("beam", "SSGM:C", "weak"), extra=FREE_EDGE)))["mirror_symmetric"]
    assert not construction_facts(ds_of(case_scenario(("plate", "LSGM:2", "strong"))))["mirror_symmetric"]
    assert math.isnan(construction_facts(ds_of(case_scenario(("plate", "LSGM:3", "strong"), "paper"), "paper"))["balance_bound_rel"])
    assert not construction_facts(xr.Dataset({"input_work": ("time", np.ones(2))}))["mirror_symmetric"]  # no scenario: no guarantee


# ---------------------------------------------------------------- the variant table


def small(claim, agree, value, construction=""):
    return Claim("Fig. X", claim, "paper", value, "rule", agree, construction)


def test_verdict_flips_of_two_small_lists():
    walled = [small("a", True, "1.0"), small("b", False, "2.0"), small("c", True, "3e-19", "symmetry"), small("d", True, "4.0"),
              small("e", True, "5.0")]
    free = [small("d", True, "4.1"), small("c", True, "1e-20", "symmetry"), small("b", True, "2.5"), small("a", False, "0.5")]
    flips = verdict_flips(walled, free)  # matched by statement, not by position
    assert [(f.number, f.claim, f.base_verdict, f.variant_verdict, f.base_value, f.variant_value) for f in flips] == [
        (1, "a", "agree", "differ", "1.0", "0.5"), (2, "b", "differ", "agree", "2.0", "2.5"),
        (5, "e", "agree", "not checked", "5.0", "")]
    assert verdict_flips([c.row() for c in walled], [c.row() for c in free]) == flips
    assert verdict_flips(walled, walled) == []


def test_report_shows_the_held_statements_and_the_variant_table(tmp_path):
    from granel.studies.paper import write_report

    m = fake_measurements()
    free = copy.deepcopy(m)
    free["cases"]["plate-LSGM3-strong"] |= {"solid_peak_time_ms": 0.29, "ssgm_peak_time_ms": 0.29}  # Fig. 5's left peak: agree -> differ
    free["beam_vs_plate"]["SSGMC-strong"] = 1.0  # no longer the largest disparity: agree -> differ
    free["cases"]["plate-LSGM3-weak"]["construction"]["mirror_symmetric"] = False  # the axial claim becomes checked
    path = write_report(tmp_path, m, {}, [], 1.0, "fast", free, free)  # the same variant for both sections
    text = path.read_text()
    rows = claims(m)
    assert f"**{summary_line(rows)}.**" in text
    assert "\\|lambda\\|" in text and " |lambda| " not in text  # a '|' inside a cell is escaped
    for c in rows:
        if c.by_construction:
            assert f"| **by construction**: {c.construction.replace('|', chr(92) + '|')} |" in text
    section = text[text.index("## The paper's ambiguity"):text.index("## The twelve cases")]
    table = [line for line in section.splitlines() if line.startswith("| ") and line[2].isdigit()]
    flips = verdict_flips(rows, claims(free))
    assert len(table) == len(flips) == 3
    n5 = next(k for k, c in enumerate(rows, 1) if c.claim.startswith("the plate's energy peaks at tau = 0.2 ms"))
    assert f"| {n5} | Fig. 5 | the plate's energy peaks at tau = 0.2 ms, strong shock from the left | **agree** | **differ** | 0.200 ms | 0.290 ms |" in table
    assert any(f"| {AXIAL} | **by construction** | **agree** |" in line for line in table)
    assert "3 of 42 verdicts flip without the SSGM's outer wall: 1 to agree, 2 to differ." in section
    # the full comparison keeps a row per statement
    full = text[text.index("## What the outer walls change"):text.index("## Errata")]
    assert sum(line.startswith("| ") and line[2].isdigit() for line in full.splitlines()) == 42
    dump = json.loads((tmp_path / "measurements.json").read_text())
    assert dump["summary"]["checked"] == 39 and dump["summary"]["line"] == summary_line(rows)
    assert len(dump["free_edge"]["flips"]) == 3 and dump["free_edge"]["summary"]["by_construction"] == 2
    assert len(dump["no_ssgm_outer_wall"]["flips"]) == 3
    assert [c["verdict"] for c in dump["claims"]].count("by construction") == 3


@pytest.mark.parametrize("verdicts", [("agree", "by construction"), ("differ", "agree")])
def test_summary_line_counts_rows(verdicts):
    rows = [{"verdict": v, "where": "w", "claim": str(k)} for k, v in enumerate(verdicts)]
    t = tally(rows)
    assert t["checked"] + t["by_construction"] == 2 and t["agree"] == verdicts.count("agree")
