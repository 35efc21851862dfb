"""The one interface between the driver and a solver (the paper's algorithm, the exact modal
integrator, modal Newmark, sparse Newmark): the driver calls nothing else."""

from __future__ import annotations

from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from .observation import Observation


class SolverError(RuntimeError):
    """The coupled step failed (no convergence, or a non-finite state); the message says where and why."""


class Reached(NamedTuple):
    """What an `advance` reached: how many outputs, and the error that stopped it short of the
    outputs it was asked for (None if none did)."""

    count: int
    error: Exception | None = None


class StepSink(Protocol):
    """Where a solver logs its accepted steps (a `io.trajectory.Trajectory`)."""

    def log_steps(self, t, h, iterations, lam) -> None: ...


@runtime_checkable
class Solver(Protocol):
    """A coupled solver as the driver sees it.

    start:     the state at t = 0, which is output 0;
    advance:   accepted steps from the current output to output k and, where the solver computes
               outputs in blocks, beyond (never past the next checkpoint output); the steps go to
               `steps`; returns how many outputs were reached;
    observe:   the outputs the last `start` or `advance` reached, as one `Observation` block;
    solid_states: the solid's state at some of those outputs (rows of the block): modal
               coordinates {eta, eta_dot} or reduced nodal ones {q, v};
    checkpoint / restore: the whole state as named arrays, and back;
    attributes: the settings and counters a result records;
    name, modes: the method's name, and the solid's eigenmodes it propagates (`solid.modal.Modes`;
               None for a rigid solid or sparse Newmark)."""

    name: str
    modes: object

    def start(self) -> None: ...

    def advance(self, k: int, steps: StepSink) -> Reached: ...

    def observe(self) -> Observation: ...

    def solid_states(self, rows: np.ndarray) -> dict: ...

    def checkpoint(self) -> dict: ...

    def restore(self, arrays: dict) -> None: ...

    def attributes(self) -> dict: ...
