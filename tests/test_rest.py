"""A medium that nothing loads stays exactly at rest (issue 28).

Packings are built touching: hexagonal columns, chains of beads, against their walls and the
solid's face. Spaced exactly by their radii, round-off left some of those contacts overlapping by
about 1e-18 m in the kernels' own arithmetic, and their Hertz forces set an unloaded medium moving
at about 1e-19 m/s. `granular.packing` now spaces each lattice so that every contact clears in
floating point (`packing.CLEARANCE`), so an unloaded run has no force at all and Newton's first
law holds exactly: the velocities are 0.0 at every output, not merely small.

The overlaps are computed by the compiled kernels themselves (`kernels.pair_overlap`,
`wall_overlap`, `point_overlap`) over every candidate of the neighbour list the run would use.
"""

import numpy as np
import pytest

from granel import scenario as S
from granel.granular import kernels
from granel.granular.system import build_neighbours
from granel.scenario.build import build_granular

CHAIN = "scenarios/designs/cutoff-chain.toml"
UNLOADED = ["excitations=[]", "simulation.equilibrate=false"]


def _box(grow: str) -> list[str]:
    """The paper's SSGM away from any solid, grown from a face line it touches (gap 0), closed by
    all four walls."""
    channel = '"left", "right"' if grow in ("up", "down") else '"bottom", "top"'
    return ["paper", 'solid.kind="none"', "media.0=-", 'media.0.side="none"', f'media.0.grow="{grow}"',
            f'media.0.walls=[{channel}, "outer", "face"]', "media.0.outer_wall=-", "excitations=[]"]


GEOMETRIES = {
    "paper-plate": ["paper", "excitations=[]"],  # both hexagonal media, walls and the plate's faces
    "paper-rigid": ["paper", "excitations=[]", 'solid.kind="rigid"'],
    "paper-beam": ["paper", "excitations=[]", 'solid.kind="beam"'],
    "box-right": _box("right"),
    "box-left": _box("left"),
    "box-up": _box("up"),
    "box-down": _box("down"),
    "chain-wall": [CHAIN, *UNLOADED],  # eight beads on the face wall
    "chain-walls": [CHAIN, *UNLOADED, 'media.0.walls=["face", "outer"]',  # mixed radii between two walls
                    "media.0.radii=[0.005, 0.003, 0.0041, 0.0077, 0.002, 0.005]"],
    "chain-down": [CHAIN, *UNLOADED, 'media.0.grow="down"', "media.0.face_y=0.137",
                   'media.0.walls=["face", "outer"]', "media.0.radii=[0.0031, 0.0052, 0.0044]"],
    "chain-solid": ["paper", "excitations=[]", "media.1=-", "media.0.radii=[0.01, 0.007, 0.0093, 0.01]",
                    "media.0.columns=-", "media.0.radius=-", 'media.0.walls=["outer"]', "media.0.channel_walls=-",
                    "media.0.outer_wall=-", "media.0.labels=-"],
}


def _scenario(spec: list[str]) -> S.Scenario:
    return S.load(spec[0], spec[1:])


@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_every_contact_of_a_built_packing_clears_in_floating_point(name):
    """Every pair, wall and solid-point candidate of the built packing has an overlap <= 0 as the
    compiled kernels compute it, while the packing's touching contacts (within 1e-12 m of touching)
    are there to be tested: the lattice is touching, not loose."""
    sc = _scenario(GEOMETRIES[name])
    system, state, _ = build_granular(sc, sc.base)
    y, R = state.y, system.radius
    nl = build_neighbours(system, system.pos0)
    pairs = np.array([kernels.pair_overlap(y, i, j, R)[3] for i, j in zip(nl.pairs.i, nl.pairs.j)])
    walls = np.array([kernels.wall_overlap(y, g, w, R, nl.walls) for g, w in zip(nl.walls.g, nl.walls.w)])
    points = np.array([kernels.point_overlap(y, g, c, R, system.points, 0.0, 0.0)
                       for c, g in enumerate(system.points.g)])
    every = np.concatenate([pairs, walls, points])
    assert every.size and np.all(every <= 0.0), every.max()
    touching = every[every > -1e-12]
    assert (pairs > -1e-12).sum() >= system.n - 1 and touching.size > (pairs > -1e-12).sum()  # walls or face too
    if name.startswith("paper") or name == "chain-solid":
        assert (points > -1e-12).sum() == len(points) > 0  # column 0 touches the solid's face


@pytest.mark.parametrize("name", ["paper-plate", "paper-rigid", "box-up", "chain-walls", "chain-solid"])
def test_an_unloaded_medium_stays_exactly_at_rest(name):
    """No load, no initial motion: every output's velocities, spins, positions and energies are
    exactly the initial ones (0.0 for the motion), with the plate or the rigid solid beside the
    paper's media, a medium in its box and chains between walls or on the solid."""
    from granel.run import run_scenario

    ds = run_scenario(_scenario(GEOMETRIES[name] + ['simulation.duration="0.1ms"']))
    assert ds.sizes["time"] > 50  # every output of 0.1 ms (1 or 2 us apart)
    for v in ("v_x", "v_y", "omega"):
        assert np.all(ds[v].values == 0.0), (v, np.abs(ds[v].values).max())
    for v in ("x", "y", "theta"):
        assert np.all(ds[v].values == ds[v].values[0]), v
    for v in [f"energy_{m.lower()}" for m in dict.fromkeys(ds["medium"].values)] + ["energy_solid", "input_work"]:
        assert np.all(ds[v].values == 0.0), v
