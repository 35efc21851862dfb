"""Coupled solvers on the compiled core: built objects in (granular system, solid model, settings),
a `Trajectory` out through the one driver (`coupling.driver`).

The two methods differ only in the core's strategies:
  fast   Newton on the interface forces at dtau0, a failed step retried at half the step;
  paper  the paper's algorithm: fixed point (A4) and the step halved by (B1) until
         max |lambda| <= 1/2 at every contact (Appendices A and B).
Both run the solid in modal coordinates with all modes (Newmark (A2), identical to the sparse
Newmark to round-off); a rigid solid has no modes. Solids beyond `solid.modal.DENSE_LIMIT` DOFs
use `coupling.sparse`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..granular.bundles import ACC_FRIC, ACC_VISC, ACC_WORK, Motion
from ..granular.kernels import rhs
from ..granular.system import GranularSystem, GranularState, Stepper, contact_label
from ..solid.base import SolidModel
from ..solid.modal import at_dofs
from . import core

METHODS = ("fast", "paper")
LOG_CAPACITY = 65536


@dataclass(frozen=True)
class SolverSettings:
    """The coupled solver's method and its numbers (the scenario's [simulation] table)."""

    method: str = "fast"  # fast | paper
    dt: float = 4e-8  # dtau0; the fixed step of a non-adaptive run
    halvings: int = 12  # the smallest step is dt / 2^halvings
    lambda_max: float = 0.5  # (B1)
    abstol: float = 1e-6  # (A4) [N]
    reltol: float = 1e-6
    max_iterations: int = 50
    integrator: str = "exact"  # the fast method's solid integrator: exact (modal, polynomial force) | newmark
    force_model: str = "quadratic"  # the exact integrator's force over a step: quadratic | linear
    adaptive: bool = True  # the exact integrator's error-controlled steps (False: every step is dt)
    rtol: float = 1e-5  # local error tolerance of the adaptive step, relative to v_ref
    atol: float = 1e-9  # [m/s]
    max_step: float = 1e-6  # [s]
    mode_cutoff: float | str = "auto"  # [Hz]: eigenmodes above are replaced by residual modes ("auto": run.auto_mode_cutoff)
    ledger_tol: float = 8e-7  # the energy balance (13) stays within this share of the largest load's energy

    def config(self, max_disp: float) -> core.CoupledConfig:
        paper = self.method == "paper"
        return core.CoupledConfig(float(self.dt), int(self.halvings), core.POLICY_B1 if paper else core.POLICY_CONSTANT,
                                  float(self.lambda_max), not paper, float(self.abstol), float(self.reltol),
                                  int(self.max_iterations), not paper, float(max_disp))


def static_modes(force, P, w2, nc):
    """The interface forces (nc, 2) and the modes' static displacement eta = W^-2 P' F under a
    preload `force` (None: none), with P the contacts' modal matrix and w2 the squared frequencies."""
    F = np.zeros((nc, 2)) if force is None else np.array(force, float).reshape(nc, 2)
    eta = (P.T @ F.ravel()) / w2 if len(w2) else np.zeros(0)
    return F, eta


class SolverError(RuntimeError):
    """The coupled step failed (no convergence, or a non-finite state); the message says where and why."""


def step_log(nc: int) -> core.StepLog:
    """An empty per-step log of LOG_CAPACITY steps for nc contacts (the compiled loops fill it)."""
    return core.StepLog(np.zeros(LOG_CAPACITY), np.zeros(LOG_CAPACITY), np.zeros(LOG_CAPACITY, np.int64),
                        np.zeros((LOG_CAPACITY, nc)))


def contact_frame(system: GranularSystem, model: SolidModel) -> core.ContactFrame:
    tangents = np.array([[-c.normal[1], c.normal[0]] for c in system.solid_contacts], float).reshape(-1, 2)
    has_t = np.array([c.dof_y >= 0 for c in model.contacts], bool)
    return core.ContactFrame(tangents, has_t, model.ndof == 0)


class ModalSolver:
    """The compiled core with the solid in modal coordinates (all modes; none for a rigid solid).

    The driver calls `start` (or `load`), then `advance(k)` to each output k, `observe` and
    `solid_snapshot` there, and `save` for checkpoints."""

    def __init__(self, system: GranularSystem, state0: GranularState, model: SolidModel, settings: SolverSettings,
                 outputs_every: int, modes=None):
        self.system, self.model, self.settings = system, model, settings
        self.y0 = state0.y.copy()
        self.stepper = Stepper(system, substep=True)
        nc = len(system.solid_contacts)
        frame = contact_frame(system, model)
        if model.ndof:
            P = at_dofs(model.contact_map(), modes.shapes)
            w2 = modes.omega**2
        else:
            P, w2 = np.zeros((2 * nc, 0)), np.zeros(0)
        self.modes = modes
        self.solid = core.ModalSolid(w2, P, frame)
        H = settings.halvings
        self.cache = core.StepCache(np.zeros(H + 1, bool), np.zeros((H + 1, len(w2))), np.zeros((H + 1, 2 * nc, 2 * nc)),
                                    np.zeros((H + 1, nc)))
        self.cfg = settings.config(self.stepper.max_disp)
        self.per_ticks = outputs_every * 2**H  # ticks between outputs
        self.log = step_log(nc)

    @property
    def name(self) -> str:
        return self.settings.method

    # ------------------------------------------------------------ state
    solid_force0 = None  # (nc, 2) static forces on the solid at t = 0 (a preload), set by run.make_solver

    def start(self) -> None:
        nm, nc = len(self.solid.w2), len(self.system.solid_contacts)
        z = lambda k: np.zeros(k)  # noqa: E731
        F0, eta0 = static_modes(self.solid_force0, self.solid.P, self.solid.w2, nc)
        self.st = core.CoupledState(y=self.y0.copy(), eta=eta0, etad=z(nm), etaa=z(nm), F=F0, u=self.solid.P @ eta0,
                                    v=z(2 * nc), a=z(2 * nc), normal=z(nc), vrel=z(nc), clock=core.new_clock())

    def save(self) -> dict:
        out = {f"st:{k}": np.asarray(v) for k, v in self.st._asdict().items()}
        out["ref_pos"] = self.stepper.nl.ref_pos
        return out

    def load(self, arrays: dict) -> None:
        arrays = core.upgraded_state(arrays)
        self.st = core.CoupledState(**{k: np.array(arrays[f"st:{k}"]) for k in core.CoupledState._fields})
        self.stepper.refresh(arrays["ref_pos"])

    @property
    def t(self) -> float:
        return float(self.st.clock[0]["t"])

    # ------------------------------------------------------------ stepping
    def advance(self, k: int, trajectory) -> None:
        """Accepted steps up to output k (time k * output interval); steps are logged in `trajectory`."""
        st = self.st
        st.clock[0]["forced"] = 0  # back to dtau0 at each output interval
        target = k * self.per_ticks
        while True:
            status, m = core.advance_modal(st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache, self.cfg,
                                           target, self.log)
            if m:
                trajectory.log_steps(self.log.t[:m], self.log.h[:m], self.log.iterations[:m], self.log.lam[:m])
            if status == core.DONE:
                return
            if status == core.REBUILD:
                self.stepper.rebuild(st.y[: 2 * self.system.n].reshape(-1, 2))
            elif status in (core.NO_CONVERGENCE, core.NON_FINITE):
                raise SolverError(self._diagnosis(status))

    def _diagnosis(self, status: int) -> str:
        s, st = self.settings, self.st
        h = s.dt / 2 ** max(int(st.clock[0]["level"]), int(st.clock[0]["forced"]))
        if status == core.NON_FINITE:
            return (f"t = {self.t:.6e} s: the granular state became non-finite at dt = {h:.3e} s; reduce simulation.dt "
                    "or lower contact.k_s")
        if s.method == "paper":
            return (f"t = {self.t:.6e} s: interface forces did not converge in {s.max_iterations} iterations, or (B1) "
                    f"needed more than {s.halvings} halvings of {s.dt:.3e} s; raise simulation.max_iterations or "
                    "simulation.max_halvings, loosen abstol/reltol, or lower k_s")
        return (f"t = {self.t:.6e} s: Newton on the interface forces did not converge even at dt = {h:.3e} s "
                f"({s.halvings} halvings of {s.dt:.3e} s); reduce simulation.dt, raise simulation.max_halvings or "
                "simulation.max_iterations, or lower k_s")

    # ------------------------------------------------------------ what the driver records
    def contact_motion(self):
        nc = len(self.system.solid_contacts)
        return self.st.u.reshape(nc, 2)

    def solid_energies(self) -> tuple[float, float]:
        """(kinetic, potential) of the solid, eq. (11), from the modal state."""
        st = self.st
        return 0.5 * float(st.etad @ st.etad), 0.5 * float(st.eta @ (self.solid.w2 * st.eta))

    def solid_snapshot(self) -> dict:
        return {"eta": self.st.eta.astype(np.float32), "eta_dot": self.st.etad.astype(np.float32)}

    def observe(self) -> dict:
        return observation(self.stepper, GranularState(self.st.y, self.t), self.contact_motion(), self.solid_energies(),
                           self.st.F, self.solid.frame.tangent, self.system)

    def attributes(self) -> dict:
        s = self.settings
        return {"name": s.method, "dt0": s.dt, "abstol": s.abstol, "reltol": s.reltol, "lambda_max": s.lambda_max,
                "max_halvings": s.halvings, "neighbour_rebuilds": self.stepper.rebuilds, "solid_representation": "modal"}


def observation(stepper: Stepper, g: GranularState, su, solid_energy, F, tangents, system) -> dict:
    """One output of eqs. (11)-(13): the granules, each medium's energy, the solid's energy, the
    dissipated and input work, the balance error, and the forces on the solid at its contacts."""
    em = stepper.medium_energy(g, su)
    ek, ep = solid_energy
    dv, df, w = g.dissipated_viscous, g.dissipated_friction, g.input_work
    normals = np.array([c.normal for c in system.solid_contacts], float).reshape(-1, 2)
    ratio, where = stepper.deepest_overlap(g, su)
    # balance_error: the ledger E + D - W here; the driver subtracts its initial value (eq. 13)
    return {"pos": g.pos.copy(), "theta": g.theta.copy(), "vel": g.vel.copy(), "omega": g.omega.copy(), "energy_media": em,
            "energy_solid": ek + ep, "energy_solid_kinetic": ek, "energy_solid_potential": ep, "dissipated_viscous": dv,
            "dissipated_friction": df, "input_work": w, "balance_error": ek + ep + em.sum() + dv + df - w,
            "force_normal": np.einsum("ij,ij->i", F, normals), "force_tangential": np.einsum("ij,ij->i", F, tangents),
            "wall_force": stepper.wall_forces(g), "overlap_ratio": ratio, "overlap_at": where}


def residual_modes(model: SolidModel, B, shapes, keep, omega, partial: bool = False, at_contacts=None):
    """Residual modes of the dropped modes at the contacts: Rayleigh-Ritz on their static shapes
    Psi = K^-1 B' - Phi W^-2 P' (the retained modes' part removed, so Psi is M-orthogonal to them).
    Psi' K Psi = R and B Psi = R, so the residual modes' static compliance at the contacts is R
    exactly, and they carry the inertia of those shapes. Returns (omega_r, P_r = B Phi_r, Z, Psi)
    with Phi_r = Psi Z; shapes that vanish (a beam's tangential DOFs) are left out.

    `partial`: `shapes` holds only the modes below the cut-off (every one of them is kept), and
    K^-1 B' comes from a sparse factorisation. Otherwise the basis is complete and `at_contacts`
    = (P, P_d, omega_d), the retained and dropped modes at the contacts, is enough: Psi = Phi_d W_d^-2 P_d', so
    R = P_d W_d^-2 P_d' and Psi' M Psi = P_d W_d^-4 P_d' (mass-normalised modes), with no
    factorisation and no read of the shapes; Psi is then returned as None (nothing needs it)."""
    from scipy.linalg import eigh

    m2 = B.shape[0]
    if np.all(keep) and not partial:
        return np.zeros(0), np.zeros((m2, 0)), np.zeros((m2, 0)), np.zeros((model.ndof, 0))
    if partial:
        from scipy.sparse.linalg import splu

        Psi = splu(model.K.tocsc()).solve(B.T.toarray())
        full = np.abs(np.diag(B @ Psi)).max()  # the largest static compliance at a contact
        nk = int(np.count_nonzero(keep))
        # the modes ascend, so the retained ones are the first columns: a slice reads a
        # memory-mapped matrix only that far along each row
        Phi = np.asarray(shapes[:, :nk]) if np.all(keep[:nk]) else np.asarray(shapes[:, keep])
        Psi -= Phi @ ((B @ Phi).T / omega[:, None] ** 2)
        R = B @ Psi  # B K^-1 B' - P W^-2 P': the dropped modes' static compliance at the contacts
        mass = Psi.T @ (model.M @ Psi)
    else:
        P_k, P_d, omega_d = at_contacts
        Psi = None
        R = (P_d / omega_d**2) @ P_d.T
        mass = (P_d / omega_d**4) @ P_d.T
        full = np.abs(np.diag(R) + np.einsum("ij,ij->i", P_k / omega**2, P_k)).max()
    R = 0.5 * (R + R.T)
    # the shapes the contacts feel: R's range (a beam's tangential DOFs feel none)
    lam, V = np.linalg.eigh(R)
    V = V[:, lam > 1e-12 * full]
    G = V.T @ mass @ V
    lam, U = np.linalg.eigh(0.5 * (G + G.T))
    ok = lam > 1e-12 * lam.max() if lam.size else lam > 0
    U = V @ (U[:, ok] / np.sqrt(lam[ok]))  # Psi U: M-orthonormal
    w2, Y = eigh(U.T @ R @ U)
    Z = U @ Y
    return np.sqrt(np.maximum(w2, 0.0)), np.ascontiguousarray(R @ Z), Z, Psi
