"""The coupled solver's method and numbers (the scenario's [simulation] table), and the compiled
core's configuration they give.

The two methods:
  fast   the exact modal integrator (`coupling.exact`) by default; with integrator = "newmark",
         Newton on the interface forces at dtau0 over modal Newmark, a failed step retried at
         half the step;
  paper  the paper's algorithm: fixed point (A4) and the step halved by (B1) until
         max |lambda| <= 1/2 at every contact (Appendices A and B).
"""

from __future__ import annotations

from dataclasses import dataclass

from . import core

METHODS = ("fast", "paper")
# the automatic cut-off keeps at most this many eigenmodes of a solid beyond solid.modal.DENSE_LIMIT
# DOFs (the propagated modes set the cost of every step)
LARGE_SOLID_MODES = 600


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
    mode_cutoff: float | str = "auto"  # [Hz]: eigenmodes above are replaced by residual modes ("auto": granular.scales.auto_mode_cutoff)
    ledger_tol: float = 8e-7  # the energy balance (13) stays within this share of the largest load's energy
    modes: str = "all"  # the exact integrator's eigenmodes: all (and residual modes from them) | below_cutoff

    def config(self, max_disp: float) -> core.CoupledConfig:
        paper = self.method == "paper"
        return core.CoupledConfig(float(self.dt), int(self.halvings), core.POLICY_B1 if paper else core.POLICY_CONSTANT,
                                  float(self.lambda_max), not paper, float(self.abstol), float(self.reltol),
                                  int(self.max_iterations), not paper, float(max_disp))
