"""The static equilibrium (`granular.static`) at scale and against statics done by hand: long
chains converge in a few Newton iterations to Hertz's overlaps, a three-bead pyramid between
walls carries the textbook forces, a medium free to slide is named with its direction, and a
Newton that cannot finish says so with exit code 3."""

import math
import re

import numpy as np
import pytest

from granel import scenario as S
from granel.granular.static import NoEquilibrium, NotConverged, equilibrium
from granel.granular.system import Stepper
from granel.guard.exits import STOPPED, USAGE

from test_narrowband import chain_scenario

E, NU, R = 200e9, 0.3, 0.005
A_PAIR = 4 / 3 * E / (2 * (1 - NU**2)) * math.sqrt(R / 2)  # eq. 2 between two equal steel beads
A_WALL = 4 / 3 * E / (1 - NU**2) * math.sqrt(R)  # a steel bead on a rigid wall


@pytest.mark.parametrize("n", [10, 60, 200, 1000])
def test_long_chains_reach_hertz_overlaps_in_a_few_iterations(tmp_path, n):
    """A chain of n beads pressed by 10 N against a wall: every contact carries the load, at
    Hertz's overlap (F / A)^(2/3). Each granule is balanced within its round-off bound (reported as
    `equilibrium_tolerance_N`), so the force on the k-th contact from the loaded end is good to k
    times that, and an overlap, a difference of coordinates as large as the chain (2 R n), to an
    ulp of them: its relative error holds the force to 3/2 of it. The secant predictor puts every
    contact within a factor of its overlap, from where Newton converges quadratically: 53 bits
    take at most 6 doublings, whatever n (before it, 60 beads did not converge in 200)."""
    F0 = 10.0
    problem = S.build_problem(S.load(str(chain_scenario(tmp_path, n=n, preload=F0))))
    eq = problem.equilibrium
    assert eq["equilibrium_loaded_pairs"] == n - 1 and eq["equilibrium_loaded_walls"] == 1
    assert eq["equilibrium_residual_N"] <= eq["equilibrium_tolerance_N"]
    assert eq["equilibrium_iterations"] <= 1 + 6
    d_pair = (F0 / A_PAIR) ** (2 / 3)
    resolution = np.spacing(2 * R * n) / d_pair
    force_tol = n * eq["equilibrium_tolerance_N"] / F0 + 1.5 * resolution
    x = problem.state.pos[:, 0]
    overlaps = 2 * R - np.diff(x)
    np.testing.assert_allclose(A_PAIR * overlaps**1.5, F0, rtol=force_tol)
    np.testing.assert_allclose(overlaps, d_pair, rtol=2 / 3 * force_tol + resolution)
    assert eq["equilibrium_max_wall_force_N"] == pytest.approx(F0, rel=force_tol)


def _pyramid(tmp_path, load=30.0, tilt=0.0):
    """Two steel beads on a floor between two walls that touch them, a third in their groove;
    a load on the top bead, down (tilted by `tilt` toward +x)."""
    h = math.sqrt(3) * R
    rows = ["label,x,y,radius", f"1,{-R!r},0.0,{R}", f"2,{R!r},0.0,{R}", f"3,0.0,{h!r},{R}"]
    (tmp_path / "pyr.csv").write_text("\n".join(rows) + "\n")
    walls = [((-2 * R, -R), (2 * R, -R), (0.0, 1.0), "floor"), ((-2 * R, -R), (-2 * R, 3 * R), (1.0, 0.0), "left"),
             ((2 * R, -R), (2 * R, 3 * R), (-1.0, 0.0), "right")]
    text = "".join(f"""[[walls]]
p0 = [{p0[0]!r}, {p0[1]!r}]
p1 = [{p1[0]!r}, {p1[1]!r}]
normal = [{nw[0]}, {nw[1]}]
name = "{name}"
""" for p0, p1, nw, name in walls)
    (tmp_path / "pyr.toml").write_text(f"""name = "pyramid"
[simulation]
duration = "10us"
equilibrate = true
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "P"
side = "none"
granules_file = "pyr.csv"
radius = {R}
{text}[[excitations]]
granule = "P:3"
kind = "constant"
value = {load!r}
direction = [{math.sin(tilt)!r}, {-math.cos(tilt)!r}]
""")
    return S.load(str(tmp_path / "pyr.toml"))


def test_a_pyramid_carries_the_forces_of_statics(tmp_path):
    """A load P down on the top bead of a pyramid of three between walls (frictionless): by
    symmetry and the balance of each bead, each inclined contact carries P / (2 cos t), each bottom
    bead presses the floor with P / 2 and its side wall with P tan(t) / 2, where t is the inclined
    contacts' angle from the vertical, 30 degrees before the overlaps open it (by about their size
    over R, 1e-4). Checked at the equilibrium's own angle to its round-off (a force good to the
    tolerance over P), and at 30 degrees to the geometric change (Hertz overlap over R)."""
    P = 30.0
    sc = _pyramid(tmp_path, P)
    problem = S.build_problem(sc)
    eq = problem.equilibrium
    names, force, _ = problem.equilibrium_contacts
    f = dict(zip(names, force))
    pos = problem.state.pos
    d = pos[2] - pos[0]
    t = math.atan2(abs(d[0]), d[1])
    tol = 4 * eq["equilibrium_tolerance_N"] / P  # four balances add up to a contact's force
    assert f["P:1-P:3"] == pytest.approx(P / (2 * math.cos(t)), rel=tol)
    assert f["P:2-P:3"] == pytest.approx(P / (2 * math.cos(t)), rel=tol)
    assert f["P:1|floor"] == pytest.approx(P / 2, rel=tol) and f["P:2|floor"] == pytest.approx(P / 2, rel=tol)
    assert f["P:1|left"] == pytest.approx(P * math.tan(t) / 2, rel=tol)
    assert f["P:2|right"] == pytest.approx(P * math.tan(t) / 2, rel=tol)
    assert "P:1-P:2" not in f  # the bottom beads part: the walls, not each other, hold them
    geometric = 4 * (P / A_PAIR) ** (2 / 3) / R  # the angle's change, a few overlaps over R
    assert abs(t - math.pi / 6) < geometric
    assert f["P:1-P:3"] == pytest.approx(P / math.sqrt(3), rel=2 * geometric)


def test_a_frictionless_medium_free_to_slide_is_named_with_its_direction(tmp_path):
    """A tilted load on the pyramid's top bead pushes the whole pyramid sideways: the walls hold
    it. Remove them and the bottom beads slide on the frictionless floor: no equilibrium, and the
    error names the beads and the direction (+x, the load's side), exit 2."""
    sc = _pyramid(tmp_path, 30.0, tilt=0.3)
    S.build_problem(sc)  # held by the walls
    text = (tmp_path / "pyr.toml").read_text()
    blocks = text.split("[[walls]]")
    floor = [b for b in blocks if 'name = "floor"' in b][0]
    (tmp_path / "pyr.toml").write_text(blocks[0] + "[[walls]]" + floor.split("[[excitations]]")[0]
                                       + "[[excitations]]" + text.split("[[excitations]]")[1])
    with pytest.raises(S.ScenarioError) as err:
        S.build_problem(S.load(str(tmp_path / "pyr.toml")))
    message = str(err.value)
    assert err.value.code == USAGE and message.startswith("simulation.equilibrate: no equilibrium")
    direction = [float(v) for v in re.search(r"along \(([^,]+), ([^)]+)\)", message).groups()]
    assert direction[0] > 0.99  # along +x, the floor's tangent
    assert "P:" in message


def test_a_bead_pushed_along_a_wall_is_free_along_it(tmp_path):
    """A bead on a frictionless wall pushed obliquely into it: the wall takes the normal part, the
    tangential one has nothing to hold it; named with the direction along the wall."""
    path = chain_scenario(tmp_path, n=1)
    path.write_text(path.read_text().replace("direction = [1.0, 0.0]", "direction = [1.0, 0.5]"))
    with pytest.raises(S.ScenarioError, match=r"no equilibrium: the loads push C:1 along \(\S+, 1\)") as err:
        S.build_problem(S.load(str(path)))
    assert err.value.code == USAGE


def test_a_newton_that_cannot_finish_says_so(tmp_path):
    """Out of iterations on a medium that is held: NotConverged names the worst granule, its
    imbalance and its round-off bound, and through a scenario it is exit 3 (a numerical stop, not
    bad input)."""
    sc = S.load(str(chain_scenario(tmp_path, n=30)))
    sc_off = S.load(str(chain_scenario(tmp_path, n=30)), ["simulation.equilibrate=false"])
    system = S.build_problem(sc_off).system
    with pytest.raises(NotConverged, match=r"did not converge in \d+ Newton iterations: granule C:\d+ is still off "
                                            r"balance by .* above its round-off bound"):
        equilibrium(system, Stepper(system).model, max_iterations=0)
    import granel.granular.static as static

    original = static.equilibrium
    try:
        static.equilibrium = lambda *a, **k: original(*a, **{**k, "max_iterations": 0})
        with pytest.raises(S.ScenarioError, match="simulation.equilibrate: the static equilibrium did not") as err:
            S.build_problem(sc)
    finally:
        static.equilibrium = original
    assert err.value.code == STOPPED
    assert issubclass(NotConverged, ValueError) and not issubclass(NotConverged, NoEquilibrium)
