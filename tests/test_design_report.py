"""The design report's modal accounting (design_report.modal_accounting): each mode's share of the
time-integrated solid energy (eqs. 15-16), checked against the run's own solid energy."""

import numpy as np
import pytest

from granel import scenario as S
from granel.studies.design_report import modal_accounting, modal_lines
from granel.run import run_scenario


@pytest.fixture(scope="module")
def beam_run():
    sc = S.load("paper", ['solid.kind="beam"', 'excitations.0.granule="SSGM:C"', 'excitations.0.shock="strong"',
                          "simulation.duration=1e-4"])
    return run_scenario(sc)


def test_modal_shares_add_up_to_the_solid_energy(beam_run):
    ds = beam_run
    acc = modal_accounting(ds, top=4)
    t = ds["solid_time"].values
    # the modal energies (15) of every mode sum to the solid's energy at each output
    solid = np.interp(t, ds["time"].values, ds["energy_solid"].values)
    w = float(np.abs(ds["input_work"].values).max())
    integral = np.trapezoid(solid, t)
    assert acc["shares"].sum() == pytest.approx(1.0, abs=1e-12)
    assert acc["solid_mean"] == pytest.approx(integral / (t[-1] - t[0]) / w, rel=1e-6)
    assert acc["solid_peak"] == pytest.approx(solid.max() / w, rel=1e-6)
    top = acc["top"]
    assert [s for *_, s in top] == sorted((s for *_, s in top), reverse=True)
    assert top[0][3] == pytest.approx(acc["shares"].max())
    assert all(k == "bending" for _, _, k, _ in top)  # every beam mode bends
    n, f, _, s = top[0]
    assert f == pytest.approx(acc["frequency_Hz"][n - 1]) and s == pytest.approx(acc["shares"][n - 1])
    # the modes holding 90 %: the smallest N whose first N modes (in order) reach 0.9
    cum = np.cumsum(acc["shares"])
    assert cum[acc["modes_90"] - 1] >= 0.9 > (cum[acc["modes_90"] - 2] if acc["modes_90"] > 1 else 0.0)
    lines = modal_lines([("base", "shock", acc)])
    assert any(line.startswith("| base | shock |") for line in lines)


def test_no_accounting_without_modes():
    sc = S.load("paper", ['solid.kind="rigid"', "simulation.duration=2e-5"])
    assert modal_accounting(run_scenario(sc)) is None
