"""Conservation laws, the energy balance (13) and symmetry."""

import numpy as np
import pytest

from granel import scenario as S
from granel.granular.packing import Wall, hexagonal_block
from granel.granular.system import ContactLaw, Excitation, Stepper, initial_state
from granel.excitation import constant_force
from granel.run import run_scenario

from conftest import make_system


def block_system(law):
    pos = hexagonal_block(6, 5, 0.005)
    rng = np.random.default_rng(1)
    R = 0.005 * (1 - 0.02 * rng.random(len(pos)))  # slightly polydisperse, all touching-free
    return make_system([(str(i), x, y, r) for i, ((x, y), r) in enumerate(zip(pos, R))], law=law)


def momenta(system, state):
    m = system.mass
    p = (m[:, None] * state.vel).sum(axis=0)
    L = float(np.sum(m * (state.pos[:, 0] * state.vel[:, 1] - state.pos[:, 1] * state.vel[:, 0])) + np.sum(system.inertia * state.omega))
    return p, L


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_momentum_and_angular_momentum(mu):
    system = block_system(ContactLaw(mu=mu, alpha_n=0.05, k_s=100.0))
    rng = np.random.default_rng(7)
    state = initial_state(system, rng.normal(0, 1.0, (system.n, 2)), rng.normal(0, 200.0, system.n))
    stepper = Stepper(system)
    p0, L0 = momenta(system, state)
    scale_p = float(np.sum(system.mass * np.hypot(*state.vel.T)))
    scale_L = float(np.sum(system.mass * 0.05 * np.hypot(*state.vel.T)))
    stepper.advance(state, 2e-8, 5000)
    p1, L1 = momenta(system, state)
    assert state.dissipated_viscous > 0  # contacts did happen
    # linear momentum is a linear invariant: RK4 keeps it to round-off
    assert np.abs(p1 - p0).max() < 1e-13 * scale_p
    if mu == 0.0:
        # central forces: L is a quadratic invariant, kept by RK4 to its truncation error
        assert abs(L1 - L0) < 1e-9 * scale_L
    else:
        # eq. (1) puts friction at R_i from the centre, not at the contact point: the couple
        # delta (n x f) per contact breaks exact conservation at order delta / R (~1e-4 here)
        assert abs(L1 - L0) < 1e-3 * scale_L


@pytest.mark.parametrize("excite", ["LSGM:3", "SSGM:C"])
def test_energy_balance_paper_rigid(excite):
    """Damping and friction on, the paper's step, 0.8 ms: (13) closes to 1e-6 of the input."""
    sc = S.load("paper", ['solid.kind="rigid"', f'excitations.0.granule="{excite}"'])
    ds = run_scenario(sc)
    w = ds["input_work"].values
    assert ds["time"].values[-1] == pytest.approx(8e-4)
    assert ds["dissipated_friction"].values[-1] > 0.05 * w[-1]  # dissipation is not negligible
    assert ds["dissipated_viscous"].values[-1] > 0
    assert np.abs(ds["balance_error"].values).max() < 1e-6 * w.max()
    # the impulse delivered to a free granule: W ~ J^2 / (2 m) (it is not free, but close)
    J = 2 * 1591.6 * 1e-5 / np.pi
    m = 4 / 3 * np.pi * (0.01 if excite == "LSGM:3" else 0.005) ** 3 * 7850
    assert w[-1] == pytest.approx(J**2 / (2 * m), rel=0.05)


def test_paper_geometry_stays_symmetric():
    sc = S.load("paper", ['solid.kind="rigid"', 'simulation.duration="0.4ms"'])
    ds = run_scenario(sc)
    lab = list(ds["granule"].values)
    mirror = {"1": "5", "2": "4", "6": "9", "7": "8", "10": "14", "11": "13"}
    worst_y = worst_v = 0.0
    for a, b in mirror.items():
        ia, ib = lab.index(f"LSGM:{a}"), lab.index(f"LSGM:{b}")
        worst_y = max(worst_y, np.abs(ds["y"].values[:, ia] + ds["y"].values[:, ib] - 0.1).max())
        worst_v = max(worst_v, np.abs(ds["v_y"].values[:, ia] + ds["v_y"].values[:, ib]).max())
        worst_v = max(worst_v, np.abs(ds["v_x"].values[:, ia] - ds["v_x"].values[:, ib]).max())
        worst_v = max(worst_v, 0.01 * np.abs(ds["omega"].values[:, ia] + ds["omega"].values[:, ib]).max())
    vmax = np.abs(ds["v_x"].values).max()
    assert vmax > 0.1
    # the initial positions are mirror images to 1 ulp (0.05 - 0.04 != 0.1 - 0.09 in binary);
    # friction amplifies such round-off, measured: 1.4e-14 m and 8e-11 vmax at 0.4 ms
    assert worst_y < 1e-12
    assert worst_v < 1e-9 * vmax


def test_sliding_disc_reaches_rolling_at_five_sevenths():
    """A sphere sliding without spin on a rigid wall under a constant normal load rolls at
    v = 5/7 v0: friction changes m v by -f dt and I w by R f dt, so m v R + I w is invariant
    (eq. 1 applies friction at lever arm R). The tanh law leaves a slip decaying like
    exp(-t / t_s) with t_s = m_eff / (mu k_s N) ~ 0.2 us, gone after 1 ms: measured 7e-15."""
    R, F, v0 = 0.005, 50.0, 1.0
    wall = Wall((-1.0, 0.0), (1.0, 0.0), (0.0, 1.0), "", "floor")
    law = ContactLaw(mu=0.3, alpha_n=0.05, k_s=100.0)
    system = make_system([("d", 0.0, R, R)], law=law, walls=[wall],
                         excitations=[Excitation(0, (0.0, -1.0), constant_force(F))])
    A = 4 / 3 * 200e9 / (1 - 0.09) * np.sqrt(R)
    delta_eq = (F / A) ** (2 / 3)
    system.pos0[0, 1] = R - delta_eq  # start at the static overlap
    state = initial_state(system, [[v0, 0.0]])
    stepper = Stepper(system)
    stepper.advance(state, 1e-7, 10000)  # 1 ms; sliding ends after (2/7) v0 m / (mu F) = 0.078 ms
    vx, w = state.vel[0, 0], state.omega[0]
    assert vx == pytest.approx(5 / 7 * v0, rel=1e-9)
    assert -w * R == pytest.approx(vx, rel=1e-9)  # rolling: no slip left


def test_stiff_friction_is_substepped():
    """k_s = 1e5: at 40 ns plain RK4 is far outside its stability region in the stick phases
    (sliding decays at mu k_s |N| / m_eff ~ 1e10 /s) and chatters; sub-steps keep (13) closed."""
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', "contact.k_s=1e5", 'simulation.duration="0.03ms"'])
    ds = run_scenario(sc)
    w = ds["input_work"].values.max()
    assert np.abs(ds["balance_error"].values).max() < 1e-6 * w
    system, state, _ = S.build_granular(sc)
    plain = Stepper(system)  # no sub-steps
    plain.advance(state, 4e-8, 750)
    assert abs(state.dissipated_viscous + state.dissipated_friction + plain.medium_energy(state).sum() - state.input_work) > 1e-5 * w


@pytest.mark.parametrize("granule, speed", [("LSGM:3", 1.0), ("SSGM:C", 0.3)])
def test_outer_wall_bounce_is_elastic_when_undamped(granule, speed):
    """The paper's outer wall (MODEL.md sec. 1: rigid, E* = E/(1-nu^2), R* = R, m* = m): the shocked
    granule thrown outward at it, with damping and friction off, bounces back with its speed, keeps
    its energy through the contact, and reaches the Hertz overlap of a rigid flat."""
    raw, _ = S.load_raw("paper")
    raw["contact"].update(alpha_n=0.0, mu=0.0)
    raw["solid"]["kind"] = "rigid"
    raw["excitations"] = []
    system0 = S.build_granular(S.validate(raw))[0]
    side = 1.0 if system0.index(granule) < 14 else -1.0  # LSGM is left of the solid: outward is -x
    raw["initial_velocities"] = [{"granule": granule, "v": [-side * speed, 0.0]}]
    system, state, _ = S.build_granular(S.validate(raw))
    g = system.index(granule)
    wall = next(w for w in system.walls if w.name == f"{granule.split(':')[0]}:outer")
    R, m = system.radius[g], system.mass[g]
    A = 4 / 3 * 200e9 / (1 - 0.3**2) * np.sqrt(R)
    dmax = (5 * m * speed**2 / (4 * A)) ** 0.4
    tc = 2.94328 * dmax / speed
    stepper = Stepper(system)
    e0 = sum(x.sum() for x in stepper.energies(state))
    overlap = lambda: R - side * (state.pos[g, 0] - wall.p0[0])  # noqa: E731
    peak, energies, dt = 0.0, [], tc / 4000
    for _ in range(6000):
        stepper.advance(state, dt, 1)
        d = overlap()
        peak = max(peak, d)
        energies.append(sum(x.sum() for x in stepper.energies(state)))
        if peak > 0 and d < 0:
            break
    assert peak == pytest.approx(dmax, rel=1e-6)  # measured 4e-11
    assert np.abs(np.array(energies) - e0).max() < 1e-9 * e0  # measured 1.7e-10
    assert side * state.vel[g, 0] == pytest.approx(speed, rel=1e-9)  # back toward the solid; measured 3e-11
    assert state.t == pytest.approx(tc, rel=2e-3)
