"""The tensioned membrane standing across the granular plane (`solid.membrane`, P2 triangles)
against closed forms: the fixed rectangle's w_mn = c pi sqrt((m/a)^2 + (n/b)^2), c = sqrt(N / rho h),
with the element's observed order (4 for quadratic elements on a second-order problem), a free
pair of edges (cos modes across), the foundation's shift w^2 = w0^2 + k_f / (rho h), and the
refusals of what holds nothing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse.linalg import eigsh

from granel import scenario as S
from granel.run import run_scenario
from granel.scenario.schema import ScenarioError
from granel.solid.base import Material, Slab
from granel.solid.kinds import kind_of
from granel.solid.membrane import MEMBRANE, build_membrane

from test_exact import ledger_bound

RUBBER = Material(1e7, 1000.0, 0.45)  # a thin sheet: only its density (and thickness) matter to a membrane
H, N = 5e-4, 200.0  # thickness [m], tension per length [N/m]
RHO_H = RUBBER.rho * H
C = math.sqrt(N / RHO_H)


def frequencies(a, b, n, edges=("fixed",) * 4, foundation=0.0, count=4):
    model = build_membrane(Slab(0.0, 0.0, H, a, b), RUBBER, [], n, edges, N, foundation)
    w2 = np.sort(eigsh(model.K.tocsc(), count, model.M.tocsc(), sigma=0.0, which="LM")[0])
    return np.sqrt(np.abs(w2)) / (2 * math.pi)


def exact(a, b, count, across=range(1, 6)):
    return np.sort([C / 2 * math.sqrt((m / a) ** 2 + (n / b) ** 2) for m in range(1, 6) for n in across])[:count]


def test_a_fixed_rectangle_converges_to_its_modes_at_order_four():
    """A 2:1 rectangle fixed on every edge: the four lowest against c/2 sqrt((m/a)^2 + (n/b)^2); P2
    on a second-order problem: eigenvalue errors O(h^4), observed between 8 and 16 elements along
    (3.6 to 4.1 measured), and the error at 16 below a tenth of the change from 8."""
    a, b = 0.1, 0.05
    want = exact(a, b, 4)
    coarse, fine = frequencies(a, b, 8), frequencies(a, b, 16)
    order = np.log(np.abs(coarse - want) / np.abs(fine - want)) / math.log(2)
    assert np.all((3.5 <= order) & (order <= 4.5)), order
    assert np.all(np.abs(fine - want) < 0.1 * np.abs(coarse - fine))


def test_free_front_and_back_edges_give_the_modes_uniform_across():
    """Fixed at y = 0 and L, free at z = +-b/2: w = sin(m pi y / a) cos(n pi (z + b/2) / b), n = 0, 1,
    ...: the lowest are the string's m c / 2a (uniform across)."""
    a, b = 0.1, 0.05
    want = exact(a, b, 4, across=range(0, 4))
    edges = ("fixed", "fixed", "free", "free")
    coarse, fine = frequencies(a, b, 8, edges), frequencies(a, b, 16, edges)
    assert np.all(np.abs(fine - want) < 0.1 * np.abs(coarse - fine))  # order 4: a fifteenth of the change
    assert fine[0] == pytest.approx(C / (2 * a), rel=1e-5)


def test_a_foundation_lifts_every_mode_by_its_stiffness_over_the_mass():
    """w^2 = w0^2 + k_f / rho h mode by mode: the foundation's matrix is k_f / rho h times the mass
    matrix, so exactly, to the eigensolver's round-off (1e-9 of w^2)."""
    kf = 1e7
    bare, lifted = frequencies(0.1, 0.05, 8), frequencies(0.1, 0.05, 8, foundation=kf)
    np.testing.assert_allclose((2 * math.pi * lifted) ** 2, (2 * math.pi * bare) ** 2 + kf / RHO_H, rtol=1e-9)
    model = build_membrane(Slab(0.0, 0.0, H, 0.1, 0.05), RUBBER, [], 8, ("fixed",) * 4, N, kf)
    f0 = kind_of(model).branches(model, np.array([0.0]))["membrane"][0]
    assert f0 == pytest.approx(math.sqrt(kf / RHO_H) / (2 * math.pi), rel=1e-12)


SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "membrane" / "dimer-membrane.toml"


@pytest.mark.parametrize("overrides, message", [
    (["solid.tension=0.0"], "solid.tension: a membrane needs a tension > 0"),
    (['solid.edges=["free", "free", "free", "free"]', "solid.foundation=0.0"], "solid.edges: a membrane with every edge free"),
    (['solid.edges=["clamped", "fixed", "fixed", "fixed"]'], "solid.edges = .*a membrane's edges are each one of fixed, free"),
])
def test_bad_membranes_are_refused_naming_the_field(overrides, message):
    with pytest.raises(ScenarioError, match=message):
        S.load(str(SCENARIO), overrides)


def test_a_dimer_chain_on_the_supported_membrane_keeps_the_ledger():
    """The predecessor's set-up (scenarios/membrane/dimer-membrane.toml) on a coarse membrane: the
    pulse reaches it, and the ledger (13) closes within the exact integrator's bound."""
    sc = S.load(str(SCENARIO), ["solid.surface_elements=10", 'simulation.duration="0.6ms"'])
    ds = run_scenario(sc)
    assert ds["energy_solid"].values.max() > 0.01 * ds["input_work"].values[-1]
    assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, sc)


def test_a_fixed_disc_converges_to_the_bessel_zeros_at_order_two():
    """A circular membrane of radius a, rim fixed: w = j_mn c / a, j the zeros of the Bessel
    functions (2.404826, 3.831706 twice, 5.135622 twice, 5.520078). P2 alone would give order 4,
    but the rim is the inscribed polygon, whose O(h^2) loss of area bounds the order at 2: the
    observed order of each falls toward 2 (16 -> 32 -> 64 elements along the diameter: 2.04-2.14,
    then 2.02-2.05 measured), and Richardson's extrapolation from 32 and 64 meets the zeros within
    its own last change (from 16 and 32)."""
    a = 0.05
    zeros = np.array([2.404826, 3.831706, 5.135622, 5.520078])
    values = {}
    for n in (16, 32, 64):
        model = build_membrane(Slab(0.0, 0.0, H, 2 * a, 2 * a), RUBBER, [], n, ("fixed",), N, 0.0, "disc")
        w = np.sqrt(np.sort(eigsh(model.K.tocsc(), 7, model.M.tocsc(), sigma=0.0, which="LM")[0]))
        values[n] = w[[0, 1, 3, 5]] * a / C
    error = {n: np.abs(v - zeros) for n, v in values.items()}
    early, late = (np.log(error[n] / error[2 * n]) / math.log(2) for n in (16, 32))
    assert np.all((late < early) & (1.95 <= late) & (late <= 2.1)), (early, late)
    rich_early, rich_late = ((4 * values[2 * n] - values[n]) / 3 for n in (16, 32))
    assert np.all(np.abs(rich_late - zeros) <= np.abs(rich_late - rich_early) + 5e-7)


def test_a_disc_on_a_foundation_may_have_a_free_rim_and_a_free_rim_alone_is_refused():
    """A free rim holds nothing; on a foundation the disc is held by it."""
    base = ['solid.shape="disc"', "solid.thickness=0.1", "solid.length=0.1", 'solid.edges=["free"]']
    with pytest.raises(ScenarioError, match="solid.edges = .*free to move as a rigid body"):
        S.load(str(SCENARIO), base + ["solid.foundation=0.0"])
    assert S.load(str(SCENARIO), base + ["solid.foundation=1e6"]).solid.shape == "disc"


def test_the_p2_dispersion_law_bounds_the_membranes_frequency_error():
    """The law `granel wavefield` reads for the membrane (`MembraneKind.dispersion`, C (K l)^4,
    C = 0.0012) against the exact c K of a fixed 2:1 rectangle's lowest modes matched by their
    count (16 elements along it): the relative errors (+1e-3 (K l)^4 measured) lie within it."""
    law, power = MEMBRANE.dispersion
    a, b, n = 0.1, 0.05, 16
    model = build_membrane(Slab(0.0, 0.0, H, a, b), RUBBER, [], n, ("fixed",) * 4, N, 0.0)
    w = np.sqrt(np.sort(eigsh(model.K.tocsc(), 8, model.M.tocsc(), sigma=0.0, which="LM")[0]))
    K = np.sort([math.pi * math.hypot(m / a, k / b) for m in range(1, 9) for k in range(1, 5)])[:8]
    error = w / (C * K) - 1
    assert np.all((0 < error) & (error <= law * (K * a / n) ** power)), error / (K * a / n) ** power


def test_a_disc_graded_toward_its_centre_keeps_its_fundamental_and_adds_vertices_only_near_it():
    """`contact_refinement` on the fixed disc (16 elements across, three levels toward a contact at
    the centre): the rim's polygon is the coarse one, so the fundamental 2.404826 c / a is met
    at least as closely as the coarse mesh meets it (its error is the polygon's); the new vertices
    on z = 0 lie within the refined zone, 4 coarse elements of the centre."""
    from granel.solid.bending_plate import REFINE_ZONE

    a = 0.05
    models = [build_membrane(Slab(0.0, -a, H, 2 * a, 2 * a), RUBBER, [("B:1", "left", 0.0)], 16, ("fixed",), N, 0.0,
                             "disc", levels) for levels in (0, 3)]
    coarse, graded = (float(np.sqrt(eigsh(m.K.tocsc(), 1, m.M.tocsc(), sigma=0.0, which="LM")[0][0])) * a / C
                      for m in models)
    assert abs(graded - 2.404826) <= abs(coarse - 2.404826)
    assert models[1].info["dofs"] > models[0].info["dofs"]
    new = np.setdiff1d(np.round(models[1].nodes[:, 1], 12), np.round(models[0].nodes[:, 1], 12))
    assert len(new) > 0 and np.abs(new).max() < REFINE_ZONE * 2 * a / 16


@pytest.mark.slow  # about 4 s: four 1 ms runs of a 1,600-DOF membrane
def test_a_tauter_membrane_takes_more_of_the_chains_shock():
    """scenarios/membrane/dimer-membrane.toml over its tension (scenarios/sweeps/membrane-tension):
    the membrane's largest share of the input work grows with the tension, as the cord's grows
    with its impedance and as both predecessors report (measured 2.8, 8.9, 25.8, 52.1 % at 250,
    1000, 4000, 16000 N/m without foundation), the chain's final share falls, the foundation adds
    to the membrane's share where the tension is low (5.5 against 2.8 %), and the ledger (13) closes."""
    shares, kept = [], []
    for tension in (250.0, 1000.0, 4000.0, 16000.0):
        sc = S.load(str(SCENARIO), [f"solid.tension={tension}", "solid.foundation=0.0"])
        ds = run_scenario(sc)
        work = float(ds["input_work"].values.max())
        shares.append(float(ds["energy_solid"].values.max()) / work)
        kept.append(float(ds["energy_d"].values[-1]) / work)
        assert np.abs(ds["balance_error"].values).max() <= ledger_bound(ds, sc)
    assert all(a < b for a, b in zip(shares, shares[1:])) and shares[0] < 0.05 < 0.5 < shares[-1]
    assert all(a > b for a, b in zip(kept, kept[1:]))
    supported = run_scenario(S.load(str(SCENARIO), ["solid.tension=250.0"]))
    assert float(supported["energy_solid"].values.max()) / float(supported["input_work"].values.max()) > 1.5 * shares[0]
