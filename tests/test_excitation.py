"""Load histories, and the work they do on a free granule (impulse-momentum theorem)."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from granel.granular.loads import PAPER_TAU, SHOCK_LEVELS, half_sine, harmonic_burst, tabulated
from granel.scenario.tables import read_load_table as read_force_csv
from granel.granular.system import Excitation, Stepper, initial_state

from conftest import make_system


def test_shock_levels_are_the_papers():
    """Transcribed from the paper (Sec. III and Fig. 9): Fmax = 63.67, 318.3, 1591.6 N, half-sine
    pulses of 0.01 ms; the levels step by five (to the paper's rounding)."""
    assert SHOCK_LEVELS == {"weak": 63.67, "moderate": 318.3, "strong": 1591.6}
    assert PAPER_TAU == 0.01e-3
    assert SHOCK_LEVELS["moderate"] / SHOCK_LEVELS["weak"] == pytest.approx(5, rel=2e-4)
    assert SHOCK_LEVELS["strong"] / SHOCK_LEVELS["moderate"] == pytest.approx(5, rel=2e-4)


def test_half_sine_shape_and_impulse():
    h = half_sine(1591.6, 1e-5)
    assert h(0.5e-5) == pytest.approx(1591.6)
    assert h(-1e-9) == 0 and h(1.01e-5) == 0
    assert h(0.25e-5) == pytest.approx(1591.6 * math.sqrt(0.5), rel=1e-14)
    J, _ = quad(h, 0, 1e-5, epsabs=0, epsrel=1e-13)
    assert J == pytest.approx(2 * 1591.6 * 1e-5 / math.pi, rel=1e-12)  # int_0^tau Fmax sin(pi t / tau) dt
    assert h.impulse() == pytest.approx(J, rel=1e-12)
    assert half_sine(100.0, 2e-5, t0=3e-5)(4e-5) == pytest.approx(100.0)  # the delay shifts the pulse


def test_burst_and_table(tmp_path):
    b = harmonic_burst(10.0, 1e4, 3, t0=1e-5)
    assert b(1e-5 + 0.25e-4) == pytest.approx(10.0)
    assert b(1e-5 + 0.75e-4) == pytest.approx(-10.0)
    assert b(1e-5 + 3.01e-4) == 0.0 and b(0.99e-5) == 0.0
    assert b.end_time == pytest.approx(1e-5 + 3e-4)
    assert b.impulse() == 0.0  # whole cycles
    # 1.5 cycles: int_0^(1.5/f) A sin(2 pi f t) dt = A (1 - cos 3 pi) / (2 pi f) = A / (pi f)
    b = harmonic_burst(10.0, 1e4, 1.5)
    assert quad(b, 0, 1.5e-4, epsabs=0, epsrel=1e-12)[0] == pytest.approx(10.0 / (math.pi * 1e4), rel=1e-10)
    assert b.impulse() == pytest.approx(10.0 / (math.pi * 1e4), rel=1e-12)
    (tmp_path / "f.csv").write_text("time,force\n0,0\n1e-5,100\n2e-5,0\n")
    tab = read_force_csv(tmp_path / "f.csv")
    assert tab(0.5e-5) == pytest.approx(50.0)
    assert tab(1.5e-5) == pytest.approx(50.0) and tab(2.5e-5) == 0.0
    assert tab.impulse() == pytest.approx(0.5 * 2e-5 * 100.0, rel=1e-12)  # the triangle's area
    (tmp_path / "bad.csv").write_text("time,force\n0,0\n0,1\n")
    with pytest.raises(ValueError, match="increase"):
        read_force_csv(tmp_path / "bad.csv")


# (history, impulse J = int F dt, first moment int t F dt), both by hand
FREE_GRANULE_CASES = [
    # half-sine: J = 2 Fmax tau / pi, int_0^tau t sin(pi t / tau) dt = tau^2 / pi
    (half_sine(1591.6, 1e-5), 2 * 1591.6 * 1e-5 / math.pi, 1591.6 * 1e-10 / math.pi),
    # 1.5 cycles: J = A / (pi f); int_0^(3 pi) u sin u du = 3 pi, so the moment is 3 A / (4 pi f^2)
    (harmonic_burst(50.0, 2e5, 1.5), 50.0 / (math.pi * 2e5), 3 * 50.0 / (4 * math.pi * 4e10)),
    # triangle (0, 0), (1e-5, 80), (3e-5, 0): area 1.2e-3 N s, centroid at t = 4e-5 / 3
    (tabulated([0, 1e-5, 3e-5], [0, 80.0, 0]), 1.2e-3, 1.2e-3 * 4e-5 / 3),
]


@pytest.mark.parametrize("hist, J, moment", FREE_GRANULE_CASES)
def test_free_granule_gains_impulse_over_mass(hist, J, moment):
    """F(t) along (0.6, 0.8) on a lone granule (m = 4/3 pi R^3 rho): after the load, v = J/m, the
    input work is J^2 / (2 m) and the displacement at T is (J T - int t F dt) / m."""
    R = 0.005
    system = make_system([("a", 0.0, 0.0, R)], excitations=[Excitation(0, (0.6, 0.8), hist)])
    state = initial_state(system)
    Stepper(system).advance(state, 1e-8, 5000)
    m = 4 / 3 * math.pi * R**3 * 7850.0
    T = 5000 * 1e-8
    assert state.t == pytest.approx(T, rel=1e-12)
    assert hist.impulse() == pytest.approx(J, rel=1e-12)
    np.testing.assert_allclose(state.vel[0], J / m * np.array([0.6, 0.8]), rtol=1e-9)
    assert state.input_work == pytest.approx(J**2 / (2 * m), rel=1e-9)
    np.testing.assert_allclose(state.pos[0], (J * T - moment) / m * np.array([0.6, 0.8]), rtol=1e-9)
    assert state.omega[0] == 0.0 and state.dissipated_friction == 0.0 and state.dissipated_viscous == 0.0


@pytest.mark.parametrize("amplitude, cycles", [(10.0, 1.25), (-10.0, 1.5), (10.0, 2.0), (3.0, 0.25)])
def test_burst_impulse_for_any_cycle_count(amplitude, cycles):
    """int_0^(c/f) A sin(2 pi f t) dt = A (1 - cos(2 pi c)) / (2 pi f); the largest momentum it
    gives on the way, |A| / (pi f) after half a period (less for a shorter burst), checked by
    quadrature of the running integral."""
    f = 1e4
    b = harmonic_burst(amplitude, f, cycles)
    assert b.impulse() == pytest.approx(amplitude * (1 - math.cos(2 * math.pi * cycles)) / (2 * math.pi * f), rel=1e-12, abs=1e-18)
    s = np.append(np.linspace(0, cycles / f, 41), min(cycles, 0.5) / f)
    running = np.array([quad(b, 0, x, limit=200)[0] for x in s])
    assert b.peak_impulse() == pytest.approx(np.abs(running).max(), rel=1e-9)


def test_harmonic_drive_ramps_up_smoothly_and_stops():
    """A harmonic drive: zero before t0 and after its duration; within the ramps (up at the start,
    down at the end) the amplitude is (1 - cos(pi s / T_r)) / 2 of the full one; force and slope
    continuous at the ramps' ends."""
    from granel.granular.loads import harmonic

    A, f, t0, ph, nr = 3.0, 2e4, 1e-5, 0.4, 2.0
    h = harmonic(A, f, t0=t0, duration=1e-3, phase=ph, ramp_cycles=nr)
    Tr = nr / f
    assert h(t0 - 1e-9) == 0.0 and h(t0 + 1e-3 + 1e-9) == 0.0
    s = 0.3 * Tr
    assert h(t0 + s) == pytest.approx(A * 0.5 * (1 - math.cos(math.pi * 0.3)) * math.sin(2 * math.pi * f * s + ph), rel=1e-13)
    s = 5.3 / f
    assert h(t0 + s) == pytest.approx(A * math.sin(2 * math.pi * f * s + ph), rel=1e-13)
    eps = 1e-12
    assert abs(h(t0 + eps)) < 1e-9  # starts from zero force ...
    slope = lambda t: (h(t + 1e-10) - h(t - 1e-10)) / 2e-10  # noqa: E731
    assert slope(t0 + Tr - 1e-9) == pytest.approx(slope(t0 + Tr + 1e-9), rel=1e-3)  # ... and the ramp's end is smooth (a kink would jump by ~ A pi / 2 T_r)
    assert h.kinks() == pytest.approx([t0, t0 + 1e-3, t0 + Tr, t0 + 1e-3 - Tr])
    s = 1e-3 - 0.3 * Tr  # the mirrored ramp at the end
    assert h(t0 + s) == pytest.approx(A * 0.5 * (1 - math.cos(math.pi * 0.3)) * math.sin(2 * math.pi * f * s + ph), rel=1e-12)
    assert abs(h(t0 + 1e-3 - eps)) < 1e-9
    assert h.top_frequency == f
    running = np.array([quad(h, t0, t0 + x, limit=400)[0] for x in np.linspace(0, 10 / f, 201)])
    assert np.abs(running).max() <= h.peak_impulse()


@pytest.mark.parametrize("mode", ["linear", "log"])
def test_chirp_instantaneous_frequency(mode):
    """A chirp from f0 to f1: the phase's slope / 2 pi (by central differences) is f0 + (f1 - f0)
    s / D (linear) or f0 (f1 / f0)^(s / D) (log), and the force is A sin(phase) past the ramp."""
    from granel.granular.laws import chirp_phase
    from granel.granular.loads import chirp

    A, f0, f1, D = 2.0, 1e3, 4e4, 2e-3
    c = chirp(A, f0, f1, D, t0=0.0, mode=mode)
    for s in (0.0, 0.3 * D, 0.9 * D, D):
        ds = 1e-9
        lo, hi = max(s - ds, 0.0), min(s + ds, D)
        freq = (chirp_phase(hi, f0, f1, D, mode == "log") - chirp_phase(lo, f0, f1, D, mode == "log")) / (hi - lo) / (2 * math.pi)
        want = f0 + (f1 - f0) * s / D if mode == "linear" else f0 * (f1 / f0) ** (s / D)
        assert freq == pytest.approx(want, rel=1e-5)
    s = 0.37 * D
    assert c(s) == pytest.approx(A * math.sin(chirp_phase(s, f0, f1, D, mode == "log")), rel=1e-13)
    assert c(D + 1e-9) == 0.0 and c.top_frequency == f1


def _drive_reference(A, f0, f1, t0, D, phase, cycles, log, t):
    """A drive's force written from its definition: A r(s) sin(phi(s)), s = t - t0 in [0, D], the
    ramp r = (1 - cos(pi x)) / 2 with x = min(s, D - s) f0 / cycles below 1, and phi = 2 pi f0 s +
    phase (harmonic, f1 = None), or the integral of 2 pi f(s) with f going linearly or
    geometrically from f0 to f1 (a chirp)."""
    s = t - t0
    if s < 0 or s > D:
        return 0.0
    x = min(s, D - s) * f0 / cycles if cycles > 0 else 1.0
    r = 0.5 * (1 - math.cos(math.pi * x)) if x < 1 else 1.0
    if f1 is None:
        phi = 2 * math.pi * f0 * s + phase
    elif log:
        k = math.log(f1 / f0)
        phi = 2 * math.pi * f0 * D / k * (math.exp(k * s / D) - 1)
    else:
        phi = 2 * math.pi * (f0 * s + (f1 - f0) * s * s / (2 * D))
    return A * r * math.sin(phi)


@pytest.mark.parametrize("kind", ["harmonic", "chirp"])
def test_compiled_drive_matches_the_reference(kind):
    """A drive's force (the compiled law, `granular.laws.load_force`, which the integrator and
    `LoadHistory` both call) against its definition written out at 2,001 times (1e-12 of the
    amplitude: the phase's rounding, 2 pi f t eps), and a free granule's velocity after the
    drive against the quadrature of F / m."""
    from granel.granular.loads import chirp, harmonic

    if kind == "harmonic":
        hist = harmonic(5.0, 3e4, t0=2e-6, duration=2e-4, phase=0.3, ramp_cycles=1.5)
        ref = lambda t: _drive_reference(5.0, 3e4, None, 2e-6, 2e-4, 0.3, 1.5, False, t)  # noqa: E731
    else:
        hist = chirp(5.0, 2e4, 6e4, 2e-4, t0=2e-6, mode="log", ramp_cycles=1.0)
        ref = lambda t: _drive_reference(5.0, 2e4, 6e4, 2e-6, 2e-4, 0.0, 1.0, True, t)  # noqa: E731
    ts = np.linspace(0, 2.2e-4, 2001)
    np.testing.assert_allclose([hist(t) for t in ts], [ref(t) for t in ts], rtol=0, atol=1e-12 * 5.0)
    R = 0.005
    system = make_system([("a", 0.0, 0.0, R)], excitations=[Excitation(0, (1.0, 0.0), hist)])
    state = initial_state(system)
    Stepper(system).advance(state, 1e-8, 22000)
    m = 4 / 3 * math.pi * R**3 * 7850.0
    J = quad(hist, 0, 2.2e-4, points=hist.kinks(), limit=2000, epsabs=1e-15, epsrel=1e-10)[0]
    assert state.vel[0, 0] == pytest.approx(J / m, rel=1e-7, abs=1e-12 * abs(hist.peak_impulse() / m))
