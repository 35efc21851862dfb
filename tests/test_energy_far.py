"""The far-medium energy shares of a run (`energy_far_peak_frac`, `energy_far_final_frac`,
`solid_energy_peak_frac`, `input_work_J`; `analysis.reciprocity.run_metrics`) under a static
preload (issue 28).

They used to divide the medium's whole energy (the preload's stored elastic energy included) by
a work that included the preload's: about 2,000 for the pulsed, precompressed chain of
scenarios/designs/cutoff-chain.toml. Now the input is the dynamic loads' work, the input work
less the preload's F0 . (r(t) - r(0)), and a medium's energy is counted from its static state,
E(t) - E(0) - F0 . (r(t) - r(0)); a run with nothing dynamic gives NaN with its reason.

The hand computation. Linearised, the chain is masses m = 4/3 pi R^3 rho joined by springs
k = 3/2 A^(2/3) F0^(1/3) (pairs: A = 4/3 E/(2(1 - nu^2)) sqrt(R/2); the wall: 4/3 E/(1 - nu^2)
sqrt(R)). A force F(t) on bead 1 gives an undamped mode j (unit shape phi_j, mass m) the energy
|phi_j1 Fhat(w_j)|^2 / (2 m) once the force has ended, Fhat(w) = int F e^(-i w t) dt; for the
half-sine F_p sin(pi t / tau) over tau, Fhat = F_p (pi/tau) (1 + e^(-i w tau)) / ((pi/tau)^2 - w^2).
Summed over the modes: the pulse's work, and without damping the chain's energy ever after.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from granel import scenario as S
from granel.analysis.reciprocity import dynamic_energy, dynamic_input, run_metrics

CHAIN = "scenarios/designs/cutoff-chain.toml"
E, NU, RHO, F0, R, N = 200e9, 0.3, 7850.0, 10.0, 0.005, 8
FP, TAU = 0.1, 5e-6  # the pulse: fmax, tau
MASS = 4 / 3 * math.pi * R**3 * RHO
A_PAIR = 4 / 3 * E / (2 * (1 - NU**2)) * math.sqrt(R / 2)
A_WALL = 4 / 3 * E / (1 - NU**2) * math.sqrt(R)


def run(*extra):
    from granel.run import run_scenario

    return run_scenario(S.load(CHAIN, list(extra)))


def pulse_work_linear() -> float:
    """The half-sine's work on the linearised, undamped chain (the module's formula)."""
    k_pair, k_wall = (1.5 * A ** (2 / 3) * F0 ** (1 / 3) for A in (A_PAIR, A_WALL))
    K = np.diag([k_pair] + [2 * k_pair] * (N - 2) + [k_pair + k_wall]) - np.diag([k_pair] * (N - 1), 1) \
        - np.diag([k_pair] * (N - 1), -1)
    lam, phi = np.linalg.eigh(K / MASS)  # bead 1, the free end, is row 0
    w = np.sqrt(lam)
    a = math.pi / TAU
    Fhat = FP * a * (1 + np.exp(-1j * w * TAU)) / (a**2 - w**2)
    return float(np.sum(phi[0] ** 2 * np.abs(Fhat) ** 2) / (2 * MASS))


def swing(ds) -> float:
    """The contacts' largest |delta - delta0| / delta0 over the run."""
    x = ds["x"].values
    delta = 2 * R - np.abs(np.diff(x, axis=1))
    return float(np.max(np.abs(delta - delta[0]) / delta[0]))


def test_an_undamped_precompressed_chain_keeps_the_pulses_work_as_its_far_energy():
    """Without damping the chain holds, from the pulse's end on, the pulse's work: the metric's
    input equals the linear formula's and both shares are 1. Bounds: the contacts' swing s (the
    size of every nonlinear term next to the linear ones; 8.3e-4 here) plus the run's largest
    energy-balance error over the pulse's work (3.1e-4 here: the ledger integrates the preload's
    work, 1e-8 J of swings, to about 4e-7 of itself). Measured: the input 3.1e-4 above the
    formula, the shares 3.0e-4 below 1, the chain's energy from its static state 1e-6 from the
    formula."""
    ds = run("contact.alpha_n=0.0")
    hand = pulse_work_linear()
    s = swing(ds)
    ledger = float(np.abs(ds["balance_error"].values).max()) / hand
    m = run_metrics(ds, "C:8")
    assert m["notes"] == {} and m["far_medium"] == "C"
    assert m["input_work_J"] == pytest.approx(hand, rel=s + ledger)
    assert m["energy_far_peak_frac"] == pytest.approx(1.0, abs=s + ledger)
    assert m["energy_far_final_frac"] == pytest.approx(1.0, abs=s + ledger)
    e, why = dynamic_energy(ds, "C")
    assert why is None and e[-1] == pytest.approx(hand, rel=s)
    assert m["solid_energy_peak_frac"] == 0.0  # no solid


def test_a_damped_chains_far_energy_is_its_motion_about_equilibrium():
    """The base chain (alpha_n = 0.05): the metric's chain energy at the end, over its input, is
    the hand sum of 1/2 m v^2 and, per contact, 2/5 A (delta^(5/2) - delta0^(5/2)) less the
    preload's work F0 . (r - r0), from the outputs' positions and velocities, over the input work
    less that preload work. Bound: round-off of the overlaps, an ulp of the positions (|x| <= 0.08
    m) times each contact's force (10 N), over the energy: 3.5e-4 at the end and 9e-5 at the peak,
    measured 4.3e-9 and 5.6e-10."""
    ds = run()
    m = run_metrics(ds, "C:8")
    x, v = ds["x"].values, ds["v_x"].values
    d_pair = 2 * R - np.abs(np.diff(x, axis=1))
    d_wall = R - x[:, -1]  # bead 8 on the face wall, the line x = 0 facing +x
    assert np.all(d_pair > 0) and np.all(d_wall > 0)
    elastic = 0.4 * A_PAIR * np.sum(d_pair**2.5, axis=1) + 0.4 * A_WALL * d_wall**2.5
    preload = F0 * -(x[:, 0] - x[0, 0])  # the constant load pushes bead 1 along -x
    energy = 0.5 * MASS * np.sum(v**2, axis=1) + elastic - elastic[0] - preload
    work = ds["input_work"].values - preload
    roundoff = N * F0 * np.spacing(0.08) / energy[-1]
    assert m["input_work_J"] == pytest.approx(work.max(), rel=1e-12)
    assert m["energy_far_final_frac"] == pytest.approx(energy[-1] / work.max(), rel=roundoff)
    assert m["energy_far_peak_frac"] == pytest.approx(energy.max() / work.max(), rel=N * F0 * np.spacing(0.08) / energy.max())
    assert 0.2 < m["energy_far_final_frac"] < m["energy_far_peak_frac"] <= 1.0  # damped: it loses some


def test_a_run_with_nothing_dynamic_gives_nan_with_its_reason(tmp_path):
    """The preload alone (the pulse removed): nothing dynamic to share, so the shares and the
    input are NaN, each with its reason under `notes`, in the metrics and in a sweep case."""
    from granel.studies.sweep import CaseSpec, run_case

    ds = run("excitations.0=-")
    m = run_metrics(ds, "C:8")
    for key in ("energy_far_peak_frac", "energy_far_final_frac", "solid_energy_peak_frac", "input_work_J"):
        assert math.isnan(m[key]) and "nothing drives the run beyond its static preload" in m["notes"][key]
    assert math.isnan(dynamic_input(ds)[0])
    spec = CaseSpec(base=str(Path(CHAIN).resolve()), mode="run", pair=("C:1", "C:8"), overrides=["excitations.0=-"])
    res = run_case(spec.model_dump_json(), str(tmp_path), {"index": [0], "overrides": {}, "tag": "a"}, str(tmp_path), False)
    assert res["status"] == "ok" and math.isnan(res["metrics"]["energy_far_peak_frac"])
    assert "static preload" in res["notes"]["energy_far_peak_frac"] and "cutoff_Hz" in res["notes"]


def test_without_a_preload_the_shares_are_the_energy_over_the_work():
    """A chain started at rest, not from its equilibrium: the constant load is a step load, part
    of the input, and the shares are the medium's energy over the loads' largest work, as the
    ledger records both."""
    ds = run("simulation.equilibrate=false", 'simulation.duration="0.2ms"')
    m = run_metrics(ds, "C:8")
    e, w = ds["energy_c"].values, ds["input_work"].values
    assert m["notes"] == {} and m["input_work_J"] == w.max()
    assert m["energy_far_peak_frac"] == e.max() / w.max() and m["energy_far_final_frac"] == e[-1] / w.max()

