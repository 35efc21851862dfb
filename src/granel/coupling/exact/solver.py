"""The fast method's default solver: the exact modal integrator (`coupling.exact`) behind the
solver interface the driver uses."""

from __future__ import annotations

import numpy as np

from ...granular.bundles import ACC_FRIC, ACC_VISC, ACC_WORK, Motion
from ...granular.kernels import rhs
from ...granular.system import GranularState, GranularSystem, Stepper, contact_label
from ...solid.base import SolidModel
from ...solid.modal import at_dofs
from .. import core
from ..observation import OutputQuantities, output_quantities
from ..solver import SolverError, SolverSettings, contact_frame, residual_modes, static_modes, step_log
from .dense import dense_state
from .loop import advance_outputs
from .state import DenseOut, ExactConfig, ExactSolid, ExactState, LastStep, initial_state, ops_cache


# the exact integrator stops when the energy ledger (13) has drifted by this share of the input
BALANCE_LIMIT = 1e-2
# outputs per compiled call of the exact integrator
OUTPUT_BATCH = 64


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
        self.solid = ExactSolid(omega, P, frame)
        self.normals = np.array([c.normal for c in system.solid_contacts], float).reshape(-1, 2)
        fixed = not settings.adaptive
        levels = 4 * settings.halvings  # fixed steps use the smaller levels only to retry a failed step
        h_max = settings.dt if fixed else settings.max_step
        self.cache = ops_cache(settings.force_model, levels, len(omega), nc)
        self.cfg = ExactConfig(float(h_max), int(levels), not fixed, float(settings.rtol), float(settings.atol),
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
        self.st = initial_state(y, dy, nr, nc, len(self.cache.nodes), 0.0, max(0, min(level, self.cfg.levels)))
        self.st.eta[:] = eta0
        self.st.F[:, :] = F0
        self.st.q[:] = self.solid.P.T @ F0.ravel() if nr else 0.0
        self.st.u[:] = u0
        self.t_out, self._k = 0.0, 0
        self._single_batch(0, y, eta0, np.zeros(nr), F0)  # the output at t = 0
        q, n = self._batch["q"], self.system.n
        # E_solid + E_granular + D - W (13)
        ledger = float(q.solid[0].sum() + q.media[0].sum()) + y[6 * n] + y[6 * n + 1] - y[6 * n + 2]
        clock = self.st.clock[0]
        clock["ledger"] = clock["ledger_start"] = ledger

    def save(self) -> dict:
        st = self.st
        out = {f"st:{k}": np.asarray(v) for k, v in st._asdict().items() if k not in ("last", "clock")}
        out.update({f"last:{k}": np.asarray(v) for k, v in st.last._asdict().items() if k != "motion"})
        out.update({f"motion:{k}": v for k, v in st.last.motion._asdict().items()})
        out["clock"] = st.clock
        out["ref_pos"] = self.stepper.nl.ref_pos
        out["t_out"] = self.t_out
        return out

    def load(self, arrays: dict) -> None:
        arrays = upgraded_checkpoint(arrays)
        motion = Motion(*[np.array(arrays[f"motion:{k}"]) for k in Motion._fields])
        last = LastStep(**{k: motion if k == "motion" else np.array(arrays[f"last:{k}"]) for k in LastStep._fields})
        fields = {k: np.array(arrays[f"st:{k}"]) for k in ExactState._fields if k not in ("last", "clock")}
        self.st = ExactState(**fields, last=last, clock=np.array(arrays["clock"]))
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
            status, m = advance_outputs(st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache,
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
        q = OutputQuantities(np.zeros((K, len(self.system.media))), np.zeros((K, 2)), np.zeros((K, nc, 2)), np.zeros(K),
                                   np.zeros((K, 2), np.int64), np.zeros((K, len(self.system.walls), 2)))
        if n:
            times = np.array([self._target(k0 + j) for j in range(n)])
            output_quantities(out[0][:n], out[1][:n], out[2][:n], self.stepper.model, self.solid,
                                    self.system.medium_index, len(self.system.media), q, times)
        self._batch = {"k0": k0, "done": n, "out": out, "q": q, "error": error, "model": self.stepper.model}

    def _single_batch(self, k: int, y, eta, etad, F) -> None:
        self._set_batch(k, 1, (y[None].copy(), eta[None].copy(), etad[None].copy(), F[None].copy()))

    def _diagnosis(self, status: int) -> str:
        t, h_min = float(self.st.clock[0]["t"]), self.cfg.h_max / 2 ** (self.cfg.levels / 4)
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
            dense_state(self.st, self.solid, self.stepper.model, self.t_out, DenseOut(y, eta, etad, F))
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


# the clock and step records of checkpoints written before they had names: [t, t0, ledger mean
# square, friction rate, ledger, its start, level, largest |input work|] and [grid level, rejected]
_OLD_CLOCK = ("t", "t_start", "ledger_ms", "friction_rate", "ledger", "ledger_start", "level", "work_max")
_OLD_LAST = {"y0": "y0", "eta0": "eta0", "etad0": "etad0", "Fs": "Fs", "qs": "qs", "Ts": "Ts"}


def upgraded_checkpoint(arrays: dict) -> dict:
    """A checkpoint's arrays in today's layout: one written before the state had named records
    (its clock and meta arrays, the last step's arrays among the state's) is translated; the
    values are the same."""
    if "clock" in arrays:
        return arrays
    from .state import CLOCK

    out = {k: v for k, v in arrays.items() if k not in ("st:clock", "st:meta")}
    old = np.asarray(arrays["st:clock"], float)
    meta = np.asarray(arrays["st:meta"], np.int64)
    clock = np.zeros(1, CLOCK)
    for i, name in enumerate(_OLD_CLOCK):
        clock[0][name] = old[i] if i < len(old) else 0.0  # the oldest had no running work scale
    clock[0]["grid_level"], clock[0]["rejected"] = int(meta[0]), int(meta[1])
    out["clock"] = clock
    for new, name in _OLD_LAST.items():
        out[f"last:{new}"] = out.pop(f"st:{name}")
    return out
