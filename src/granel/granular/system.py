"""The assembled granular system: arrays for the compiled kernels, neighbour lists, stepping.

`GranularSystem` is static data (granules, walls, contact law, solid contact points,
excitations); `GranularState` is the evolving state. `advance` is a pure-ish function that
moves a state forward by RK4 steps, rebuilding the neighbour list when granules have moved
more than half the skin distance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..excitation import KIND_CODES, LoadHistory
from ..materials import (
    damping_coefficient,
    effective_mass,
    effective_modulus,
    effective_radius,
    hertz_coefficient,
    sphere_inertia,
    sphere_mass,
)
from . import kernels
from .packing import Medium, Wall


@dataclass(frozen=True)
class ContactLaw:
    """Parameters of eqs. (2)-(5): friction coefficient, Tsuji damping, tanh smoothness."""

    mu: float = 0.099
    alpha_n: float = 6.313e-3
    k_s: float = 100.0  # [s/m]


@dataclass(frozen=True)
class SolidContact:
    """A contact point of a granule with a solid's edge (a massless rigid layer, m* = 0).

    `normal` is n_ik: from the granule centre toward the solid. The point moves with the
    solid; `E_solid`/`nu_solid` give E* (None = rigid layer: E* = E_g / (1 - nu_g^2)).
    """

    granule: int
    point: tuple[float, float]
    normal: tuple[float, float]
    name: str = ""


@dataclass(frozen=True)
class Excitation:
    granule: int
    direction: tuple[float, float]
    history: LoadHistory


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
    # derived arrays
    wall_p0: np.ndarray = field(init=False)
    wall_dir: np.ndarray = field(init=False)
    wall_len: np.ndarray = field(init=False)
    wall_n: np.ndarray = field(init=False)
    wall_medium: np.ndarray = field(init=False)
    sg: np.ndarray = field(init=False)
    sp: np.ndarray = field(init=False)
    sn: np.ndarray = field(init=False)
    sA: np.ndarray = field(init=False)
    sG: np.ndarray = field(init=False)

    def __post_init__(self):
        n = len(self.labels)
        if self.skin <= 0.0:
            self.skin = 0.1 * float(self.radius.min()) if n else 1e-3
        nw = len(self.walls)
        self.wall_p0 = np.zeros((nw, 2))
        self.wall_dir = np.zeros((nw, 2))
        self.wall_len = np.zeros(nw)
        self.wall_n = np.zeros((nw, 2))
        self.wall_medium = np.full(nw, -1, dtype=np.int64)
        for k, w in enumerate(self.walls):
            p0 = np.asarray(w.p0, float)
            d = np.asarray(w.p1, float) - p0
            L = float(np.hypot(*d))
            self.wall_p0[k] = p0
            self.wall_dir[k] = d / L
            self.wall_len[k] = L
            nn = np.asarray(w.normal, float)
            self.wall_n[k] = nn / np.hypot(*nn)
            if w.medium:
                self.wall_medium[k] = self.media.index(w.medium)
        nc = len(self.solid_contacts)
        self.sg = np.array([c.granule for c in self.solid_contacts], dtype=np.int64)
        self.sp = np.array([c.point for c in self.solid_contacts], float).reshape(nc, 2)
        self.sn = np.array([c.normal for c in self.solid_contacts], float).reshape(nc, 2)
        self.sn /= np.maximum(np.hypot(self.sn[:, 0], self.sn[:, 1]), 1e-300)[:, None]
        # granule-solid law: rigid massless layer, E* = E/(1-nu^2), R* = R, m* = 0 (no damping)
        self.sA = np.array([hertz_coefficient(effective_modulus(self.E[g], self.nu[g]), self.radius[g]) for g in self.sg])
        self.sG = np.zeros(nc)

    @property
    def n(self) -> int:
        return len(self.labels)

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
    labels, mi, pos, rad, E, nu, rho, walls = [], [], [], [], [], [], [], []
    for k, m in enumerate(media):
        labels += [f"{m.name}:{lab}" for lab in m.labels]
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
    )


@dataclass
class GranularState:
    """y: the augmented state vector (see kernels); t: time [s]."""

    y: np.ndarray
    t: float = 0.0

    @property
    def n(self) -> int:
        return (len(self.y) - 3) // 6

    @property
    def pos(self) -> np.ndarray:
        return self.y[: 2 * self.n].reshape(-1, 2)

    @property
    def theta(self) -> np.ndarray:
        return self.y[2 * self.n : 3 * self.n]

    @property
    def vel(self) -> np.ndarray:
        return self.y[3 * self.n : 5 * self.n].reshape(-1, 2)

    @property
    def omega(self) -> np.ndarray:
        return self.y[5 * self.n : 6 * self.n]

    @property
    def dissipated_viscous(self) -> float:
        return float(self.y[6 * self.n + kernels.ACC_VISC])

    @property
    def dissipated_friction(self) -> float:
        return float(self.y[6 * self.n + kernels.ACC_FRIC])

    @property
    def input_work(self) -> float:
        return float(self.y[6 * self.n + kernels.ACC_WORK])


def initial_state(system: GranularSystem, velocities=None, spins=None) -> GranularState:
    n = system.n
    y = np.zeros(6 * n + 3)
    y[: 2 * n] = system.pos0.ravel()
    if velocities is not None:
        y[3 * n : 5 * n] = np.asarray(velocities, float).ravel()
    if spins is not None:
        y[5 * n : 6 * n] = np.asarray(spins, float)
    return GranularState(y, 0.0)


@dataclass
class NeighbourList:
    """Candidate contacts within `skin` of touching, with their Hertz/damping coefficients."""

    ref_pos: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    pA: np.ndarray
    pG: np.ndarray
    wg: np.ndarray
    ww: np.ndarray
    wA: np.ndarray
    wG: np.ndarray


def build_neighbours(system: GranularSystem, pos: np.ndarray) -> NeighbourList:
    """Pairs whose surfaces are closer than the skin (KD-tree), and granule-wall candidates."""
    n = system.n
    R = system.radius
    skin = system.skin
    law = system.law
    if n > 1:
        tree = cKDTree(pos)
        pairs = tree.query_pairs(2.0 * R.max() + skin, output_type="ndarray")
    else:
        pairs = np.zeros((0, 2), dtype=np.int64)
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        d = np.hypot(*(pos[j] - pos[i]).T)
        keep = (d < R[i] + R[j] + skin) & (system.medium_index[i] == system.medium_index[j])
        i, j = i[keep], j[keep]
        order = np.lexsort((j, i))
        i, j = i[order].astype(np.int64), j[order].astype(np.int64)
    else:
        i = j = np.zeros(0, dtype=np.int64)
    inv_E = (1 - system.nu[i] ** 2) / system.E[i] + (1 - system.nu[j] ** 2) / system.E[j]
    Rs = R[i] * R[j] / (R[i] + R[j])
    pA = 4.0 / 3.0 / inv_E * np.sqrt(Rs)
    ms = system.mass[i] * system.mass[j] / (system.mass[i] + system.mass[j])
    pG = law.alpha_n * np.sqrt(ms * pA)
    # walls
    wg, ww = [], []
    for k in range(len(system.walls)):
        r = pos - system.wall_p0[k]
        along = r @ system.wall_dir[k]
        h = r @ system.wall_n[k]
        ok = (h < R + skin) & (h > -R) & (along > -skin) & (along < system.wall_len[k] + skin)
        if system.wall_medium[k] >= 0:
            ok &= system.medium_index == system.wall_medium[k]
        idx = np.flatnonzero(ok)
        wg += idx.tolist()
        ww += [k] * len(idx)
    wg = np.array(wg, dtype=np.int64)
    ww = np.array(ww, dtype=np.int64)
    wA = np.array([hertz_coefficient(effective_modulus(system.E[g], system.nu[g]), effective_radius(R[g])) for g in wg])
    wG = np.array([damping_coefficient(law.alpha_n, effective_mass(system.mass[g], None), a) for g, a in zip(wg, wA)])
    return NeighbourList(pos.copy(), i, j, pA, pG, wg, ww, wA.reshape(-1), wG.reshape(-1))


@dataclass
class ExcitationArrays:
    eg: np.ndarray
    edir: np.ndarray
    ekind: np.ndarray
    epar: np.ndarray
    eoff: np.ndarray
    tab_t: np.ndarray
    tab_v: np.ndarray


def excitation_arrays(excitations: list[Excitation]) -> ExcitationArrays:
    ne = len(excitations)
    eg = np.array([e.granule for e in excitations], dtype=np.int64)
    edir = np.zeros((ne, 2))
    ekind = np.zeros(ne, dtype=np.int64)
    epar = np.zeros((ne, 4))
    eoff = np.zeros(ne + 1, dtype=np.int64)
    tt, tv = [], []
    for k, e in enumerate(excitations):
        d = np.asarray(e.direction, float)
        edir[k] = d / np.hypot(*d)
        ekind[k] = KIND_CODES[e.history.kind]
        p = list(e.history.params)[:4]
        epar[k, : len(p)] = p
        tt.append(np.asarray(e.history.times, float))
        tv.append(np.asarray(e.history.values, float))
        eoff[k + 1] = eoff[k] + len(e.history.times)
    cat = lambda a: np.concatenate(a) if a else np.zeros(0)  # noqa: E731
    return ExcitationArrays(eg, edir, ekind, epar, eoff, cat(tt), cat(tv))


class NonFiniteStateError(RuntimeError):
    """Raised when the integration produces NaN or inf; carries a diagnosis."""


@dataclass
class Stepper:
    """Binds a system to its compiled-kernel arrays and advances states by RK4 steps."""

    system: GranularSystem
    nl: NeighbourList = None
    ex: ExcitationArrays = None
    rebuilds: int = 0
    substep: bool = False  # split steps into RK4 sub-steps where the friction is stiff (large k_s)

    def __post_init__(self):
        self.nl = build_neighbours(self.system, self.system.pos0)
        self.ex = excitation_arrays(self.system.excitations)
        nc = len(self.system.solid_contacts)
        self._zero = np.zeros((nc, 2))

    def advance(self, state: GranularState, dt: float, nsteps: int, su0=None, sv0=None, sa=None) -> GranularState:
        """Advance `state` in place by nsteps RK4 steps; the solid contact points follow
        u(tau) = su0 + sv0 tau + sa tau^2 / 2 within each step (zero for a rigid solid)."""
        s = self.system
        z = self._zero
        su0 = z if su0 is None else su0
        sv0 = z if sv0 is None else sv0
        sa = z if sa is None else sa
        done = 0
        while done < nsteps:
            nl = self.nl
            ex = self.ex
            kernel = kernels.rk4_advance_substepped if self.substep else kernels.rk4_advance
            k = kernel(
                state.y, state.t, dt, nsteps - done, s.n, nl.ref_pos, 0.5 * s.skin,
                s.radius, s.mass, s.inertia, s.law.mu, s.law.k_s,
                nl.pi, nl.pj, nl.pA, nl.pG,
                nl.wg, nl.ww, nl.wA, nl.wG, s.wall_p0, s.wall_dir, s.wall_len, s.wall_n,
                s.sg, s.sp, s.sn, s.sA, s.sG, su0, sv0, sa,
                ex.eg, ex.edir, ex.ekind, ex.epar, ex.eoff, ex.tab_t, ex.tab_v,
            )
            if k < 0:
                steps_ok = -k - 2
                state.t += steps_ok * dt
                raise NonFiniteStateError(
                    f"granular state became non-finite at t = {state.t:.6e} s (step size {dt:.3e} s): "
                    "the step is too large for the contact stiffness or the friction smoothness k_s; "
                    "reduce dt"
                )
            state.t += k * dt
            done += k
            moved = np.max(np.abs(state.pos - nl.ref_pos), initial=0.0)
            if moved >= 0.5 * s.skin / np.sqrt(2.0):
                # a granule moved (nearly) half a skin: refresh the candidate contacts
                self.nl = build_neighbours(s, state.pos.copy())
                self.rebuilds += 1
        return state

    def energies(self, state: GranularState, su=None):
        s, nl = self.system, self.nl
        su = self._zero if su is None else su
        return kernels.granule_energies(
            state.y, s.n, s.radius, s.mass, s.inertia,
            nl.pi, nl.pj, nl.pA, nl.wg, nl.ww, nl.wA, s.wall_p0, s.wall_dir, s.wall_len, s.wall_n,
            s.sg, s.sp, s.sn, s.sA, su,
        )

    def medium_energy(self, state: GranularState, su=None) -> np.ndarray:
        """Energy of each medium, eq. (11): shape (n_media,)."""
        kin, rot, pot = self.energies(state, su)
        e = kin + rot + pot
        return np.bincount(self.system.medium_index, weights=e, minlength=len(self.system.media))

    def solid_contact_state(self, state: GranularState, su=None, sv=None):
        s = self.system
        su = self._zero if su is None else su
        sv = self._zero if sv is None else sv
        return kernels.solid_contact_state(state.y, s.n, s.radius, s.law.mu, s.law.k_s, s.sg, s.sp, s.sn, s.sA, s.sG, su, sv)
