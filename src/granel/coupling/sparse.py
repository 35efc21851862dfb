"""Solids too large for all modes (beyond `solid.modal.DENSE_LIMIT` DOFs): sparse-direct Newmark
(A1)-(A2) for the solid, stepped from Python, around the same compiled interface iteration
(`core.interface_solve`) and step policy as the modal solver.

With S(h) = M + K h^2/4, Newmark gives a_{s+1} = a_pred + S^-1 B' F_{s+1}, where B picks the
contact points' (x, y) displacements from the reduced DOFs. Per step size we factor S once and
keep Z = S^-1 B' (ndof x 2nc) and C = B Z (2nc x 2nc): an interface iteration then costs a
2nc-vector product instead of a sparse solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.linalg import splu

from ..granular.bundles import state_views
from ..granular.system import Stepper
from ..solid.newmark import Newmark, NewmarkState
from . import core
from .frame import contact_frame, contact_normals
from .observation import Observation, OutputStates, observe_outputs
from .protocol import Reached, SolverError, StepSink


@dataclass
class StepOperators:
    h: float
    Z: np.ndarray  # (ndof, 2nc): S^-1 B'
    C: np.ndarray  # (2nc, 2nc): B S^-1 B'
    ct: np.ndarray  # (nc,): t' C_kk t, the tangential compliance of (A8)


class SparseSolver:
    """The coupled step with sparse Newmark, one output per `advance`; built from the run's coupled
    problem (`granel.problem.Problem`)."""

    def __init__(self, problem):
        system, state0, model, settings = problem.system, problem.state, problem.solid, problem.settings
        outputs_every, preload = problem.schedule.per, problem.solid_force0
        self.system, self.model, self.settings = system, model, settings
        self.name = f"{settings.method}-sparse"
        self.modes = None  # the solid is stepped in its nodal coordinates
        self.y0 = state0.y.copy()
        self.preload = preload  # (nc, 2) static forces on the solid at t = 0, or None
        self.normals = contact_normals(system)
        self.stepper = Stepper(system, substep=True)
        self.newmark = Newmark(model.M, model.K)
        self.B = model.contact_map()
        self.Bt = self.B.T.tocsc()
        self.frame = contact_frame(system, model)
        self.cfg = settings.config(self.stepper.max_disp)
        self.per_ticks = outputs_every * 2**settings.halvings
        self._ops: dict[int, StepOperators] = {}
        self.work = core.iter_work(self.y0, len(system.solid_contacts))

    def operators(self, level: int) -> StepOperators:
        ops = self._ops.get(level)
        if ops is None:
            h = self.settings.dt / 2**level
            Z = self.newmark.factor(h).solve(self.Bt.toarray())
            C = np.ascontiguousarray(self.B @ Z)
            t = self.frame.tangent
            ct = np.array([core.tangential_compliance(C, k, t[k, 0], t[k, 1]) if self.frame.has_tangent[k] else 0.0
                           for k in range(len(t))])
            ops = self._ops[level] = StepOperators(h, Z, C, ct)
        return ops

    def _cache(self, levels: int) -> core.StepCache:
        """A StepCache with the tangential compliances of levels 0..levels-1 (for `core.step_level`)."""
        H = self.settings.halvings
        nc = len(self.frame.tangent)
        cache = core.StepCache(np.zeros(H + 1, bool), np.zeros((H + 1, 0)), np.zeros((H + 1, 2 * nc, 2 * nc)), np.zeros((H + 1, nc)))
        for n in range(levels):
            cache.ct[n] = self.operators(n).ct
            cache.ready[n] = True
        return cache

    # ------------------------------------------------------------ state
    def start(self) -> None:
        nc = len(self.frame.tangent)
        F0 = np.zeros((nc, 2)) if self.preload is None else np.asarray(self.preload, float)
        BtF = self.Bt @ F0.ravel()
        x0 = splu(self.model.K.tocsc()).solve(BtF) if np.any(BtF) else None  # at rest under F0
        self.sol = self.newmark.initial(x0, None, BtF if x0 is not None else None)
        z = np.zeros(nc)
        # the policy reads normal, vrel and ticks from a CoupledState (modal parts empty)
        self.st = core.CoupledState(y=self.y0.copy(), eta=np.zeros(0), etad=np.zeros(0), etaa=np.zeros(0), F=F0.copy(),
                                    u=self.B @ self.sol.x, v=np.zeros(2 * nc), a=np.zeros(2 * nc), normal=z, vrel=z.copy(),
                                    clock=core.new_clock())

    def checkpoint(self) -> dict:
        out = {f"st:{k}": np.asarray(v) for k, v in self.st._asdict().items()}
        out.update({"sx": self.sol.x, "sv": self.sol.v, "sa": self.sol.a, "ref_pos": self.stepper.nl.ref_pos})
        return out

    def restore(self, arrays: dict) -> None:
        arrays = core.upgraded_state(arrays)
        self.st = core.CoupledState(**{k: np.array(arrays[f"st:{k}"]) for k in core.CoupledState._fields})
        self.sol = NewmarkState(np.array(arrays["sx"]), np.array(arrays["sv"]), np.array(arrays["sa"]), self.t)
        self.stepper.refresh(arrays["ref_pos"])

    @property
    def t(self) -> float:
        return float(self.st.clock[0]["t"])

    # ------------------------------------------------------------ stepping
    def advance(self, k: int, steps: StepSink) -> Reached:
        st, s = self.st, self.settings
        H = s.halvings
        clock = st.clock[0]
        clock["forced"] = 0
        target = k * self.per_ticks
        lam = np.zeros(len(self.frame.tangent))
        cache = self._cache(H + 1 if s.method == "paper" else 1)
        no_modes = core.ModalSolid(np.zeros(0), np.zeros((0, 0)), self.frame)  # the policy reads only the frame and cache
        while clock["ticks"] < target:
            if not cache.ready[clock["forced"]]:
                cache = self._cache(int(clock["forced"]) + 1)
            level = core.step_level(st, self.stepper.model.law, cache, no_modes, self.cfg, target - int(clock["ticks"]), lam)
            if level < 0:
                raise SolverError(f"t = {self.t:.6e} s: (B1) needs more than {H} halvings of {s.dt:.3e} s")
            ops = self.operators(level)
            a_pred = self.newmark.predictor(self.sol, ops.h)
            pred = core.Prediction(self.B @ self.sol.x, self.B @ self.sol.v, self.B @ self.sol.a, self.B @ a_pred)
            status, its = core.interface_solve(st.y, self.t, ops.h, self.stepper.model, pred, ops.C, st.F, self.cfg, self.frame, self.work)
            if status != core.CONVERGED:
                if self.cfg.retry and clock["forced"] < H:
                    clock["forced"] += 1
                    continue
                raise SolverError(f"t = {self.t:.6e} s: the interface forces did not converge at dt = {ops.h:.3e} s; reduce "
                                  "simulation.dt, raise simulation.max_halvings or simulation.max_iterations, or lower k_s")
            self.sol = Newmark.finish(self.sol, a_pred + ops.Z @ st.F.ravel(), ops.h)
            st.y[:] = self.work.ytr
            st.normal[:] = self.work.iface.normal
            st.vrel[:] = self.work.iface.vrel
            clock["t"] += ops.h
            clock["ticks"] += 2 ** (H - level)
            clock["level"] = level
            steps.log_steps([self.t], [ops.h], [its], lam[None, :])
            self.stepper.maybe_refresh(state_views(st.y, self.system.n).pos)
        return Reached(1)

    # ------------------------------------------------------------ what the driver records
    def observe(self) -> Observation:
        nc = len(self.frame.tangent)
        su = (self.B @ self.sol.x).reshape(1, nc, 2)
        energy = np.array([self.model.energy(self.sol.x, self.sol.v)], float)
        states = OutputStates(times=[self.t], y=self.st.y[None], su=su, solid_energy=energy, F=self.st.F[None])
        return observe_outputs(states, self.system, self.stepper.model, self.normals, self.frame.tangent)

    def solid_states(self, rows) -> dict:
        return {"q": self.sol.x[None].astype(np.float32), "v": self.sol.v[None].astype(np.float32)}

    def attributes(self) -> dict:
        s = self.settings
        return {"name": self.name, "dt0": s.dt, "abstol": s.abstol, "reltol": s.reltol, "lambda_max": s.lambda_max,
                "max_halvings": s.halvings, "neighbour_rebuilds": self.stepper.rebuilds, "solid_representation": "nodal"}
