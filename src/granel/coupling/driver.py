"""The one driver loop of every solver: the output schedule, progress, checkpoints and resume.

A solver (`coupling.solver.ModalSolver`, `coupling.sparse.SparseSolver`) offers `start()`,
`advance(k, trajectory)` to output k, `observe()`, `solid_snapshot()`, `save()`/`load(arrays)`
and `attributes()`; the driver never sees the physics inside.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from ..checkpoint import load_checkpoint, save_checkpoint
from ..trajectory import Trajectory


@dataclass(frozen=True)
class Schedule:
    """When outputs, solid snapshots and checkpoints happen. Outputs fall on multiples of the
    step dt: every `per` steps, `outputs` of them after t = 0."""

    duration: float
    dt: float
    output_every: float
    solid_output_every: float = 0.0  # 0: at every output
    checkpoint_every: float = 0.0  # 0: none

    @property
    def per(self) -> int:
        return max(1, int(round(self.output_every / self.dt)))

    @property
    def outputs(self) -> int:
        return int(math.ceil(self.duration / (self.per * self.dt) - 1e-9))

    @property
    def solid_every(self) -> int:
        """Outputs between stored solid states."""
        return max(1, int(round(self.solid_output_every / self.output_every))) if self.solid_output_every > 0 else 1

    def checkpoint_period(self) -> int:
        """Outputs between checkpoints (0: none)."""
        return max(1, int(round(self.checkpoint_every / (self.per * self.dt)))) if self.checkpoint_every > 0 else 0


def drive(solver, schedule: Schedule, progress=None, checkpoint=None, resume=None, fingerprint: str = "") -> Trajectory:
    """Run `solver` through `schedule`: record every output, store the solid state at its
    outputs, report progress(t) and write a resumable checkpoint every `checkpoint_every`
    (atomically, with `fingerprint` naming the scenario); `resume` continues from such a file."""
    if resume is not None:
        arrays, recorded, _ = load_checkpoint(resume, fingerprint)
        solver.load(arrays)
        traj = Trajectory.unpack(recorded)
        start = int(arrays["k"])
    else:
        solver.start()
        traj = Trajectory()
        traj.record(solver.t, solver.observe())
        traj.record_solid(solver.t, solver.solid_snapshot())
        start = 0
    every = schedule.checkpoint_period() if checkpoint else 0
    t_wall = time.perf_counter()
    for k in range(start, schedule.outputs):
        solver.advance(k + 1, traj)
        traj.record(solver.t, solver.observe())
        if (k + 1) % schedule.solid_every == 0:
            traj.record_solid(solver.t, solver.solid_snapshot())
        if progress is not None:
            progress(solver.t)
        if every and (k + 1) % every == 0 and k + 1 < schedule.outputs:
            save_checkpoint(checkpoint, fingerprint, {**solver.save(), "k": k + 1}, traj.pack(), traj.times)
    traj.solver = {**solver.attributes(), "wall_time_s": time.perf_counter() - t_wall}
    return traj
