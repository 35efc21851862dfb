"""Solitary wave in an uncompressed 1D Hertzian chain vs Nesterenko's long-wave solution.

Reference (Nesterenko, Dynamics of Heterogeneous Materials, 2001): for identical spheres,
V_s = (16/25)^(1/5) c0^(4/5) v_m^(1/5), c0^2 = 2E / (pi rho (1 - nu^2)), with v_m the peak
particle velocity; the wave is about five particle diameters long.
"""

import math

import numpy as np
import pytest

from granel.granular.system import Stepper, initial_state
from granel.materials import STEEL

from conftest import make_system


@pytest.fixture(scope="module")
def chain_run():
    N, R = 60, 0.005
    system = make_system([(str(i), 2 * R * i, 0.0, R) for i in range(N)])
    v0 = np.zeros((N, 2))
    v0[0, 0] = 1.0  # striker
    state = initial_state(system, v0)
    stepper = Stepper(system)
    dt, every, nout = 5e-8, 4, 4000
    V, T = np.empty((nout, N)), np.empty(nout)
    for k in range(nout):
        stepper.advance(state, dt, every)
        V[k] = state.vel[:, 0]
        T[k] = state.t
    return R, N, V, T


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
    R, N, V, T = chain_run
    bulk = np.arange(20, 45)
    tp, vm = peak_times(V, T, bulk)
    Vs = np.polyfit(tp, 2 * R * bulk, 1)[0]
    v_m = float(np.mean(vm))
    # the wave is stationary in the bulk: its amplitude does not change
    assert np.std(vm) / v_m < 1e-4
    c0 = math.sqrt(2 * STEEL.E / (math.pi * STEEL.rho * (1 - STEEL.nu**2)))
    V_nesterenko = (16 / 25) ** 0.2 * c0**0.8 * v_m**0.2
    assert Vs == pytest.approx(V_nesterenko, rel=0.02)


def test_solitary_wave_width(chain_run):
    R, N, V, T = chain_run
    k = int(np.argmax(V[:, 30]))
    snap = V[k]
    moving = np.flatnonzero(snap > 1e-3 * snap.max())
    # about five diameters: the continuum solution spans 5 pi / sqrt(10) = 4.97 diameters
    assert 4 <= len(moving) <= 6
    assert moving.max() - moving.min() + 1 == len(moving)  # one compact pulse
