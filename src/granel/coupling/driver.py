"""The one driver loop of every solver: the output schedule, progress, checkpoints and resume.

A solver (`coupling.solver.ModalSolver`, `coupling.sparse.SparseSolver`) offers `start()`,
`advance(k, trajectory)` to output k, `observe()`, `solid_snapshot()`, `save()`/`load(arrays)`
and `attributes()`; one that computes its outputs in blocks (`coupling.exact.solver.ExactSolver`) also
offers `advance_block(k, trajectory)`, which returns the outputs from k on that it reached as
arrays (first axis: the output), and `solid_block(rows)`. The driver never sees the physics
inside.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..io.checkpoint import load_checkpoint, save_checkpoint
from ..io.trajectory import Trajectory


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


def _guarded(obs: dict, ledger0: float, energy0: float, guards: Guards, t: float) -> dict:
    """The observation with the balance error relative to the initial ledger, after the checks."""
    obs = dict(obs)
    ratio, where = obs.pop("overlap_ratio", 0.0), obs.pop("overlap_at", "")
    obs["balance_error"] = obs["balance_error"] - ledger0
    if not (np.all(np.isfinite(obs["pos"])) and np.all(np.isfinite(obs["vel"]))):
        raise PhysicsStop(f"t = {t:.6e} s: the granular state is not finite")
    scale = max(abs(float(obs["input_work"])), energy0, guards.energy_floor)
    if scale > 0 and abs(obs["balance_error"]) > guards.balance_limit * scale:
        raise PhysicsStop(f"t = {t:.6e} s: the energy balance (13) is off by {abs(obs['balance_error']) / scale:.2e} of the "
                          f"energy put in (limit simulation.balance_limit = {guards.balance_limit:g}): the results would be "
                          "wrong; reduce simulation.dt (or the tolerances) or check the loads")
    if ratio > guards.overlap_limit:
        raise PhysicsStop(f"t = {t:.6e} s: {where} overlap by {ratio:.1%} of the radius (limit simulation.overlap_limit = "
                          f"{guards.overlap_limit:g}): the step is too large for the loads or a body passed through another; "
                          "reduce simulation.dt or the loads")
    return obs


def _guarded_block(obs: dict, ledger0: float, energy0: float, guards: Guards, times) -> dict:
    """`_guarded` for a block of outputs (arrays whose first axis is the output): the first
    output that breaks a rule stops the run with its own time and message."""
    obs = dict(obs)
    ratio, where = obs.pop("overlap_ratio"), obs.pop("overlap_at")
    obs["balance_error"] = obs["balance_error"] - ledger0
    finite = np.isfinite(obs["pos"]).reshape(len(times), -1).all(axis=1) & np.isfinite(obs["vel"]).reshape(len(times), -1).all(axis=1)
    scale = np.maximum(np.abs(obs["input_work"]), max(energy0, guards.energy_floor))
    lost = (scale > 0) & (np.abs(obs["balance_error"]) > guards.balance_limit * scale)
    bad = ~finite | lost | (ratio > guards.overlap_limit)
    if bad.any():
        i = int(np.argmax(bad))
        one = {k: v[i] for k, v in obs.items()}
        one.update(balance_error=one["balance_error"] + ledger0, overlap_ratio=float(ratio[i]), overlap_at=where[i])
        _guarded(one, ledger0, energy0, guards, float(times[i]))  # raises with the output's own message
    return obs


def _initial(obs: dict) -> tuple[float, float]:
    """From the first output: the ledger E + D - W (eq. 13) and the energy E the run starts with."""
    energy = float(np.sum(obs["energy_media"]) + obs["energy_solid"])
    return energy + float(obs["dissipated_viscous"] + obs["dissipated_friction"] - obs["input_work"]), energy


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


def drive(solver, schedule: Schedule, progress=None, checkpoint=None, resume=None, fingerprint: str = "",
          guards: Guards | None = None, max_wall: float | None = None) -> Trajectory:
    """Run `solver` through `schedule`: record every output, store the solid state at its
    outputs, report progress(t) and write a resumable checkpoint every `checkpoint_every`
    (atomically, with `fingerprint` naming the scenario); `resume` continues from such a file.
    Every output passes the `guards` (a `PhysicsStop` otherwise); past `max_wall` seconds of wall
    time the run stops (`WallTimeExceeded`), its last checkpoint resumable."""
    guards = guards or Guards()
    t_start = time.perf_counter()
    if resume is not None:
        arrays, recorded, _ = load_checkpoint(resume, fingerprint)
        solver.load(arrays)
        traj = Trajectory.unpack(recorded)
        start = int(arrays["k"])
        # the recorded balance starts at zero: rebuild the initial ledger from the first output
        ledger0, energy0 = _initial({k: traj.first(k) for k in traj.names})
    else:
        solver.start()
        traj = Trajectory()
        obs = solver.observe()
        ledger0, energy0 = _initial(obs)
        traj.record(solver.t, _guarded(obs, ledger0, energy0, guards, solver.t))
        traj.record_solid(solver.t, solver.solid_snapshot())
        start = 0
    every = schedule.checkpoint_period() if checkpoint else 0
    t_wall = time.perf_counter()
    traj.watch = _watcher(progress, max_wall, t_start)
    block = getattr(solver, "advance_block", None)
    k = start
    while k < schedule.outputs:
        if block is None:
            solver.advance(k + 1, traj)
            traj.watch(solver.t)
            traj.record(solver.t, _guarded(solver.observe(), ledger0, energy0, guards, solver.t))
            if (k + 1) % schedule.solid_every == 0:
                traj.record_solid(solver.t, solver.solid_snapshot())
            k += 1
        else:  # outputs k + 1 .. k + m, ending at a checkpoint's output; the error of an output beyond
            times, obs, error = block(k + 1, traj)
            m = len(times)
            if m:
                traj.watch(float(times[-1]))
                traj.record_block(times, _guarded_block(obs, ledger0, energy0, guards, times))
                rows = np.flatnonzero(np.arange(k + 1, k + m + 1) % schedule.solid_every == 0)
                if len(rows):
                    traj.record_solid_block(times[rows], solver.solid_block(rows))
            k += m
            if error is not None:
                raise error
        if every and k % every == 0 and k < schedule.outputs:
            save_checkpoint(checkpoint, fingerprint, {**solver.save(), "k": k}, traj.pack(), traj.times)
    traj.solver = {**solver.attributes(), "wall_time_s": time.perf_counter() - t_wall}
    traj.watch = None
    return traj
