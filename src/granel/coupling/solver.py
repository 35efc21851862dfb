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
from . import core, exact

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


# the exact integrator stops when the energy ledger (13) has drifted by this share of the input
BALANCE_LIMIT = 1e-2
# outputs per compiled call of the exact integrator
OUTPUT_BATCH = 64


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
        self.st = core.CoupledState(self.y0.copy(), eta0, z(nm), z(nm), F0, self.solid.P @ eta0, z(2 * nc), z(2 * nc),
                                    z(nc), z(nc), np.zeros(1), np.zeros(3, np.int64))

    def save(self) -> dict:
        out = {f"st:{k}": np.asarray(v) for k, v in self.st._asdict().items()}
        out["ref_pos"] = self.stepper.nl.ref_pos
        return out

    def load(self, arrays: dict) -> None:
        self.st = core.CoupledState(*[np.array(arrays[f"st:{k}"]) for k in core.CoupledState._fields])
        self.stepper.refresh(arrays["ref_pos"])

    @property
    def t(self) -> float:
        return float(self.st.clock[0])

    # ------------------------------------------------------------ stepping
    def advance(self, k: int, trajectory) -> None:
        """Accepted steps up to output k (time k * output interval); steps are logged in `trajectory`."""
        st = self.st
        st.ticks[2] = 0  # back to dtau0 at each output interval
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
        h = s.dt / 2 ** max(int(st.ticks[1]), int(st.ticks[2]))
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


class _Labels:
    """Labels of a block's outputs, made only when one is read (a guard's message)."""

    def __init__(self, label, n):
        self._label, self._n = label, n

    def __getitem__(self, i):
        return self._label(i)

    def __len__(self):
        return self._n


class ExactSolver:
    """The fast method with the exact modal integrator (`coupling.exact`): the eigenmodes below
    `mode_cutoff` and the residual modes of the dropped ones (their static compliance at the
    contacts) propagated in closed form under an interface force that is a polynomial over the
    step, Newton on the forces at the polynomial's nodes, and error-controlled steps with dense
    output at the output times."""

    def __init__(self, system: GranularSystem, state0: GranularState, model: SolidModel, settings: SolverSettings,
                 schedule, modes=None, v_ref: float = 1.0, e_ref: float = 1.0, kinks=()):
        self.system, self.model, self.settings, self.schedule = system, model, settings, schedule
        self.y0 = state0.y.copy()
        self.stepper = Stepper(system, substep=True)
        nc = len(system.solid_contacts)
        frame = contact_frame(system, model)
        if model.ndof:
            keep = modes.omega <= 2 * np.pi * float(settings.mode_cutoff)
            B = model.contact_map()
            P = at_dofs(B, modes.shapes, keep)
            omega = modes.omega[keep]
            # the dropped modes: their static compliance at the contacts, as residual modes
            self.P_drop = at_dofs(B, modes.shapes, ~keep)
            self.omega_drop = modes.omega[~keep]
            om_r, P_r, self.residual_Z, Psi = residual_modes(model, B, modes.shapes, keep, omega,
                                                             partial=modes.count < model.ndof,
                                                             at_contacts=(P, self.P_drop, self.omega_drop))
            self.kept, self.residual = int(len(omega)), int(len(om_r))
            omega = np.concatenate([omega, om_r])
            P = np.ascontiguousarray(np.hstack([P, P_r]))
            # only the modes below the cut-off are known (a large solid): the solid's state is
            # stored in its reduced nodal coordinates, q = Phi eta + Psi Z q_r
            self.nodal = None if modes.count == model.ndof else (np.asarray(modes.shapes), Psi @ self.residual_Z)
        else:
            P, omega = np.zeros((2 * nc, 0)), np.zeros(0)
            self.kept, self.residual, self.residual_Z, self.nodal = 0, 0, np.zeros((2 * nc, 0)), None
            self.P_drop, self.omega_drop = np.zeros((2 * nc, 0)), np.zeros(0)
        self.modes = modes
        self.solid = exact.ExactSolid(omega, P, frame)
        self.normals = np.array([c.normal for c in system.solid_contacts], float).reshape(-1, 2)
        fixed = not settings.adaptive
        levels = 4 * settings.halvings  # fixed steps use the smaller levels only to retry a failed step
        h_max = settings.dt if fixed else settings.max_step
        self.cache = exact.ops_cache(settings.force_model, levels, len(omega), nc)
        self.cfg = exact.ExactConfig(float(h_max), int(levels), not fixed, float(settings.rtol), float(settings.atol),
                                     float(v_ref), float(e_ref), float(settings.ledger_tol),
                                     BALANCE_LIMIT * float(e_ref), float(schedule.duration), True,
                                     float(settings.abstol), float(settings.reltol),
                                     int(settings.max_iterations), float(self.stepper.max_disp))
        self.kinks = np.array(sorted(k for k in kinks if np.isfinite(k) and k > 0), float)
        self.log = step_log(nc)
        self.t_out, self._k, self._batch = 0.0, 0, None

    @property
    def name(self) -> str:
        return "fast"

    solid_force0 = None  # (nc, 2) static forces on the solid at t = 0 (a preload), set by run.make_solver

    def start(self) -> None:
        nr, nc = len(self.solid.omega), len(self.system.solid_contacts)
        y = self.y0.copy()
        dy = np.zeros_like(y)
        F0, eta0 = static_modes(self.solid_force0, self.solid.P, self.solid.omega**2, nc)
        u0 = self.solid.P @ eta0 if nr else np.zeros(2 * nc)
        still = self.stepper.still
        rhs(0.0, y, dy, self.stepper.model, Motion(u0.reshape(nc, 2), still.v0, still.a, still.j, still.d4, still.d5), 0.0)
        level = 0 if not self.settings.adaptive else int(round(4 * np.log2(self.cfg.h_max / self.settings.dt)))
        self.st = exact.initial_state(y, dy, nr, nc, len(self.cache.nodes), 0.0, max(0, min(level, self.cfg.levels)))
        self.st.eta[:] = eta0
        self.st.F[:, :] = F0
        self.st.q[:] = self.solid.P.T @ F0.ravel() if nr else 0.0
        self.st.u[:] = u0
        self.t_out, self._k = 0.0, 0
        self._single_batch(0, y, eta0, np.zeros(nr), F0)  # the output at t = 0
        q, n = self._batch["q"], self.system.n
        # E_solid + E_granular + D - W (13)
        ledger = float(q.solid[0].sum() + q.media[0].sum()) + y[6 * n] + y[6 * n + 1] - y[6 * n + 2]
        self.st.clock[4] = self.st.clock[5] = ledger

    def save(self) -> dict:
        out = {f"st:{k}": np.asarray(v) for k, v in self.st._asdict().items() if k != "step_motion"}
        out.update({f"motion:{k}": v for k, v in self.st.step_motion._asdict().items()})
        out["ref_pos"] = self.stepper.nl.ref_pos
        out["t_out"] = self.t_out
        return out

    def load(self, arrays: dict) -> None:
        motion = Motion(*[np.array(arrays[f"motion:{k}"]) for k in Motion._fields])
        self.st = exact.ExactState(*[motion if k == "step_motion" else np.array(arrays[f"st:{k}"])
                                           for k in exact.ExactState._fields])
        if len(self.st.clock) < 8:  # an older checkpoint: no running work scale yet
            self.st = self.st._replace(clock=np.append(self.st.clock, np.zeros(8 - len(self.st.clock))))
        self.stepper.refresh(arrays["ref_pos"])
        self.t_out = float(arrays["t_out"])
        self._k, self._batch = int(round(self.t_out / self._target(1))), None

    @property
    def t(self) -> float:
        return self.t_out

    def _target(self, k: int) -> float:
        return k * self.schedule.output_every if self.settings.adaptive else k * self.schedule.per * self.settings.dt

    def advance(self, k: int, trajectory) -> None:
        """To output k. Outputs come in batches of up to OUTPUT_BATCH from one compiled call (the
        steps through them and the state at each by dense output), ending at checkpoint outputs so
        that `save` sees the state of its output; a failure inside a batch is raised when the
        driver asks for an output beyond the last one reached."""
        b = self._batch
        if b is not None and b["k0"] <= k < b["k0"] + b["done"]:
            self._k, self.t_out = k, self._target(k)
            return
        if b is not None and b.get("error") is not None:
            raise b["error"]
        self._run_batch(k, trajectory)
        self._k, self.t_out = k, self._target(k)
        b = self._batch
        if b["done"] == 0:
            raise b["error"]

    def _run_batch(self, k0: int, trajectory) -> None:
        outputs = self.schedule.outputs
        k1 = min(outputs, k0 + OUTPUT_BATCH - 1)
        every = self.schedule.checkpoint_period()
        if every:
            k1 = min(k1, (k0 + every - 1) // every * every)  # a checkpoint output ends the batch
        ks = np.arange(k0, k1 + 1)
        targets = np.array([self._target(int(k)) for k in ks])
        K, nr, nc = len(ks), len(self.solid.omega), len(self.system.solid_contacts)
        out = (np.empty((K, len(self.st.y))), np.empty((K, nr)), np.empty((K, nr)), np.empty((K, nc, 2)))
        done = np.zeros(1, np.int64)
        st, error = self.st, None
        while done[0] < K:
            status, m = exact.advance_outputs(st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache,
                                              self.cfg, targets, self.kinks, self.log, out, done)
            if m:
                trajectory.log_steps(self.log.t[:m], self.log.h[:m], self.log.iterations[:m], self.log.lam[:m])
            if status == core.REBUILD:
                self.stepper.rebuild(st.y[: 2 * self.system.n].reshape(-1, 2))
            elif status in (core.BALANCE_LOST, core.NO_CONVERGENCE, core.NON_FINITE):
                error = SolverError(self._diagnosis(status))
                break
        self._set_batch(k0, int(done[0]), out, error)

    def _set_batch(self, k0: int, n: int, out, error=None) -> None:
        """Outputs k0 .. k0 + n - 1 from their states `out` (y, eta, eta', F), with the
        quantities of eqs. (11)-(13) computed by one compiled call."""
        K, nc = len(out[0]), len(self.system.solid_contacts)
        q = exact.OutputQuantities(np.zeros((K, len(self.system.media))), np.zeros((K, 2)), np.zeros((K, nc, 2)), np.zeros(K),
                                   np.zeros((K, 2), np.int64), np.zeros((K, len(self.system.walls), 2)))
        if n:
            times = np.array([self._target(k0 + j) for j in range(n)])
            exact.output_quantities(out[0][:n], out[1][:n], out[2][:n], self.stepper.model, self.solid,
                                    self.system.medium_index, len(self.system.media), q, times)
        self._batch = {"k0": k0, "done": n, "out": out, "q": q, "error": error, "model": self.stepper.model}

    def _single_batch(self, k: int, y, eta, etad, F) -> None:
        self._set_batch(k, 1, (y[None].copy(), eta[None].copy(), etad[None].copy(), F[None].copy()))

    def _diagnosis(self, status: int) -> str:
        t, h_min = self.st.clock[0], self.cfg.h_max / 2 ** (self.cfg.levels / 4)
        if status == core.BALANCE_LOST:
            return (f"t = {t:.6e} s: the energy balance (13) drifted by more than {BALANCE_LIMIT:g} of the input energy "
                    f"with the error control at its smallest step ({h_min:.3e} s): the results would be wrong. "
                    "Try simulation.integrator = \"newmark\" or another simulation.mode_cutoff")
        what = "the granular state became non-finite" if status == core.NON_FINITE else \
            "Newton on the interface forces did not converge"
        return f"t = {t:.6e} s: {what} even at the smallest step ({h_min:.3e} s); lower k_s or raise simulation.max_halvings"

    def _current(self) -> int:
        """The index of the current output in the batch, made first where it is missing (just
        after a resume: dense output of the restored last step)."""
        b = self._batch
        if b is None or not (b["k0"] <= self._k < b["k0"] + b["done"]):
            nr, nc = len(self.solid.omega), len(self.system.solid_contacts)
            y, eta, etad, F = np.empty_like(self.st.y), np.empty(nr), np.empty(nr), np.empty((nc, 2))
            exact.dense_state(self.st, self.solid, self.stepper.model, self.t_out, exact.DenseOut(y, eta, etad, F))
            self._single_batch(self._k, y, eta, etad, F)
        return self._k - self._batch["k0"]

    def _dense(self):
        """The state (y, eta, eta', F) at the current output."""
        i = self._current()
        return tuple(a[i] for a in self._batch["out"])

    def advance_block(self, k: int, trajectory):
        """Outputs from k on, as many as one compiled batch reaches (it ends at a checkpoint's
        output): (times, observations as arrays whose first axis is the output, the error that
        stopped the batch or None)."""
        self._run_batch(k, trajectory)
        b = self._batch
        n = b["done"]
        if n:
            self._k, self.t_out = k + n - 1, self._target(k + n - 1)
        times = np.array([self._target(j) for j in range(k, k + n)])
        return times, self._observe_rows(np.arange(n)), b["error"]

    def solid_block(self, rows) -> dict:
        """`solid_snapshot` at the rows of the last block."""
        _, eta, etad, _ = self._batch["out"]
        return self._snapshots(eta[rows], etad[rows])

    def observe(self) -> dict:
        rows = self._observe_rows(np.array([self._current()]))
        return {k: v[0] for k, v in rows.items()}

    def _observe_rows(self, rows) -> dict:
        """The observations at the given outputs of the current batch (arrays, first axis the row)."""
        b = self._batch
        Y, F, q = b["out"][0][rows], b["out"][3][rows], b["q"]
        n = self.system.n
        ek, ep = q.solid[rows, 0], q.solid[rows, 1]
        em = q.media[rows]
        dv, df, w = Y[:, 6 * n + ACC_VISC], Y[:, 6 * n + ACC_FRIC], Y[:, 6 * n + ACC_WORK]
        where, model = q.where[rows], b["model"]
        return {"pos": Y[:, : 2 * n].reshape(-1, n, 2), "theta": Y[:, 2 * n : 3 * n], "vel": Y[:, 3 * n : 5 * n].reshape(-1, n, 2),
                "omega": Y[:, 5 * n : 6 * n], "energy_media": em, "energy_solid": ek + ep, "energy_solid_kinetic": ek,
                "energy_solid_potential": ep, "dissipated_viscous": dv, "dissipated_friction": df, "input_work": w,
                "balance_error": ek + ep + em.sum(axis=1) + dv + df - w,
                "force_normal": np.einsum("kij,ij->ki", F, self.normals),
                "force_tangential": np.einsum("kij,ij->ki", F, self.solid.frame.tangent), "wall_force": q.walls[rows],
                "overlap_ratio": q.overlap[rows],
                "overlap_at": _Labels(lambda i: contact_label(self.system, model, int(where[i, 0]), int(where[i, 1])), len(rows))}

    def solid_snapshot(self) -> dict:
        _, eta, etad, _ = self._dense()
        return {k: v[0] for k, v in self._snapshots(eta[None], etad[None]).items()}

    def _snapshots(self, eta, etad) -> dict:
        """All eigenmodes at a block of outputs (rows of eta, eta'): the retained ones' state, and
        the residual modes' state projected on the dropped eigenmodes (their shapes lie in the
        dropped modes' span: eta_d = W_d^-2 P_d' Z q), so that the modal energies add up to the
        solid's energy; or, for a large solid, its reduced nodal state."""
        nk = self.kept
        if self.nodal is not None:
            Phi, PsiZ = self.nodal
            return {"q": (eta[:, :nk] @ Phi.T + eta[:, nk:] @ PsiZ.T).astype(np.float32),
                    "v": (etad[:, :nk] @ Phi.T + etad[:, nk:] @ PsiZ.T).astype(np.float32)}
        proj = self.residual_Z.T @ self.P_drop / self.omega_drop**2  # residual -> dropped modes
        out = {}
        for key, x in (("eta", eta), ("eta_dot", etad)):
            full = np.empty((len(x), nk + len(self.omega_drop)), np.float32)
            full[:, :nk] = x[:, :nk]
            full[:, nk:] = x[:, nk:] @ proj
            out[key] = full
        return out

    def attributes(self) -> dict:
        s = self.settings
        return {"name": "fast", "integrator": "exact", "adaptive": int(s.adaptive), "rtol": s.rtol, "atol": s.atol,
                "max_step": s.max_step, "dt0": s.dt, "mode_cutoff_hz": s.mode_cutoff, "force_model": s.force_model,
                "residual_modes": self.residual, "modes_kept": self.kept,
                "abstol": s.abstol, "reltol": s.reltol, "neighbour_rebuilds": self.stepper.rebuilds,
                "solid_representation": "modal" if self.nodal is None else "nodal"}


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
