"""The assembled granular system: static data, the evolving state, neighbour lists, stepping.

`GranularSystem` is static data (granules, walls, contact law, solid contact points, loads) and
hands the compiled kernels their bundles (`granular.bundles`); `GranularState` is the evolving
state; `Stepper` moves a state forward by RK4 steps, rebuilding the neighbour list when granules
have moved more than half the skin distance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .loads import LOAD_PARAMS, LoadHistory
from .materials import Body, pair_coefficients, point_coefficient, sphere_inertia, sphere_mass, wall_coefficients
from . import kernels
from .bundles import GranularModel, Granules, Law, Loads, Motion, Pairs, Points, StateViews, Walls, state_size, \
    state_views, still
from .neighbours import close_pairs
from .packing import Medium, Wall


@dataclass(frozen=True)
class ContactLaw:
    """Parameters of eqs. (2)-(5): friction coefficient, Tsuji damping, tanh smoothness."""

    mu: float = 0.099
    alpha_n: float = 6.313e-3
    k_s: float = 100.0  # [s/m]


@dataclass(frozen=True)
class SolidContact:
    """A contact point of a granule with a solid's edge (a massless rigid layer, m* = 0:
    E* = E_g / (1 - nu_g^2), R* = R_g, no damping). `normal` is n_ik: from the granule centre
    toward the solid. The point moves with the solid."""

    granule: int
    point: tuple[float, float]
    normal: tuple[float, float]
    name: str = ""


@dataclass(frozen=True)
class Excitation:
    granule: int
    direction: tuple[float, float]
    history: LoadHistory
    toward: int = 0  # the direction as given: +1 toward the solid, -1 away from it, 0 a vector


# the unit vector toward the solid from a medium on each side of it
MEDIUM_TOWARD_SOLID = {"left": (1.0, 0.0), "right": (-1.0, 0.0)}


@dataclass
class GranularSystem:
    labels: list[str]
    medium_index: np.ndarray  # (n,) int
    media: list[str]
    pos0: np.ndarray  # (n, 2)
    radius: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    E: np.ndarray
    nu: np.ndarray
    law: ContactLaw
    walls: list[Wall]
    solid_contacts: list[SolidContact]
    excitations: list[Excitation]
    skin: float = 0.0
    toward_solid: np.ndarray | None = None  # (n, 2) unit vectors toward the solid (NaN: a medium away from it)
    strikers: tuple[int, ...] = ()  # the granules given an initial motion, in the scenario's order
    gravity: tuple[float, float] = (0.0, 0.0)  # the acceleration of gravity in the plane [m/s^2]
    # derived: the bundles the kernels read
    wall_geometry: tuple = field(init=False)  # (p0, tangent, length, normal, medium index) per wall
    points: Points = field(init=False)
    loads: Loads = field(init=False)

    def __post_init__(self):
        n = len(self.labels)
        if self.skin <= 0.0:
            self.skin = 0.1 * float(self.radius.min()) if n else 1e-3
        if self.toward_solid is None:
            self.toward_solid = np.full((n, 2), np.nan)
        self.wall_geometry = wall_geometry(self.walls, self.media)
        nc = len(self.solid_contacts)
        g = np.array([c.granule for c in self.solid_contacts], dtype=np.int64)
        nrm = np.array([c.normal for c in self.solid_contacts], float).reshape(nc, 2)
        nrm /= np.maximum(np.hypot(nrm[:, 0], nrm[:, 1]), 1e-300)[:, None]
        A = np.asarray(point_coefficient(self.bodies(g)), float).reshape(nc)
        self.points = Points(g, np.array([c.point for c in self.solid_contacts], float).reshape(nc, 2), nrm, A, np.zeros(nc))
        self.loads = load_bundle(self.excitations)

    @property
    def granules(self) -> Granules:
        return Granules(self.radius, self.mass, self.inertia, self.weights, np.asarray(self.pos0, float).reshape(-1, 2))

    @property
    def weights(self) -> np.ndarray:
        """(n, 2) each granule's weight m g [N]."""
        return np.asarray(self.mass, float)[:, None] * np.asarray(self.gravity, float)[None, :]

    @property
    def has_gravity(self) -> bool:
        return bool(np.any(np.asarray(self.gravity, float) != 0.0))

    def with_solid_contacts_moved(self, offsets: np.ndarray) -> None:
        """Move the solid contact points' rest positions by `offsets` (nc, 2) [m] (the solid's sag
        under its own weight), in place."""
        self.solid_contacts = [SolidContact(c.granule, (float(c.point[0] + d[0]), float(c.point[1] + d[1])), c.normal,
                                            c.name) for c, d in zip(self.solid_contacts, np.asarray(offsets, float))]
        self.points = self.points._replace(p=np.array([c.point for c in self.solid_contacts], float).reshape(-1, 2))

    @property
    def contact_law(self) -> Law:
        return Law(float(self.law.mu), float(self.law.k_s))

    @property
    def n(self) -> int:
        return len(self.labels)

    def bodies(self, index) -> Body:
        """The granules `index` (an index or an array of them) as contacts see them."""
        return Body(self.E[index], self.nu[index], self.radius[index], self.mass[index])

    def index(self, label: str) -> int:
        try:
            return self.labels.index(label)
        except ValueError:
            raise KeyError(f"unknown granule label {label!r}; known: {', '.join(self.labels)}") from None

    def medium_members(self, name: str) -> np.ndarray:
        return np.flatnonzero(self.medium_index == self.media.index(name))


def build_system(
    media: list[Medium],
    law: ContactLaw,
    solid_contacts: list[SolidContact] | None = None,
    excitations: list[Excitation] | None = None,
    extra_walls: list[Wall] | None = None,
) -> GranularSystem:
    labels, mi, pos, rad, E, nu, rho, walls, toward = [], [], [], [], [], [], [], [], []
    for k, m in enumerate(media):
        labels += [f"{m.name}:{lab}" for lab in m.labels]
        toward += [MEDIUM_TOWARD_SOLID.get(m.side, (np.nan, np.nan))] * m.n
        mi += [k] * m.n
        pos.append(m.pos)
        rad.append(m.radius)
        mats = m.materials()
        E += [x.E for x in mats]
        nu += [x.nu for x in mats]
        rho += [x.rho for x in mats]
        walls += m.walls
    walls += list(extra_walls or [])
    rad = np.concatenate(rad) if rad else np.zeros(0)
    mass = np.array([sphere_mass(r, d) for r, d in zip(rad, rho)])
    inertia = np.array([sphere_inertia(m, r) for m, r in zip(mass, rad)])
    return GranularSystem(
        labels=labels,
        medium_index=np.array(mi, dtype=np.int64),
        media=[m.name for m in media],
        pos0=np.vstack(pos) if pos else np.zeros((0, 2)),
        radius=rad,
        mass=mass,
        inertia=inertia,
        E=np.array(E, float),
        nu=np.array(nu, float),
        law=law,
        walls=walls,
        solid_contacts=list(solid_contacts or []),
        excitations=list(excitations or []),
        toward_solid=np.array(toward, float).reshape(-1, 2),
    )


@dataclass
class GranularState:
    """y: the augmented state vector (layout in `granular.bundles`); t: time [s]."""

    y: np.ndarray
    t: float = 0.0

    @property
    def n(self) -> int:
        return (len(self.y) - 3) // 6

    @property
    def views(self) -> StateViews:
        return state_views(self.y, self.n)

    @property
    def pos(self) -> np.ndarray:
        return self.views.pos

    @property
    def theta(self) -> np.ndarray:
        return self.views.theta

    @property
    def vel(self) -> np.ndarray:
        return self.views.vel

    @property
    def omega(self) -> np.ndarray:
        return self.views.spin

    @property
    def dissipated_viscous(self) -> float:
        return float(self.views.dissipated_viscous)

    @property
    def dissipated_friction(self) -> float:
        return float(self.views.dissipated_friction)

    @property
    def input_work(self) -> float:
        return float(self.views.input_work)


def initial_state(system: GranularSystem, velocities=None, spins=None) -> GranularState:
    n = system.n
    y = np.zeros(state_size(n))
    v = state_views(y, n)
    v.pos[:] = system.pos0
    if velocities is not None:
        v.vel[:] = np.asarray(velocities, float).reshape(n, 2)
    if spins is not None:
        v.spin[:] = np.asarray(spins, float)
    return GranularState(y, 0.0)


def wall_geometry(walls: list[Wall], media: list[str]):
    """(p0, unit tangent, length, unit normal, medium index or -1, drive) arrays of the walls;
    drive (nw, 6) holds a moving wall's `WallDrive.params` (zeros for a wall at rest)."""
    nw = len(walls)
    p0, tan, length, nrm = np.zeros((nw, 2)), np.zeros((nw, 2)), np.zeros(nw), np.zeros((nw, 2))
    medium = np.full(nw, -1, dtype=np.int64)
    drive = np.zeros((nw, 6))
    for k, w in enumerate(walls):
        if w.drive is not None:
            drive[k] = w.drive.params()
        p0[k] = w.p0
        d = np.asarray(w.p1, float) - p0[k]
        length[k] = float(np.hypot(*d))
        tan[k] = d / length[k]
        nrm[k] = np.asarray(w.normal, float) / np.hypot(*w.normal)
        if w.medium:
            medium[k] = media.index(w.medium)
    return p0, tan, length, nrm, medium, drive


@dataclass
class NeighbourList:
    """Candidate contacts within `skin` of touching (pairs and granule-wall), with their Hertz and
    damping coefficients, found around the positions `ref_pos`."""

    ref_pos: np.ndarray
    pairs: Pairs
    walls: Walls


def build_neighbours(system: GranularSystem, pos: np.ndarray) -> NeighbourList:
    """Pairs whose surfaces are closer than the skin (KD-tree), and granule-wall candidates."""
    R = system.radius
    skin = system.skin
    law = system.law
    pairs = close_pairs(pos, 2.0 * R.max() + skin)
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        d = np.hypot(*(pos[j] - pos[i]).T)
        keep = (d < R[i] + R[j] + skin) & (system.medium_index[i] == system.medium_index[j])
        i, j = i[keep], j[keep]
        order = np.lexsort((j, i))
        i, j = i[order].astype(np.int64), j[order].astype(np.int64)
    else:
        i = j = np.zeros(0, dtype=np.int64)
    pA, pG = pair_coefficients(system.bodies(i), system.bodies(j), law.alpha_n)
    p0, tan, length, nrm, medium, drive = system.wall_geometry
    wg, ww = [], []
    for k in range(len(length)):
        r = pos - p0[k]
        along = r @ tan[k]
        h = r @ nrm[k]
        reach = abs(drive[k, 0])  # a moving wall comes this much closer
        ok = (h < R + skin + reach) & (h > -R - reach) & (along > -skin) & (along < length[k] + skin)
        if medium[k] >= 0:
            ok &= system.medium_index == medium[k]
        idx = np.flatnonzero(ok)
        wg += idx.tolist()
        ww += [k] * len(idx)
    wg = np.array(wg, dtype=np.int64)
    damped = np.array([w.damped for w in system.walls], bool)[np.array(ww, dtype=np.int64)]
    wA, wG = wall_coefficients(system.bodies(wg), law.alpha_n, damped)
    walls = Walls(wg, np.array(ww, dtype=np.int64), wA, wG, p0, tan, length, nrm, drive)
    return NeighbourList(pos.copy(), Pairs(i, j, pA, pG), walls)


def load_bundle(excitations: list[Excitation]) -> Loads:
    """The applied loads as compiled-kernel arrays (each history's `code` and `params`)."""
    ne = len(excitations)
    direction = np.zeros((ne, 2))
    kind = np.zeros(ne, dtype=np.int64)
    params = np.zeros((ne, LOAD_PARAMS))
    offset = np.zeros(ne + 1, dtype=np.int64)
    tt, tv = [], []
    for k, e in enumerate(excitations):
        d = np.asarray(e.direction, float)
        direction[k] = d / np.hypot(*d)
        kind[k] = e.history.code
        p = list(e.history.params)[:LOAD_PARAMS]
        params[k, : len(p)] = p
        tt.append(np.asarray(e.history.times, float))
        tv.append(np.asarray(e.history.values, float))
        offset[k + 1] = offset[k] + len(e.history.times)
    cat = lambda a: np.concatenate(a) if a else np.zeros(0)  # noqa: E731
    return Loads(np.array([e.granule for e in excitations], dtype=np.int64), direction, kind, params, offset, cat(tt), cat(tv))


def contact_label(system: GranularSystem, model: GranularModel, kind: int, k: int) -> str:
    """Who touches at candidate contact k of a kind (0 granule pair, 1 granule-wall, 2 granule-solid
    point; -1 none), for messages."""
    lab = system.labels
    if kind == 0:
        return f"granules {lab[model.pairs.i[k]]} and {lab[model.pairs.j[k]]}"
    if kind == 1:
        return f"granule {lab[model.walls.g[k]]} and wall {int(model.walls.w[k])}"
    if kind == 2:
        return f"granule {lab[model.points.g[k]]} and the solid"
    return ""


class NonFiniteStateError(RuntimeError):
    """Raised when the integration produces NaN or inf; carries a diagnosis."""


class Stepper:
    """Binds a system to its neighbour list and advances states by RK4 steps; the current
    `model` bundle is what every compiled kernel reads."""

    def __init__(self, system: GranularSystem, substep: bool = False, pos=None):
        self.system = system
        self.substep = substep  # split steps into RK4 sub-steps where the friction is stiff (large k_s)
        self.rebuilds = 0
        self.refresh(system.pos0 if pos is None else pos)
        self.still = still(len(system.solid_contacts))  # the contact points at rest

    def refresh(self, pos) -> None:
        """New candidate contacts around `pos`."""
        s = self.system
        self.nl = build_neighbours(s, np.array(pos, float).reshape(-1, 2))
        self.model = GranularModel(s.granules, s.contact_law, self.nl.pairs, self.nl.walls, s.points, s.loads)

    def maybe_refresh(self, pos) -> bool:
        """Rebuild the neighbour list if a granule moved (nearly) half a skin from its reference."""
        if np.max(np.abs(pos - self.nl.ref_pos), initial=0.0) >= 0.5 * self.system.skin / np.sqrt(2.0):
            self.rebuild(pos)
            return True
        return False

    def rebuild(self, pos) -> None:
        """A new neighbour list around `pos`, counted (a granule moved far)."""
        self.refresh(pos)
        self.rebuilds += 1

    @property
    def max_disp(self) -> float:
        return 0.5 * self.system.skin

    def advance(self, state: GranularState, dt: float, nsteps: int, motion: Motion | None = None) -> GranularState:
        """Advance `state` in place by nsteps RK4 steps; the solid contact points follow `motion`
        within each step (still for a rigid solid)."""
        motion = self.still if motion is None else motion
        done = 0
        while done < nsteps:
            k = kernels.rk4_advance(state.y, state.t, dt, nsteps - done, self.model, motion, self.nl.ref_pos,
                                    self.max_disp, self.substep)
            if k < 0:
                state.t += (-k - 2) * dt
                raise NonFiniteStateError(
                    f"granular state became non-finite at t = {state.t:.6e} s (step size {dt:.3e} s): "
                    "the step is too large for the contact stiffness or the friction smoothness k_s; reduce dt"
                )
            state.t += k * dt
            done += k
            self.maybe_refresh(state.pos)
        return state

    def energies(self, state: GranularState, su=None):
        """(kinetic, rotational, potential) per granule, eq. (11); solid points displaced by su."""
        su = self.still.u0 if su is None else su
        return kernels.granule_energies(state.y, self.model, su)

    def medium_energy(self, state: GranularState, su=None) -> np.ndarray:
        """Energy of each medium, eq. (11): shape (n_media,)."""
        kin, rot, pot = self.energies(state, su)
        return np.bincount(self.system.medium_index, weights=kin + rot + pot, minlength=len(self.system.media))
