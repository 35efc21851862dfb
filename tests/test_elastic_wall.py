"""An undamped (elastic) wall through every layer: the scenario's choice (`[[walls]] damped`, a
medium's `undamped_walls`), the built system's contact coefficients, a run (a sphere thrown at
the wall bounces back with its speed, and nothing is dissipated), the result's model record
(results without `wall_damped` read as damped) and bad input. The impact itself against Hertz's
closed form: tests/test_hertz_impact.py (`test_an_undamped_wall_is_elastic`)."""

import math

import numpy as np
import pytest

from granel import scenario as S
from granel.analysis.result_model import result_system
from granel.granular.system import build_neighbours
from granel.io.model import read_record
from granel.run import run_scenario

from test_exact import ledger_bound

R, V = 0.005, 1.0


def thrown_at_a_wall(tmp_path, damped: bool, alpha_n: float = 0.5):
    """A 5 mm steel sphere 10 um from a wall, thrown at it at V, no friction, Tsuji damping alpha_n
    in the contact law, no solid; 0.2 ms (the contact lasts about 21 us)."""
    (tmp_path / "one.csv").write_text(f"label,x,y,radius\n1,{0.01 - R - 1e-5!r},0.0,{R!r}\n")
    (tmp_path / "wall.toml").write_text(f"""name = "thrown"
[simulation]
duration = "0.2ms"
output_every = "1us"
[contact]
mu = 0.0
alpha_n = {alpha_n!r}
[solid]
kind = "none"
[[media]]
name = "M"
side = "none"
granules_file = "one.csv"
[[walls]]
p0 = [0.01, -0.02]
p1 = [0.01, 0.02]
normal = [-1.0, 0.0]
name = "w"
damped = {str(damped).lower()}
[[initial_velocities]]
granule = "M:1"
v = [{V!r}, 0.0]
""")
    return S.load(str(tmp_path / "wall.toml"))


def test_a_sphere_bounces_off_an_undamped_wall_with_its_energy(tmp_path):
    """Through the whole run: the undamped wall's contact has G = 0 (the built system and the one
    rebuilt from the result alike), no viscous work is done at any output, and the sphere leaves
    with its kinetic energy to within the bound the error-controlled integrator holds the energy
    balance (13) to (`ledger_bound`; measured 2e-8 of the speed). The result records the wall as
    undamped. The same wall damped takes energy (restitution 0.486 at alpha_n = 0.5)."""
    sc = thrown_at_a_wall(tmp_path, damped=False)
    ds = run_scenario(sc)
    m = float(ds["granule_mass"].values[0])
    v_end = float(ds["v_x"].values[-1, 0])
    print(f"rebound {-v_end:.10f} m/s, viscous work {np.abs(ds['dissipated_viscous'].values).max():.1e} J")
    assert v_end < 0  # it came back
    assert abs(0.5 * m * (v_end**2 - V**2)) <= ledger_bound(ds, sc)
    assert np.all(ds["dissipated_viscous"].values == 0.0)
    assert list(ds["wall_damped"].values) == [0]
    assert read_record(ds).walls[0].damped is False
    for system in (S.build_granular(sc, sc.base)[0], result_system(ds)):
        assert system.walls[0].damped is False
        assert list(build_neighbours(system, system.pos0).walls.G) == [0.0]
    damped = run_scenario(thrown_at_a_wall(tmp_path, damped=True))
    assert list(damped["wall_damped"].values) == [1]
    assert damped["dissipated_viscous"].values[-1] > 0.1 * 0.5 * m * V**2
    assert -damped["v_x"].values[-1, 0] < 0.9 * V


def test_results_without_the_field_read_as_damped(tmp_path):
    """A result of an earlier granel has no `wall_damped`: its walls read as damped, so it
    rebuilds the system it ran (G > 0 at its wall)."""
    ds = run_scenario(thrown_at_a_wall(tmp_path, damped=True)).drop_vars("wall_damped")
    assert read_record(ds).walls[0].damped is True
    system = result_system(ds)
    assert system.walls[0].damped is True and build_neighbours(system, system.pos0).walls.G[0] > 0


def test_a_medium_names_its_undamped_walls():
    """`undamped_walls` on a built medium: those walls lose their dashpot (G = 0 for every
    candidate contact), the others keep it (G = alpha_n sqrt(m A), eq. 3, with m* = m)."""
    sc = S.load("paper", ['media.0.undamped_walls=["top", "outer"]', "media.0.outer_wall=true"])
    system = S.build_granular(sc, sc.base)[0]
    damped = {w.name: w.damped for w in system.walls}
    assert damped == {"LSGM:bottom": True, "LSGM:top": False, "LSGM:outer": False, "SSGM:bottom": True,
                      "SSGM:top": True, "SSGM:outer": True}
    walls = build_neighbours(system, system.pos0).walls
    names = [system.walls[w].name for w in walls.w]
    for name, G, A, g in zip(names, walls.G, walls.A, walls.g):
        want = 0.0 if not damped[name] else sc.contact.alpha_n * math.sqrt(system.mass[g] * A)
        assert G == pytest.approx(want, rel=4 * np.finfo(float).eps), name


@pytest.mark.parametrize("overrides, needle", [
    (['walls.0.damped="no"'], "walls.0.damped = 'no': a boolean"),
    (["walls.0.damped=0.5"], "walls.0.damped = 0.5: a boolean"),
    (['media.0.undamped_walls=["outer"]'], "undamped_walls: a medium from granules_file has no walls"),
])
def test_bad_wall_damping_is_refused_naming_the_field(tmp_path, overrides, needle):
    thrown_at_a_wall(tmp_path, damped=False)
    with pytest.raises(S.ScenarioError) as e:
        S.load(str(tmp_path / "wall.toml"), overrides)
    assert needle in str(e.value), str(e.value)


@pytest.mark.parametrize("overrides, needle", [
    (['media.0.undamped_walls=["left"]'], "undamped_walls: 'left' is not one of the medium's walls"),
    (['media.0.undamped_walls=["top", "top"]'], "names a wall twice"),
    (['media.0.undamped_walls=["sideways"]'], "media.0.undamped_walls.0"),
])
def test_bad_undamped_walls_are_refused(overrides, needle):
    with pytest.raises(S.ScenarioError) as e:
        S.load("paper", overrides)
    assert needle in str(e.value), str(e.value)
