"""The fast method's default solver: the exact modal integrator (`coupling.exact`) behind the
solver interface the driver uses."""

from __future__ import annotations

import numpy as np

from ...granular.bundles import Motion, state_views
from ...granular.kernels import rhs
from ...granular.system import Stepper
from ...guard.ahead import compile_ahead
from ...solid.modal import at_dofs
from ...solid.reduction import residual_modes, static_modes
from .. import core
from ..frame import contact_frame, contact_normals
from ..observation import Observation, OutputStates, observe_outputs
from ..protocol import Reached, SolverError, StepSink
from .dense import solid_at_outputs
from .loop import advance_outputs
from .state import CLOCK, DenseOut, ExactConfig, ExactSolid, ExactState, LastStep, initial_state, ops_cache


# the exact integrator stops when the energy ledger (13) has drifted by this share of the input
BALANCE_LIMIT = 1e-2
# outputs per compiled call of the exact integrator
OUTPUT_BATCH = 64
# an eigenmode whose contact participation |B phi| is below this share of the largest mode's never
# moves (a mass-normalised mode's participation is a displacement per unit modal amplitude: at
# 1e-9 its share of any contact's compliance or energy is below 1e-18 times the largest mode's,
# times (w_max / w_1)^2 <= 1e10 for the lowest: far below round-off of the ledger (13))
SILENT = 1e-9


def silent_modes(P: np.ndarray) -> np.ndarray:
    """The modes the contacts cannot move nor feel: P = B Phi's columns (each mode at the
    contacts) no longer than SILENT times the longest (the antisymmetric modes of a plate struck
    on its axis of symmetry, say). The exact integrator leaves them out: under forces at the
    contacts alone their state stays at rest (their modal force P' F vanishes, and the solid's
    initial state, the static response to forces at the contacts, lies in P's span)."""
    norms = np.sqrt(np.einsum("ij,ij->j", P, P)) if P.size else np.zeros(P.shape[1])
    return norms <= SILENT * (norms.max() if len(norms) else 0.0)


class ExactSolver:
    """The fast method with the exact modal integrator: the eigenmodes below `mode_cutoff` and the
    residual modes of the dropped ones propagated in closed form under an interface force that
    is a polynomial over the step, Newton on the forces at the polynomial's nodes, and
    error-controlled steps with dense output at the output times. Outputs come in batches of up
    to OUTPUT_BATCH from one compiled call, each batch ending at a checkpoint's output.

    Built from the run's coupled problem (`granel.problem.Problem`: its system, initial state,
    solid, settings, schedule, the velocity and energy `scales` of `granular.scales.load_scales`,
    the `kinks` a step never crosses, and the static forces on the solid at t = 0) and the
    solid's eigenmodes."""

    def __init__(self, problem, modes=None):
        system, state0, model = problem.system, problem.state, problem.solid
        settings, schedule, scales, kinks = problem.settings, problem.schedule, problem.scales, problem.kinks
        preload = problem.solid_force0
        self.system, self.model, self.settings, self.schedule = system, model, settings, schedule
        self.name = "fast"
        self.y0 = state0.y.copy()
        self.preload = preload
        self.stepper = Stepper(system, substep=True)
        nc = len(system.solid_contacts)
        frame = contact_frame(system, model)
        self.mode_cutoff = float(settings.mode_cutoff)
        if model.ndof:
            B = model.contact_map()
            P_all = at_dofs(B, modes.shapes)
            # the modes below the cut-off that the contacts move (`silent_modes`: the others never move)
            self.silent = silent_modes(P_all)
            keep = (modes.omega <= 2 * np.pi * self.mode_cutoff) & ~self.silent
            P = np.ascontiguousarray(P_all[:, keep])
            omega = modes.omega[keep]
            # the dropped modes: their static compliance at the contacts, as residual modes
            self.P_drop = np.ascontiguousarray(P_all[:, ~keep])
            self.omega_drop = modes.omega[~keep]
            self.keep_index, self.drop_index = np.flatnonzero(keep), np.flatnonzero(~keep)
            om_r, P_r, self.residual_Z, Psi = residual_modes(model, B, modes.shapes, keep, omega,
                                                             partial=modes.count < model.ndof,
                                                             at_contacts=(P, self.P_drop, self.omega_drop))
            self.kept, self.residual = int(len(omega)), int(len(om_r))
            omega = np.concatenate([omega, om_r])
            P = np.ascontiguousarray(np.hstack([P, P_r]))
            # only the modes below the cut-off are known (a large solid): the solid's state is
            # stored in its reduced nodal coordinates, q = Phi eta + Psi Z q_r; the cut-off is then
            # at most just above the highest of them (a capped count of modes)
            self.nodal = None if modes.count == model.ndof else (np.asarray(modes.shapes)[:, keep], Psi @ self.residual_Z)
            if modes.count < model.ndof and len(modes.omega):
                self.mode_cutoff = min(self.mode_cutoff, float(modes.omega[-1]) / (2 * np.pi) * (1 + 1e-9))
        else:
            P, omega = np.zeros((2 * nc, 0)), np.zeros(0)
            self.kept, self.residual, self.residual_Z, self.nodal = 0, 0, np.zeros((2 * nc, 0)), None
            self.P_drop, self.omega_drop = np.zeros((2 * nc, 0)), np.zeros(0)
            self.silent, self.keep_index, self.drop_index = np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, np.int64)
        self.modes = modes
        self.solid = ExactSolid(omega=omega, P=P, frame=frame)
        self.normals = contact_normals(system)
        fixed = not settings.adaptive
        levels = 4 * settings.halvings  # fixed steps use the smaller levels only to retry a failed step
        v_ref, e_ref = scales
        self.cache = ops_cache(settings.force_model, levels, len(omega), nc)
        self.cfg = ExactConfig(h_max=float(settings.dt if fixed else settings.max_step), levels=int(levels),
                               adaptive=not fixed, rtol=float(settings.rtol), atol=float(settings.atol), v_ref=float(v_ref),
                               e_ref=float(e_ref), ledger_tol=float(settings.ledger_tol),
                               ledger_limit=BALANCE_LIMIT * float(e_ref), duration=float(schedule.duration), newton=True,
                               abstol=float(settings.abstol), reltol=float(settings.reltol),
                               max_iterations=int(settings.max_iterations), max_disp=float(self.stepper.max_disp))
        self.kinks = np.array(sorted(k for k in kinks if np.isfinite(k) and k > 0), float)
        self.log = core.step_log(nc)
        self._batch = None
        self._proj = None

    # ------------------------------------------------------------ state
    def start(self) -> None:
        nr, nc = len(self.solid.omega), len(self.system.solid_contacts)
        y = self.y0.copy()
        self._compile_ahead(y, nr, nc)
        dy = np.zeros_like(y)
        F0, eta0 = static_modes(self.preload, self.solid.P, self.solid.omega**2, nc)
        u0 = self.solid.P @ eta0 if nr else np.zeros(2 * nc)
        still = self.stepper.still
        rhs(0.0, y, dy, self.stepper.model, Motion(u0.reshape(nc, 2), still.v0, still.a, still.j, still.d4, still.d5), 0.0)
        level = 0 if not self.settings.adaptive else int(round(4 * np.log2(self.cfg.h_max / self.settings.dt)))
        self.st = initial_state(y, dy, nr, nc, len(self.cache.nodes), 0.0, max(0, min(level, self.cfg.levels)))
        self.st.eta[:] = eta0
        self.st.F[:, :] = F0
        self.st.q[:] = self.solid.P.T @ F0.ravel() if nr else 0.0
        self.st.u[:] = u0
        at_start = DenseOut(y=y[None].copy(), eta=eta0[None].copy(), etad=np.zeros((1, nr)), F=F0[None].copy())
        self._set_batch(0, 1, at_start)  # the output at t = 0
        clock = self.st.clock[0]
        clock["ledger"] = clock["ledger_start"] = float(self._batch["observation"].ledger[0])

    def _compile_ahead(self, y, nr: int, nc: int) -> None:
        """When the step loop is not compiled yet, a second process compiles the kernels it calls
        last (`loop.compile_plan`) while this one compiles the others (`guard.ahead`)."""
        st = initial_state(y, np.zeros_like(y), nr, nc, len(self.cache.nodes), 0.0, 0)
        out = DenseOut(y=np.empty((1, len(y))), eta=np.empty((1, nr)), etad=np.empty((1, nr)), F=np.empty((1, nc, 2)))
        self._ahead = compile_ahead(advance_outputs, "granel.coupling.exact.loop:compile_plan",
                                    (st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache, self.cfg,
                                     np.zeros(1), self.kinks, self.log, out, np.zeros(1, np.int64)))

    def checkpoint(self) -> dict:
        st = self.st
        out = {f"st:{k}": np.asarray(v) for k, v in st._asdict().items() if k not in ("last", "clock")}
        out.update({f"last:{k}": np.asarray(v) for k, v in st.last._asdict().items() if k != "motion"})
        out.update({f"motion:{k}": v for k, v in st.last.motion._asdict().items()})
        out["clock"] = st.clock
        out["ref_pos"] = self.stepper.nl.ref_pos
        return out

    def restore(self, arrays: dict) -> None:
        """The state of a checkpoint (`checkpoint`); CheckpointError for one whose modal state
        does not fit this solver's modes (written by a granel that kept other modes: before the
        silent modes were left out, say), which would otherwise be read as garbage."""
        from ...io.checkpoint import CheckpointError

        arrays = upgraded_checkpoint(arrays)
        nr, held = len(self.solid.omega), np.shape(arrays.get("st:eta", ()))
        if held != (nr,):
            raise CheckpointError(f"it holds the solid in {held[0] if held else 0} modal coordinates, this run "
                                  f"propagates {nr} (it was written by a granel that kept other modes): run again "
                                  "without resuming", 2)
        motion = Motion(*[np.array(arrays[f"motion:{k}"]) for k in Motion._fields])
        last = LastStep(**{k: motion if k == "motion" else np.array(arrays[f"last:{k}"]) for k in LastStep._fields})
        fields = {k: np.array(arrays[f"st:{k}"]) for k in ExactState._fields if k not in ("last", "clock")}
        self.st = ExactState(**fields, last=last, clock=np.array(arrays["clock"]))
        self.stepper.refresh(arrays["ref_pos"])
        self._batch = None

    def _target(self, k: int) -> float:
        return k * self.schedule.output_every if self.settings.adaptive else k * self.schedule.per * self.settings.dt

    # ------------------------------------------------------------ stepping
    def advance(self, k: int, steps: StepSink) -> Reached:
        """Outputs from k on, as many as one compiled batch reaches (to a checkpoint's output at
        most): the steps through them and the state at each by dense output."""
        outputs = self.schedule.outputs
        k1 = min(outputs, k + OUTPUT_BATCH - 1)
        every = self.schedule.checkpoint_period()
        if every:
            k1 = min(k1, (k + every - 1) // every * every)  # a checkpoint output ends the batch
        targets = np.array([self._target(j) for j in range(k, k1 + 1)])
        K, nr, nc = len(targets), len(self.solid.omega), len(self.system.solid_contacts)
        out = DenseOut(y=np.empty((K, len(self.st.y))), eta=np.empty((K, nr)), etad=np.empty((K, nr)),
                       F=np.empty((K, nc, 2)))
        done = np.zeros(1, np.int64)
        st, error = self.st, None
        while done[0] < K:
            status, m = advance_outputs(st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache, self.cfg,
                                        targets, self.kinks, self.log, out, done)
            if m:
                steps.log_steps(self.log.t[:m], self.log.h[:m], self.log.iterations[:m], self.log.lam[:m])
            if status == core.REBUILD:
                self.stepper.rebuild(state_views(st.y, self.system.n).pos)
            elif status in (core.BALANCE_LOST, core.NO_CONVERGENCE, core.NON_FINITE):
                error = SolverError(self._diagnosis(status))
                break
        self._set_batch(k, int(done[0]), out)
        return Reached(int(done[0]), error)

    def _set_batch(self, k0: int, n: int, out: DenseOut) -> None:
        """Outputs k0 .. k0 + n - 1 from their states `out` (rows of a `DenseOut`), observed at once."""
        y, eta, etad, F = out.y[:n], out.eta[:n], out.etad[:n], out.F[:n]
        nc = len(self.system.solid_contacts)
        su, energy = np.zeros((n, nc, 2)), np.zeros((n, 2))
        if n:
            solid_at_outputs(self.solid.P, self.solid.omega, eta, etad, su, energy)
        times = np.array([self._target(k0 + j) for j in range(n)])
        states = OutputStates(times=times, y=y, su=su, solid_energy=energy, F=F)
        obs = observe_outputs(states, self.system, self.stepper.model, self.normals, self.solid.frame.tangent)
        self._batch = {"eta": eta, "etad": etad, "observation": obs}

    def _diagnosis(self, status: int) -> str:
        t, h_min = float(self.st.clock[0]["t"]), self.cfg.h_max / 2 ** (self.cfg.levels / 4)
        if status == core.BALANCE_LOST:
            return (f"t = {t:.6e} s: the energy balance (13) drifted by more than {BALANCE_LIMIT:g} of the input energy "
                    f"with the error control at its smallest step ({h_min:.3e} s): the results would be wrong. "
                    "Try simulation.integrator = \"newmark\" or another simulation.mode_cutoff")
        what = "the granular state became non-finite" if status == core.NON_FINITE else \
            "Newton on the interface forces did not converge"
        return f"t = {t:.6e} s: {what} even at the smallest step ({h_min:.3e} s); lower k_s or raise simulation.max_halvings"

    # ------------------------------------------------------------ what the driver records
    def observe(self) -> Observation:
        return self._batch["observation"]

    def solid_states(self, rows) -> dict:
        """All eigenmodes at some outputs of the last batch, in their own order: the retained ones'
        state, and the residual modes' state projected on the dropped eigenmodes (their shapes lie
        in the dropped modes' span: eta_d = W_d^-2 P_d' Z q; a silent mode's is zero), so that
        the modal energies add up to the solid's energy; or, for a large solid, its reduced nodal
        state."""
        eta, etad = self._batch["eta"][rows], self._batch["etad"][rows]
        nk = self.kept
        if self.nodal is not None:
            Phi, PsiZ = self.nodal
            return {"q": (eta[:, :nk] @ Phi.T + eta[:, nk:] @ PsiZ.T).astype(np.float32),
                    "v": (etad[:, :nk] @ Phi.T + etad[:, nk:] @ PsiZ.T).astype(np.float32)}
        if self._proj is None:  # residual -> dropped modes, the same at every batch
            self._proj = self.residual_Z.T @ self.P_drop / self.omega_drop**2
        proj = self._proj
        out = {}
        for key, x in (("eta", eta), ("eta_dot", etad)):
            full = np.empty((len(x), nk + len(self.omega_drop)), np.float32)
            full[:, self.keep_index] = x[:, :nk]
            full[:, self.drop_index] = x[:, nk:] @ proj
            out[key] = full
        return out

    def attributes(self) -> dict:
        s = self.settings
        return {"name": "fast", "integrator": "exact", "adaptive": int(s.adaptive), "rtol": s.rtol, "atol": s.atol,
                "max_step": s.max_step, "dt0": s.dt, "ledger_tol": s.ledger_tol, "mode_cutoff_hz": self.mode_cutoff,
                "force_model": s.force_model,
                "residual_modes": self.residual, "modes_kept": self.kept, "modes_silent": int(self.silent.sum()),
                "abstol": s.abstol, "reltol": s.reltol, "neighbour_rebuilds": self.stepper.rebuilds,
                "solid_representation": "modal" if self.nodal is None else "nodal"}


# the clock and step records of checkpoints written before they had names: [t, t0, ledger mean
# square, friction rate, ledger, its start, level, largest |input work|] and [grid level, rejected]
_OLD_CLOCK = ("t", "t_start", "ledger_ms", "friction_rate", "ledger", "ledger_start", "level", "work_max")
_OLD_LAST = ("y0", "eta0", "etad0", "Fs", "qs", "Ts")


def upgraded_checkpoint(arrays: dict) -> dict:
    """A checkpoint's arrays in today's layout: one written before the state had named records
    (its clock and meta arrays, the last step's arrays among the state's) is translated; the
    values are the same."""
    if "clock" in arrays:
        return arrays
    out = {k: v for k, v in arrays.items() if k not in ("st:clock", "st:meta")}
    old = np.asarray(arrays["st:clock"], float)
    meta = np.asarray(arrays["st:meta"], np.int64)
    clock = np.zeros(1, CLOCK)
    for i, name in enumerate(_OLD_CLOCK):
        clock[0][name] = old[i] if i < len(old) else 0.0  # the oldest had no running work scale
    clock[0]["grid_level"], clock[0]["rejected"] = int(meta[0]), int(meta[1])
    out["clock"] = clock
    for name in _OLD_LAST:
        out[f"last:{name}"] = out.pop(f"st:{name}")
    return out
