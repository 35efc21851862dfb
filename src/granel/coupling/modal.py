"""Newmark over the solid's modes, stepped by the compiled core (`coupling.core.advance_modal`):
the paper's method (fixed point and (B1)) and the fast method's `integrator = "newmark"` (Newton
at dtau0). All modes are kept (Newmark (A2) is then one scalar recursion per mode, identical to
the sparse Newmark to round-off); a rigid solid has none."""

from __future__ import annotations

import numpy as np

from ..granular.system import Stepper
from ..solid.modal import at_dofs
from ..solid.reduction import static_modes
from . import core
from .frame import contact_frame, contact_normals
from .observation import Observation, OutputStates, modal_energy, observe_outputs
from .protocol import Reached, SolverError, StepSink


class ModalSolver:
    """The compiled core with the solid in modal coordinates, one output per `advance`; built from
    the run's coupled problem (`granel.problem.Problem`) and the solid's eigenmodes."""

    def __init__(self, problem, modes=None):
        system, state0, model, settings = problem.system, problem.state, problem.solid, problem.settings
        outputs_every, preload = problem.schedule.per, problem.solid_force0
        self.system, self.model, self.settings = system, model, settings
        self.name = settings.method
        self.y0 = state0.y.copy()
        self.preload = preload  # (nc, 2) static forces on the solid at t = 0, or None
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
        self.omega = modes.omega if model.ndof else np.zeros(0)
        self.normals = contact_normals(system)
        H = settings.halvings
        self.cache = core.StepCache(ready=np.zeros(H + 1, bool), D=np.zeros((H + 1, len(w2))),
                                    C=np.zeros((H + 1, 2 * nc, 2 * nc)), ct=np.zeros((H + 1, nc)))
        self.cfg = settings.config(self.stepper.max_disp)
        self.per_ticks = outputs_every * 2**H  # ticks between outputs
        self.log = core.step_log(nc)

    # ------------------------------------------------------------ state
    def start(self) -> None:
        nm, nc = len(self.solid.w2), len(self.system.solid_contacts)
        z = lambda k: np.zeros(k)  # noqa: E731
        F0, eta0 = static_modes(self.preload, self.solid.P, self.solid.w2, nc)
        self.st = core.CoupledState(y=self.y0.copy(), eta=eta0, etad=z(nm), etaa=z(nm), F=F0, u=self.solid.P @ eta0,
                                    v=z(2 * nc), a=z(2 * nc), normal=z(nc), vrel=z(nc), clock=core.new_clock())

    def checkpoint(self) -> dict:
        out = {f"st:{k}": np.asarray(v) for k, v in self.st._asdict().items()}
        out["ref_pos"] = self.stepper.nl.ref_pos
        return out

    def restore(self, arrays: dict) -> None:
        arrays = core.upgraded_state(arrays)
        self.st = core.CoupledState(**{k: np.array(arrays[f"st:{k}"]) for k in core.CoupledState._fields})
        self.stepper.refresh(arrays["ref_pos"])

    @property
    def t(self) -> float:
        return float(self.st.clock[0]["t"])

    # ------------------------------------------------------------ stepping
    def advance(self, k: int, steps: StepSink) -> Reached:
        """Accepted steps up to output k (time k * output interval)."""
        st = self.st
        st.clock[0]["forced"] = 0  # back to dtau0 at each output interval
        target = k * self.per_ticks
        while True:
            status, m = core.advance_modal(st, self.stepper.model, self.stepper.nl.ref_pos, self.solid, self.cache, self.cfg,
                                           target, self.log)
            if m:
                steps.log_steps(self.log.t[:m], self.log.h[:m], self.log.iterations[:m], self.log.lam[:m])
            if status == core.DONE:
                return Reached(1)
            if status == core.REBUILD:
                self.stepper.rebuild(st.y[: 2 * self.system.n].reshape(-1, 2))
            elif status in (core.NO_CONVERGENCE, core.NON_FINITE):
                raise SolverError(self._diagnosis(status))

    def _diagnosis(self, status: int) -> str:
        s, clock = self.settings, self.st.clock[0]
        h = s.dt / 2 ** max(int(clock["level"]), int(clock["forced"]))
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
    def observe(self) -> Observation:
        st, nc = self.st, len(self.system.solid_contacts)
        energy = np.array([modal_energy(st.eta, st.etad, self.omega)])
        states = OutputStates(times=[self.t], y=st.y[None], su=st.u.reshape(1, nc, 2), solid_energy=energy, F=st.F[None])
        return observe_outputs(states, self.system, self.stepper.model, self.normals, self.solid.frame.tangent)

    def solid_states(self, rows) -> dict:
        return {"eta": self.st.eta[None].astype(np.float32), "eta_dot": self.st.etad[None].astype(np.float32)}

    def attributes(self) -> dict:
        s = self.settings
        return {"name": s.method, "dt0": s.dt, "abstol": s.abstol, "reltol": s.reltol, "lambda_max": s.lambda_max,
                "max_halvings": s.halvings, "neighbour_rebuilds": self.stepper.rebuilds, "solid_representation": "modal"}
