"""The thick (Mindlin) plate, `solid.plate_theory = "mindlin"` (`solid.mindlin`), against references
no one here wrote: the simply supported plate's exact frequencies from Mindlin's equations
(w, beta as sines and cosines; the tabulated lambda = w a^2 sqrt(rho h / D) = 19.065 of the
square with h / a = 0.1 and k = 5/6), the P2 elements' observed order, the thin plate's limit
(Kirchhoff's pi^2 (m^2 + n^2)), and a chain striking it through the scenario."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.linalg import eigsh

from granel import scenario as S
from granel.run import run_scenario
from granel.scenario.schema import ScenarioError
from granel.solid.base import Material, Slab
from granel.solid.bending_plate import flexural_rigidity
from granel.solid.mindlin import SHEAR_COEFFICIENT, build_mindlin_plate, mindlin_frequencies

from test_exact import ledger_bound

STEEL = Material(200e9, 7850.0, 0.3)
A = 1.0  # the square's side [m]


def constants(h):
    """D, k G h, rho h, rho h^3 / 12 of a steel plate of thickness h."""
    return (flexural_rigidity(STEEL.E, STEEL.nu, h), SHEAR_COEFFICIENT * STEEL.E / (2 * (1 + STEEL.nu)) * h,
            STEEL.rho * h, STEEL.rho * h**3 / 12)


def exact(h, count=4):
    """The lowest `count` angular frequencies of the simply supported square: each mode (m, n)'s
    flexural root of `mindlin_frequencies`."""
    D, shear, rho_h, rho_i = constants(h)
    roots = [mindlin_frequencies(m * math.pi / A, n * math.pi / A, D, STEEL.nu, shear, rho_h, rho_i)[0]
             for m in range(1, 5) for n in range(1, 5)]
    return np.sort(roots)[:count]


def fe(h, n, edges=("simple",) * 4, count=4):
    model = build_mindlin_plate(Slab(0.0, 0.0, h, A, A), STEEL, [], n, edges)
    return np.sqrt(np.sort(eigsh(model.K.tocsc(), count, model.M.tocsc(), sigma=0.0, which="LM")[0]))


def test_the_reference_meets_the_tabulated_thick_square():
    """Mindlin's 3 x 3 problem per mode (written out in `mindlin_frequencies`) gives the tabulated
    fundamental of the simply supported square with h / a = 0.1, k = 5/6: lambda = 19.065 (to
    its four digits), below Kirchhoff's 2 pi^2 = 19.739 by the shear and rotary inertia; and as
    h / a -> 0 it tends to Kirchhoff's (within (h / a)^2 times a few: 4e-4 at h / a = 0.01)."""
    D, _, rho_h, _ = constants(0.1)
    lam = exact(0.1, 1)[0] * A**2 * math.sqrt(rho_h / D)
    assert lam == pytest.approx(19.065, abs=5e-4)
    D, _, rho_h, _ = constants(0.01)
    thin = exact(0.01, 1)[0] * A**2 * math.sqrt(rho_h / D)
    assert 0 < 2 * math.pi**2 - thin < 5 * 0.01**2 * 2 * math.pi**2


def test_a_thick_square_converges_to_mindlins_frequencies_at_order_four():
    """h / a = 0.1, simply supported (hard: w and the rotation along each edge held), modes 1-4:
    P2's eigenvalue errors go as l^(2(p + 1 - 1)) = l^4 (Strang & Fix); observed between 3.6 and
    4.4 over 8 -> 16 -> 32 elements (measured 3.8-3.9), and at 32 every mode within 1e-4."""
    ref = exact(0.1)
    errors = {n: np.abs(fe(0.1, n) / ref - 1) for n in (8, 16, 32)}
    for coarse, fine in ((8, 16), (16, 32)):
        order = np.log(errors[coarse] / errors[fine]) / math.log(2)
        assert np.all((3.6 <= order) & (order <= 4.4)), order
    assert errors[32].max() < 1e-4


def test_a_thin_plate_locks_only_mildly_and_converges():
    """h / a = 0.01: P2's shear locking (the elements' h / l = 0.08-0.32) makes the coarse mesh
    stiff (7 % at 8 elements, measured), but the error falls at order 3 or more and reaches
    Kirchhoff's neighbourhood at 32 elements (within 3e-3 of Mindlin's exact; docs/solids.md says
    to prefer `kirchhoff` for thin plates)."""
    ref = exact(0.01)
    errors = {n: np.abs(fe(0.01, n) / ref - 1) for n in (8, 16, 32)}
    assert np.all(np.log(errors[16] / errors[32]) / math.log(2) >= 3.0)
    assert errors[32].max() < 3e-3 and errors[8].max() > 0.05


def test_edges_that_hold_nothing_are_refused():
    with pytest.raises(ValueError, match="free to move as a rigid body"):
        build_mindlin_plate(Slab(0.0, 0.0, 0.1, A, A), STEEL, [], 4, ("simple", "free", "free", "free"))


def test_a_chain_on_a_thick_plate_through_the_scenario_keeps_the_ledger():
    """The built-in chain-on-plate with plate_theory = "mindlin" on a coarse mesh: the run is the
    Mindlin plate's (three fields per node: 3 x the thin plate's count of vertices and edges),
    the chain strikes it and the ledger (13) closes."""
    sc = S.load("chain-on-plate", ['solid.plate_theory="mindlin"', "solid.surface_elements=8",
                                   'simulation.duration="0.3ms"', 'simulation.output_every="2us"'])
    ds = run_scenario(sc)
    assert ds["contact_force_normal"].values.max() > 1.0
    assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, sc)
    from granel.analysis.result_model import result_solid
    from granel.solid.kinds import kind_of

    model = result_solid(ds)
    assert model.info["theory"] == "mindlin" and model.recipe.theory == "mindlin"
    assert model.T.shape[0] == kind_of("bending_plate").size(sc.solid)[0]
    stress = kind_of(model).stress(model, model.T @ np.ones(model.ndof), STEEL.E, STEEL.nu)["surface_von_mises"]
    assert stress.shape == (model.nelements,) and np.isfinite(stress).all()
    # the per-segment energies of a mass-normalised mode at amplitude a: a^2 / 2 kinetic at unit
    # speed, a^2 w^2 / 2 strain, to the assembly's round-off
    from granel.analysis.result_model import result_modes

    modes = result_modes(ds)
    shape = np.asarray(modes.shapes[:, 0]) * 1e-3
    kinetic, strain = model.element_energies(shape, shape)
    assert kinetic.sum() == pytest.approx(0.5e-6, rel=1e-9)
    assert strain.sum() == pytest.approx(0.5e-6 * modes.omega[0] ** 2, rel=1e-9)
    # its wavefield branch: Kirchhoff's at long waves, below it (shear, rotary inertia) at short ones
    k = np.array([10.0, 1000.0])
    branch = kind_of(model).branches(model, k)["flexural"]
    kirchhoff = k**2 * math.sqrt(model.info["D"] / model.info["rhoh"]) / (2 * math.pi)
    assert branch[0] == pytest.approx(kirchhoff[0], rel=1e-3) and branch[1] < 0.7 * kirchhoff[1]


@pytest.mark.parametrize("overrides, message", [
    (['solid.kind="membrane"', "solid.tension=100.0", 'solid.plate_theory="mindlin"'],
     "solid.plate_theory: a membrane solid does not use it"),
    (['solid.plate_theory="reissner"'], "solid.plate_theory"),
])
def test_bad_theories_are_refused_naming_the_field(overrides, message):
    with pytest.raises(ScenarioError, match=message):
        S.load("chain-on-plate", overrides)
