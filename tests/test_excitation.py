"""Load histories, and the work they do on a free granule (impulse-momentum theorem)."""

import math

import numpy as np
import pytest

from granel.excitation import half_sine, harmonic_burst, read_force_csv, tabulated, SHOCK_LEVELS
from granel.granular.system import Excitation, Stepper, initial_state

from conftest import make_system


def test_shock_levels_are_the_papers():
    assert SHOCK_LEVELS == {"weak": 63.67, "moderate": 318.3, "strong": 1591.6}


def test_half_sine_shape_and_impulse():
    h = half_sine(1591.6, 1e-5)
    assert h(0.5e-5) == pytest.approx(1591.6)
    assert h(-1e-9) == 0 and h(1.01e-5) == 0
    t = np.linspace(0, 1e-5, 20001)
    assert np.trapezoid([h(x) for x in t], t) == pytest.approx(h.impulse(), rel=1e-7)
    assert h.impulse() == pytest.approx(2 * 1591.6 * 1e-5 / math.pi)


def test_burst_and_table(tmp_path):
    b = harmonic_burst(10.0, 1e4, 3, t0=1e-5)
    assert b(1e-5 + 0.25e-4) == pytest.approx(10.0)
    assert b(1e-5 + 3.01e-4) == 0.0
    (tmp_path / "f.csv").write_text("time,force\n0,0\n1e-5,100\n2e-5,0\n")
    tab = read_force_csv(tmp_path / "f.csv")
    assert tab(0.5e-5) == pytest.approx(50.0)
    assert tab.impulse() == pytest.approx(1e-3)
    (tmp_path / "bad.csv").write_text("time,force\n0,0\n0,1\n")
    with pytest.raises(ValueError, match="increase"):
        read_force_csv(tmp_path / "bad.csv")


@pytest.mark.parametrize("hist", [half_sine(1591.6, 1e-5), harmonic_burst(50.0, 2e5, 1.5), tabulated([0, 1e-5, 3e-5], [0, 80.0, 0])])
def test_free_granule_gains_impulse_over_mass(hist):
    """F(t) on a lone granule: v = J/m and the input work equals J^2 / (2 m)."""
    system = make_system([("a", 0.0, 0.0, 0.005)], excitations=[Excitation(0, (0.6, 0.8), hist)])
    state = initial_state(system)
    Stepper(system).advance(state, 1e-8, 5000)
    m = system.mass[0]
    J = hist.impulse()
    assert np.hypot(*state.vel[0]) == pytest.approx(J / m, rel=1e-9)
    assert state.vel[0, 1] / state.vel[0, 0] == pytest.approx(0.8 / 0.6)
    assert state.input_work == pytest.approx(J**2 / (2 * m), rel=1e-9)
