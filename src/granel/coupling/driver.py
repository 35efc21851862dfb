"""The one driver loop of every solver: the output schedule, the guards, progress, checkpoints
and resume. It sees a solver only through `coupling.protocol.Solver`, never the physics inside.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..io.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from ..io.trajectory import Stored, Trajectory
from .observation import Observation, energy_ledger
from .protocol import Solver


@dataclass(frozen=True)
class Schedule:
    """When outputs, solid snapshots and checkpoints happen: at multiples of output_every,
    `outputs` of them after t = 0; fixed-step solvers reach them every `per` steps dt."""

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
        """Outputs after t = 0; the last at `duration` (the scenario checks make it a whole number
        of output intervals)."""
        return max(1, int(round(self.duration / self.output_every)))

    @property
    def solid_every(self) -> int:
        """Outputs between stored solid states."""
        return max(1, int(round(self.solid_output_every / self.output_every))) if self.solid_output_every > 0 else 1

    def checkpoint_period(self) -> int:
        """Outputs between checkpoints (0: none)."""
        return max(1, int(round(self.checkpoint_every / (self.per * self.dt)))) if self.checkpoint_every > 0 else 0


class PhysicsStop(RuntimeError):
    """The run left the physics it models (a balance lost, granules passing through each other
    or through a wall or the solid, a non-finite state); the message says when, where and why."""


@dataclass(frozen=True)
class Guards:
    """The driver's stop rules, checked at every output: the energy ledger (13), E + D - W minus
    its initial value, within `balance_limit` of the energy put in (the input work, the initial
    energy or `energy_floor`, whichever is largest: the build sets the floor at 1e-3 of the loads'
    energy scale, so that a drive's first, nearly unloaded outputs are not judged on round-off),
    and no overlap deeper than `overlap_limit` of the smaller radius (eq. 2: the paper's overlaps
    are below 1 %)."""

    balance_limit: float = 1e-2
    overlap_limit: float = 0.1
    energy_floor: float = 0.0  # [J] the energy put in is counted as at least this (a run's first outputs)


def check_guards(obs: Observation, ledger0: float, energy0: float, guards: Guards) -> None:
    """PhysicsStop at the first output of a block that breaks a rule: a non-finite granular state,
    an energy ledger (13) off its initial value ledger0 by more than balance_limit of the energy
    put in, or an overlap deeper than overlap_limit of the radius."""
    K = len(obs)
    finite = np.isfinite(obs.pos).reshape(K, -1).all(axis=1) & np.isfinite(obs.vel).reshape(K, -1).all(axis=1)
    balance = obs.ledger - ledger0
    scale = np.maximum(np.abs(obs.input_work), max(energy0, guards.energy_floor))
    lost = (scale > 0) & (np.abs(balance) > guards.balance_limit * scale)
    deep = obs.overlap_ratio > guards.overlap_limit
    bad = ~finite | lost | deep
    if not bad.any():
        return
    i = int(np.argmax(bad))
    t = float(obs.times[i])
    if not finite[i]:
        raise PhysicsStop(f"t = {t:.6e} s: the granular state is not finite")
    if lost[i]:
        raise PhysicsStop(f"t = {t:.6e} s: the energy balance (13) is off by {abs(balance[i]) / scale[i]:.2e} of the "
                          f"energy put in (limit simulation.balance_limit = {guards.balance_limit:g}): the results would be "
                          "wrong; reduce simulation.dt (or the tolerances) or check the loads")
    raise PhysicsStop(f"t = {t:.6e} s: {obs.overlap_at[i]} overlap by {obs.overlap_ratio[i]:.1%} of the radius (limit "
                      f"simulation.overlap_limit = {guards.overlap_limit:g}): the step is too large for the loads or a body "
                      "passed through another; reduce simulation.dt or the loads")


def _initial_of_record(traj: Trajectory) -> tuple[float, float]:
    """The ledger (13) and the energy a run started with, from its first recorded output (for a
    checkpoint written before they were stored with it)."""
    first = {k: traj.first(k) for k in traj.names}
    granular = float(np.sum(first["energy_media"])) + float(first.get("energy_gravity", 0.0))
    ledger = energy_ledger.py_func(float(first["energy_solid"]), granular,
                           float(first["dissipated_viscous"]), float(first["dissipated_friction"]), float(first["input_work"]))
    return float(ledger), float(np.sum(first["energy_media"]) + first["energy_solid"])


class WallTimeExceeded(RuntimeError):
    """The run went past its wall-time limit (`max_wall`)."""


def _watcher(progress, max_wall, t_start):
    """Called between an output's steps (whenever a solver logs them): progress inside long output
    intervals, and the wall-time limit."""

    def watch(t):
        if progress is not None:
            progress(t)
        if max_wall is not None and time.perf_counter() - t_start > max_wall:
            raise WallTimeExceeded(f"t = {t:.6e} s: stopped after the wall-time limit of {max_wall:g} s")

    return watch


def drive(solver: Solver, schedule: Schedule, progress=None, checkpoint=None, resume=None, fingerprint: str = "",
          guards: Guards | None = None, max_wall: float | None = None, stored: Stored = Stored()) -> Trajectory:
    """Run `solver` through `schedule`: record every output, store the solid state at its
    outputs, report progress(t) and write a resumable checkpoint every `checkpoint_every`
    (atomically, with `fingerprint` naming the scenario); `resume` continues from such a file.
    Every output passes the `guards` (a `PhysicsStop` otherwise); past `max_wall` seconds of wall
    time the run stops (`WallTimeExceeded`), its last checkpoint resumable. Only what `stored`
    names is kept (the traced granules' states, the solid's states if stored)."""
    guards = guards or Guards()
    t_start = time.perf_counter()

    def record(first: int) -> None:
        obs = solver.observe()
        check_guards(obs, ledger0, energy0, guards)
        traj.record_block(obs.times, obs.recorded(ledger0))
        rows = np.flatnonzero(np.arange(first, first + len(obs)) % schedule.solid_every == 0)
        if len(rows) and stored.solid:
            traj.record_solid_block(obs.times[rows], solver.solid_states(rows))

    if resume is not None:
        arrays, recorded, _ = load_checkpoint(resume, fingerprint)
        try:
            solver.restore(arrays)
        except CheckpointError as e:  # the solver's own refusal: name the file
            raise CheckpointError(f"checkpoint {resume}: {e}", 2) from None
        traj = Trajectory.unpack(recorded).keep(stored)
        k = int(arrays["k"])
        if "driver:ledger0" in arrays:
            ledger0, energy0 = float(arrays["driver:ledger0"]), float(arrays["driver:energy0"])
        else:
            ledger0, energy0 = _initial_of_record(traj)
    else:
        solver.start()
        traj = Trajectory().keep(stored)
        first = solver.observe()
        ledger0 = float(first.ledger[0])
        energy0 = float(np.sum(first.energy_media[0]) + first.energy_solid[0])
        record(0)
        k = 0
    every = schedule.checkpoint_period() if checkpoint else 0
    t_wall = time.perf_counter()
    traj.watch = _watcher(progress, max_wall, t_start)
    while k < schedule.outputs:
        reached = solver.advance(k + 1, traj)  # outputs k + 1 .. k + m
        if reached.count:
            traj.watch(float(solver.observe().times[-1]))
            record(k + 1)
        k += reached.count
        if reached.error is not None:
            raise reached.error
        if every and k % every == 0 and k < schedule.outputs:
            state = {**solver.checkpoint(), "k": k, "driver:ledger0": ledger0, "driver:energy0": energy0}
            save_checkpoint(checkpoint, fingerprint, state, traj.pack(), traj.times)
    traj.solver = {**solver.attributes(), "wall_time_s": time.perf_counter() - t_wall}
    traj.watch = None
    return traj
