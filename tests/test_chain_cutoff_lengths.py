"""A chain's measured cut-off at any length (issue 28): `analysis.narrowband.cutoff_frequency` on
precompressed steel chains of 8 to 40 beads (scenarios/designs/cutoff-chain.toml: a free end
rung by a weak pulse, 10 N against a rigid wall), with the paper's Tsuji damping and a heavier one,
against the linearised chain's eigenvalues computed here from the contact laws.

The reference. Beads of mass m = 4/3 pi R^3 rho, pairs of Hertz coefficient A = 4/3 E* sqrt(R/2)
with E* = E / 2(1 - nu^2), the wall of A_w = 4/3 E / (1 - nu^2) sqrt(R) (a sphere on a rigid
plane); under the force F0 each contact linearises to k = 3/2 A^(2/3) F0^(1/3). The eigenvalues of
M^-1 K (numpy's eigvalsh; tridiagonal, the wall's stiffness on the last bead's diagonal) are the
undamped modes; the linear cut-off is (1/pi) sqrt(K/m).

The bound on the measured top mode f, each term from the run's own numbers:
* the contacts' nonlinearity: over the record each overlap stays within delta0 (1 +- s) (s is the
  measured `strain`), so each contact's tangent stiffness, 3/2 A delta^(1/2), stays within
  (1 +- s)^(1/2) of its static value and every mode's frequency within (1 +- s)^(1/4): s/4;
* the fit's resolution over the window T: an oscillation of relative amplitude e (the measured
  `leak` of the top mode's coordinate) closer to the mode than the window resolves (1/T) can
  pull the fitted frequency by at most e/T; one farther away is fitted on its own: e / (T f);
* the integrator: classical RK4 on an oscillation of angular frequency w loses w^5 h^5 / 120 of
  phase per step of h radians' worth w h, a relative frequency error (w h)^4 / 120, largest at
  the largest step `solver_max_step`;
* the damping: none. Tsuji's dashpot linearises to G delta0^(1/4), and with the pair's m* = m/2
  and the wall's m* = m, delta_wall = delta_pair / 2 and A_w = 2^(3/2) A, the wall's dashpot is
  twice the pair's, as its spring is: the damping is proportional to the stiffness, its modes are
  the undamped ones and |s| (what the fit reports) is the undamped frequency exactly.
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from granel import scenario as S
from granel.analysis.narrowband import CutoffError, cutoff_frequency

CHAIN = Path(__file__).resolve().parents[1] / "scenarios" / "designs" / "cutoff-chain.toml"
E, NU, RHO, F0, R = 200e9, 0.3, 7850.0, 10.0, 0.005
PAPER_ALPHA = 0.006313  # the paper's Tsuji coefficient (scenario default)


def linearised_modes(n: int, radius: float = R) -> np.ndarray:
    """Undamped modes [Hz] of n beads pressed by F0 on a rigid wall at bead n, bead 1 free."""
    k_pair = 1.5 * (4 / 3 * E / (2 * (1 - NU**2)) * math.sqrt(radius / 2)) ** (2 / 3) * F0 ** (1 / 3)
    k_wall = 1.5 * (4 / 3 * E / (1 - NU**2) * math.sqrt(radius)) ** (2 / 3) * F0 ** (1 / 3)
    m = 4 / 3 * math.pi * radius**3 * RHO
    K = np.zeros((n, n))
    for i in range(n - 1):  # each pair's spring between beads i and i + 1
        K[i, i] += k_pair
        K[i + 1, i + 1] += k_pair
        K[i, i + 1] -= k_pair
        K[i + 1, i] -= k_pair
    K[-1, -1] += k_wall
    return np.sqrt(np.linalg.eigvalsh(K / m)) / (2 * math.pi)


def linear_cutoff(radius: float = R) -> float:
    k_pair = 1.5 * (4 / 3 * E / (2 * (1 - NU**2)) * math.sqrt(radius / 2)) ** (2 / 3) * F0 ** (1 / 3)
    return math.sqrt(k_pair / (4 / 3 * math.pi * radius**3 * RHO)) / math.pi


def chain_run(n: int, alpha: float, extra=()):
    from granel.run import run_scenario
    from granel.scenario.build import build_granular

    sc = S.load(str(CHAIN), [f"media.0.radii={[R] * n}", f"contact.alpha_n={alpha!r}", *extra])
    return run_scenario(sc), build_granular(sc, sc.base)[0]


def bound(c, ds, f: float) -> float:
    """The module docstring's bound for a mode at f [Hz] fitted in the record of cut-off c."""
    T = c.window[1] - c.window[0]
    h = float(ds.attrs["solver_max_step"])
    return c.strain / 4 + c.leak / (T * f) + (2 * math.pi * f * h) ** 4 / 120


LENGTHS = [
    pytest.param(18, PAPER_ALPHA, id="18-paper"),  # the chain that reported a 264 kHz mode
    pytest.param(20, 0.05, id="20-heavy"),  # beyond the old 600-sample cap
    pytest.param(8, PAPER_ALPHA, id="8-paper", marks=pytest.mark.slow),
    pytest.param(8, 0.05, id="8-heavy", marks=pytest.mark.slow),
    pytest.param(18, 0.05, id="18-heavy", marks=pytest.mark.slow),
    pytest.param(20, PAPER_ALPHA, id="20-paper", marks=pytest.mark.slow),
    pytest.param(30, PAPER_ALPHA, id="30-paper", marks=pytest.mark.slow),
    pytest.param(30, 0.05, id="30-heavy", marks=pytest.mark.slow),
    pytest.param(40, PAPER_ALPHA, id="40-paper", marks=pytest.mark.slow),
    pytest.param(40, 0.05, id="40-heavy", marks=pytest.mark.slow),
]


@pytest.mark.parametrize("n, alpha", LENGTHS)
def test_the_cutoff_of_a_chain_of_any_length_is_the_linearised_chains(n, alpha):
    """The top mode and the cut-off agree with eigvalsh of the linearised chain within the
    module's bound (about 2.1e-4 here, nearly all of it the nonlinearity's s/4; measured within
    4.1e-6 for every case); every mode found lies in the pass band (no mode of the fit's own
    making: the 18-bead chain with the paper's damping used to report one at 264 kHz), each
    within its bound with the leak taken at its refusal limit (0.1), and the top mode's damping
    ratio is the linearised Tsuji damping's, alpha / sqrt(3) sin(theta / 2) with sin(theta / 2)
    the top mode's share of the cut-off: an error of the fitted exponent s within the bound times
    |s| moves zeta = -Re s / |s| by at most the bound, a share bound / zeta of it (6 % with the
    paper's damping, 0.7 % with 0.05; measured within 0.08 % and 0.04 %)."""
    ds, system = chain_run(n, alpha)
    c = cutoff_frequency(ds, system)
    ref = linearised_modes(n)
    assert c.beads == tuple(f"C:{k}" for k in range(1, n + 1)) and len(c.modes_hz) == n
    # the ends, free and 2K, from the equilibrium's forces: each granule balanced to 1e-10 of the load
    # (`granular.static.equilibrium`), so a contact's force to n 1e-10 of it, its stiffness (F^(1/3)) and the
    # wall's ratio to a third of that, and the factor to an eighth of the ratio's error (d lambda / d T_nn <= 1)
    assert c.factor == pytest.approx(math.cos(math.pi / (4 * n)), rel=n * 1e-10)
    tol = bound(c, ds, ref[-1])
    assert tol < 3e-4
    assert abs(c.top_mode_hz / ref[-1] - 1) <= tol
    assert abs(c.cutoff_hz / linear_cutoff() - 1) <= tol + 1e-11
    assert np.all(np.isfinite(c.modes_hz)) and c.modes_hz.max() <= ref[-1] * (1 + tol)
    T = c.window[1] - c.window[0]
    loose = c.strain / 4 + 0.1 / (T * ref) + (2 * math.pi * ref * float(ds.attrs["solver_max_step"])) ** 4 / 120
    assert np.all(np.abs(c.modes_hz / ref - 1) <= loose)
    zeta = alpha / math.sqrt(3) * math.cos(math.pi / (4 * n))
    assert c.top_damping_ratio == pytest.approx(zeta, rel=tol / zeta)


def _suggested(message: str, field: str) -> float:
    """The value a refusal proposes for `field` ("... field to at least X s")."""
    m = re.search(re.escape(field) + r" to (?:at least|at most) ([0-9.eE+-]+) s", message)
    assert m, message
    return float(m.group(1))


def test_a_record_too_short_for_a_long_chain_says_which_duration_suffices():
    """The old cap of 600 samples refused every chain of 20 beads or more and asked for a longer
    run, which changed nothing. Now a 20-bead run too short for the fit names the duration that
    suffices, and a run of that duration gives the cut-off."""
    ds, system = chain_run(20, 0.05, ['simulation.duration="0.2ms"'])
    with pytest.raises(CutoffError, match="simulation.duration") as err:
        cutoff_frequency(ds, system)
    need = _suggested(str(err.value), "simulation.duration")
    assert 0.2e-3 < need < 1e-3  # 10 periods of a 17.3 kHz mode after a 5 us pulse: about 0.59 ms
    ds, system = chain_run(20, 0.05, [f"simulation.duration={need!r}"])
    c = cutoff_frequency(ds, system)
    assert abs(c.top_mode_hz / linearised_modes(20)[-1] - 1) <= bound(c, ds, c.top_mode_hz)


def test_too_sparse_outputs_say_how_dense_they_must_be():
    """Outputs too sparse for the chain's highest possible frequency (Gershgorin's bound of the
    linearised chain, 2 sqrt(K/m) / 2 pi = the cut-off for these ends) name the largest
    simulation.output_every that samples it 2.5 times a period."""
    ds, system = chain_run(20, 0.05, ['simulation.output_every="40us"', 'simulation.duration="0.4ms"'])
    with pytest.raises(CutoffError, match="lower simulation.output_every") as err:
        cutoff_frequency(ds, system)
    # printed to 3 significant figures: half a unit of the third, 0.005 in 2.31
    assert _suggested(str(err.value), "simulation.output_every") == pytest.approx(1 / (2.5 * linear_cutoff()), rel=0.005 / 2.3)


def test_a_pulse_too_strong_says_by_how_much_to_weaken_it():
    """A pulse that swings the contacts beyond the linear regime names its field and the factor
    to scale it down by: the measured swing over the limit."""
    ds, system = chain_run(20, 0.05, ["excitations.0.fmax=30.0", 'simulation.duration="0.1ms"'])
    with pytest.raises(CutoffError, match="not in its linear regime") as err:
        cutoff_frequency(ds, system)
    factor = float(re.search(r"excitations\.0\.fmax down by a factor of at least ([0-9.]+)", str(err.value)).group(1))
    ds2, system2 = chain_run(20, 0.05, [f"excitations.0.fmax={30.0 / (1.5 * factor)!r}", 'simulation.duration="0.1ms"'])
    with pytest.raises(CutoffError) as again:
        cutoff_frequency(ds2, system2)
    assert "linear regime" not in str(again.value)  # the swing is within the limit now (the record is still short)
