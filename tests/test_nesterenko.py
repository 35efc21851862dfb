"""Solitary wave in an uncompressed 1D Hertzian chain vs Nesterenko's long-wave solution.

Reference (Nesterenko, Dynamics of Heterogeneous Materials, 2001): for identical spheres,
V_s = (16/25)^(1/5) c0^(4/5) v_m^(1/5), c0^2 = 2E / (pi rho (1 - nu^2)), with v_m the peak
particle velocity; the wave is about five particle diameters long.
"""

import math

import numpy as np
import pytest

from granel.granular.system import Stepper, initial_state
from granel.granular.materials import STEEL

from conftest import make_system

EPS = np.finfo(float).eps


def run_chain(v_striker, dt, N=60, R=0.005, every=4, nout=4000):
    """A striker at v_striker hits 59 touching beads at rest: velocities V and positions X of
    every bead at the output times T."""
    system = make_system([(str(i), 2 * R * i, 0.0, R) for i in range(N)])
    v0 = np.zeros((N, 2))
    v0[0, 0] = v_striker
    state = initial_state(system, v0)
    stepper = Stepper(system)
    V, X, T = np.empty((nout, N)), np.empty((nout, N)), np.empty(nout)
    for k in range(nout):
        stepper.advance(state, dt, every)
        V[k] = state.vel[:, 0]
        X[k] = state.pos[:, 0]
        T[k] = state.t
    return R, N, V, T, X


@pytest.fixture(scope="module")
def chain_run():
    return run_chain(1.0, 5e-8)


@pytest.fixture(scope="module")
def fine_chain_run():
    """The same chain at half the step, outputs at the same times: RK4's truncation, by difference."""
    return run_chain(1.0, 2.5e-8, every=8)


@pytest.fixture(scope="module")
def slow_chain_run():
    """1/32 of the striker speed: by the Hertz scaling (t ~ v^(-1/5)) the wave is twice as slow,
    so the same number of steps of twice the size covers the same beads."""
    return run_chain(1.0 / 32, 1e-7)


def wave_speed(R, V, T):
    """Speed of the velocity maximum over beads 20..44 and the mean peak velocity there."""
    bulk = np.arange(20, 45)
    tp, vm = peak_times(V, T, bulk)
    return np.polyfit(tp, 2 * R * bulk, 1)[0], float(np.mean(vm)), vm


def peak_times(V, T, beads):
    """Time and value of each bead's velocity maximum (parabolic refinement)."""
    h = T[1] - T[0]
    tp, vm = [], []
    for i in beads:
        k = int(np.argmax(V[:, i]))
        y0, y1, y2 = V[k - 1 : k + 2, i]
        d = (y0 - y2) / (2 * (y0 - 2 * y1 + y2))
        tp.append(T[k] + d * h)
        vm.append(y1 - 0.25 * (y0 - y2) * d)
    return np.array(tp), np.array(vm)


def test_solitary_wave_speed(chain_run):
    R, N, V, T, X = chain_run
    Vs, v_m, vm = wave_speed(R, V, T)
    # the wave is stationary in the bulk: its amplitude does not change but for RK4's truncation
    # and the parabola's refinement of the sampled peaks, both of order (h / tau)^2 with h the
    # output spacing (0.2 us) and tau the pulse's time at a bead (five diameters at 670 m/s, 75 us):
    # 7e-6 (measured 2.6e-7)
    assert np.std(vm) / v_m < 1e-5
    c0 = math.sqrt(2 * STEEL.E / (math.pi * STEEL.rho * (1 - STEEL.nu**2)))
    V_nesterenko = (16 / 25) ** 0.2 * c0**0.8 * v_m**0.2
    # the discrete chain's wave is 0.78 % slower than the long-wave (continuum) solution
    assert Vs == pytest.approx(V_nesterenko, rel=0.01)


def test_solitary_wave_speed_scales_as_the_fifth_root_of_amplitude(chain_run, slow_chain_run):
    """V_s ~ v_m^(1/5) (Nesterenko), exact for the discrete Hertz chain: a 32 times weaker
    striker gives a wave twice as slow (measured ratio 2 - 1.6e-10). A force law delta^p would
    give the exponent (p - 1) / (p + 1)."""
    (R, N, V1, T1, X1), (_, _, V2, T2, X2) = chain_run, slow_chain_run
    Vs1, vm1, _ = wave_speed(R, V1, T1)
    Vs2, vm2, _ = wave_speed(R, V2, T2)
    # RK4 commutes with the scaling (t x 2, v / 32, displacements / 16): the two runs are the same
    # discrete wave but for the positions' rounding, an ulp of x a step against the slow wave's
    # overlaps (its smallest peak, from Hertz: 4.5e-7 m)
    m = 4 / 3 * math.pi * R**3 * STEEL.rho
    A = 4 / 3 * STEEL.E / (2 * (1 - STEEL.nu**2)) * math.sqrt(R / 2)
    dmax = (5 * (m / 2) * vm2**2 / (4 * A)) ** 0.4
    rel = len(T2) * 4 * np.spacing(np.abs(X2).max()) / dmax
    assert vm1 / vm2 == pytest.approx(32, rel=rel)  # the same wave, scaled
    assert Vs1 / Vs2 == pytest.approx((vm1 / vm2) ** 0.2, rel=rel)


def test_chain_conserves_energy_and_momentum(chain_run, fine_chain_run):
    """No damping, no friction: at every output the kinetic energy plus 2/5 A delta^(5/2) per
    contact (A = 4/3 E* sqrt(R/2), E* = E / (2 (1 - nu^2))) is the striker's m v^2 / 2 within
    RK4's truncation (~400 steps per contact; twice its change at half the step) and the
    positions' rounding (an ulp of x a step against the overlaps, 2.5 times for delta^(5/2));
    measured 5.6e-9. The momentum is m v to an ulp of the speeds a step (measured 4e-15)."""
    R, N, V, T, X = chain_run
    m = 4 / 3 * math.pi * R**3 * STEEL.rho
    A = 4 / 3 * STEEL.E / (2 * (1 - STEEL.nu**2)) * math.sqrt(R / 2)

    def energy(V, X):
        delta = np.maximum(2 * R - np.diff(X, axis=1), 0.0)
        return (0.5 * m * (V**2).sum(axis=1) + 0.4 * A * (delta**2.5).sum(axis=1)) / (0.5 * m)

    coarse, fine = energy(V, X), energy(fine_chain_run[2], fine_chain_run[4])
    steps = 4 * len(T)
    dmax = (5 * (m / 2) * V.max() ** 2 / (4 * A)) ** 0.4
    rounding = 2.5 * steps * np.spacing(np.abs(X).max()) / dmax
    assert np.all(np.abs(coarse - 1) <= 2 * np.abs(coarse - fine) + rounding)
    assert np.abs(V.sum(axis=1) - 1.0).max() <= steps * EPS * np.abs(V).sum(axis=1).max()
    assert V[:, 44].max() > 0.6  # the wave (peak 0.68 m/s) has passed through the bulk


def test_solitary_wave_width(chain_run):
    R, N, V, T, X = chain_run
    k = int(np.argmax(V[:, 30]))
    snap = V[k]
    moving = np.flatnonzero(snap > 1e-3 * snap.max())
    # about five diameters: the continuum solution spans 5 pi / sqrt(10) = 4.97 diameters; in the
    # discrete wave the next beads out move at 8e-3 and 8e-6 of the peak
    assert len(moving) == 5
    assert moving.max() - moving.min() + 1 == len(moving)  # one compact pulse
    assert moving.min() == 28  # centred on bead 30
