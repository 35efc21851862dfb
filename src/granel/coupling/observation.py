"""What every solver records at an output, written once: the energy ledger (13), and the
observation record (granules, the energies of eqs. 11-13, the interface forces, the force on each
wall, the deepest overlap) built from the outputs' states in one compiled pass."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from ..granular.bundles import state_views
from ..granular.kernels import granule_energies, gravity_energy, overlaps, wall_forces
from ..guard.jit import njit
from ..solid.modal import mode_energy


@njit(cache=True, inline="always")
def energy_ledger(e_solid, e_granular, dissipated_viscous, dissipated_friction, input_work):
    """E_solid + E_granular + D - W, eq. (13) (E_granular with the granules' gravitational potential): constant in time for an exact solution (scalars or
    arrays; from Python, `energy_ledger.py_func` does the same arithmetic with numpy, without
    compiling or loading a kernel for each array layout)."""
    return e_solid + e_granular + (dissipated_viscous + dissipated_friction) - input_work


@njit(cache=True)
def granular_energy(y, model, su):
    """E_granular of eq. (11), the granules' kinetic, rotational and contact energy, with the solid
    contact points displaced by su (nc, 2), plus their gravitational potential (`gravity_energy`):
    the granular share of the ledger (13)."""
    kin, rot, pot = granule_energies(y, model, su)
    return kin.sum() + rot.sum() + pot.sum() + gravity_energy(y, model.granules)


@njit(cache=True)
def modal_energy(eta, etad, omega):
    """The solid's kinetic and strain energy (eq. 11): `solid.modal.mode_energy` (eq. 15) summed
    over the modes."""
    kinetic = 0.0
    potential = 0.0
    for i in range(eta.shape[0]):
        k, p = mode_energy(eta[i], etad[i], omega[i])
        kinetic += k
        potential += p
    return kinetic, potential


class OutputQuantities(NamedTuple):
    """Filled by `output_quantities` for a batch of K outputs."""

    media: np.ndarray  # (K, n_media) each medium's energy (11)
    granular: np.ndarray  # (K,) all granules' energy (11)
    gravity: np.ndarray  # (K,) their gravitational potential energy
    overlap: np.ndarray  # (K,) the deepest overlap over the smaller radius ...
    where: np.ndarray  # (K, 2) int: ... at which kind of contact (0 pair, 1 wall, 2 solid) and index
    walls: np.ndarray  # (K, n_walls, 2): the force each wall takes


def output_buffers(K: int, n_media: int, n_walls: int) -> OutputQuantities:
    return OutputQuantities(media=np.zeros((K, n_media)), granular=np.zeros(K), gravity=np.zeros(K), overlap=np.zeros(K),
                            where=np.zeros((K, 2), np.int64), walls=np.zeros((K, n_walls, 2)))


@njit(cache=True)
def output_quantities(Y, su, model, medium, times, q):
    """Per output o of a batch (granular states Y (K, ny), solid contact points displaced by su
    (K, nc, 2), at `times`): each medium's energy (11) and their sum, the deepest overlap (eq. 2)
    over the smaller radius with its kind and index, and the force on each wall."""
    radius = model.granules.radius
    pairs, walls, points = model.pairs, model.walls, model.points
    for o in range(Y.shape[0]):
        kin, rot, pot = granule_energies(Y[o], model, su[o])
        q.media[o, :] = 0.0
        for i in range(kin.shape[0]):
            q.media[o, medium[i]] += kin[i] + rot[i] + pot[i]
        q.granular[o] = kin.sum() + rot.sum() + pot.sum()
        q.gravity[o] = gravity_energy(Y[o], model.granules)
        dp, dw, ds = overlaps(Y[o], model, su[o])
        best, kind, idx = 0.0, -1, -1
        for c in range(dp.shape[0]):
            r = dp[c] / min(radius[pairs.i[c]], radius[pairs.j[c]])
            if r > best:
                best, kind, idx = r, 0, c
        for c in range(dw.shape[0]):
            r = dw[c] / radius[walls.g[c]]
            if r > best:
                best, kind, idx = r, 1, c
        for c in range(ds.shape[0]):
            r = ds[c] / radius[points.g[c]]
            if r > best:
                best, kind, idx = r, 2, c
        q.overlap[o] = best
        q.where[o, 0] = kind
        q.where[o, 1] = idx
        wall_forces(Y[o], model, q.walls[o], times[o])


class _Labels:
    """Where the deepest overlaps are, as words, made only when one is read (a guard's message)."""

    def __init__(self, label, n):
        self._label, self._n = label, n

    def __getitem__(self, i):
        return self._label(i)

    def __len__(self):
        return self._n


@dataclass(frozen=True)
class Observation:
    """A block of outputs (first axis: the output) as every solver reports them: the granules,
    each medium's energy, the solid's energy, the accumulated dissipation and input work, the
    ledger (13), the interface forces along each contact's normal and tangent, the force each wall
    takes, and the deepest overlap with where it is."""

    times: np.ndarray
    pos: np.ndarray  # (K, n, 2)
    theta: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    energy_media: np.ndarray  # (K, n_media)
    energy_gravity: np.ndarray  # (K,) the granules' gravitational potential (`granular.kernels.gravity_energy`)
    energy_solid: np.ndarray
    energy_solid_kinetic: np.ndarray
    energy_solid_potential: np.ndarray
    dissipated_viscous: np.ndarray
    dissipated_friction: np.ndarray
    input_work: np.ndarray
    ledger: np.ndarray  # E + D - W, eq. (13)
    force_normal: np.ndarray  # (K, nc)
    force_tangential: np.ndarray
    wall_force: np.ndarray  # (K, n_walls, 2)
    overlap_ratio: np.ndarray
    overlap_at: object  # labels of the deepest overlaps, by output

    def __len__(self) -> int:
        return len(self.times)

    def recorded(self, ledger0: float) -> dict:
        """The arrays a trajectory records, the ledger as the balance error against its initial
        value ledger0."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("times", "ledger", "overlap_ratio",
                                                                                      "overlap_at")}
        out["balance_error"] = self.ledger - ledger0
        return out

    def row(self, i: int) -> "Observation":
        """Output i alone, as a block of one."""
        return Observation(**{f.name: (_Labels(lambda _, i=i: self.overlap_at[i], 1) if f.name == "overlap_at"
                                       else getattr(self, f.name)[i: i + 1]) for f in fields(self)})


class OutputStates(NamedTuple):
    """The states of a block of K outputs: their times (K,), the granular states y (K, ny), the
    solid contact points' displacement su (K, nc, 2), the solid's (kinetic, potential) energy
    (K, 2) and the interface forces on the solid F (K, nc, 2)."""

    times: object
    y: np.ndarray
    su: np.ndarray
    solid_energy: np.ndarray
    F: np.ndarray


def observe_outputs(states: OutputStates, system, model, normals, tangents) -> Observation:
    """The observation of a block of outputs from their states; `model` is the compiled bundle the
    states were computed with, `system` names the contacts, `normals` and `tangents` (nc, 2) are
    the contact frame the interface forces are resolved in."""
    from ..granular.system import contact_label

    times, Y = np.array(states.times, float), np.array(states.y, float)  # copies: a solver may step its arrays on
    su, solid_energy, F = states.su, states.solid_energy, states.F
    K, n = len(times), system.n
    q = output_buffers(K, len(system.media), len(system.walls))
    output_quantities(Y, np.ascontiguousarray(su, float), model, system.medium_index, times, q)
    ek, ep = solid_energy[:, 0], solid_energy[:, 1]
    v = state_views(Y, n)
    dv, df, w = v.dissipated_viscous, v.dissipated_friction, v.input_work
    where = q.where
    ledger = energy_ledger.py_func(ek + ep, q.granular + q.gravity, dv, df, w)  # numpy's arithmetic, no kernel per layout
    return Observation(times=times, pos=v.pos, theta=v.theta, vel=v.vel, omega=v.spin, energy_media=q.media,
                       energy_gravity=q.gravity,
                       energy_solid=ek + ep, energy_solid_kinetic=ek, energy_solid_potential=ep, dissipated_viscous=dv,
                       dissipated_friction=df, input_work=w, ledger=ledger,
                       force_normal=np.einsum("kij,ij->ki", F, normals), force_tangential=np.einsum("kij,ij->ki", F, tangents),
                       wall_force=q.walls, overlap_ratio=q.overlap,
                       overlap_at=_Labels(lambda i: contact_label(system, model, int(where[i, 0]), int(where[i, 1])), K))
