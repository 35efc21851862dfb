"""A run's record, whatever solver produced it: per output, the granules and the energies of
eqs. (11)-(13) and the interface forces; at the solid's outputs, its state in mass-normalised
modal coordinates (or, for a solid too large for all modes, reduced nodal coordinates); per
accepted step, its size, iterations and friction eigenvalues (A9).

Records arrive in blocks of outputs (`record_block`: arrays whose first axis is the output); they
are kept as blocks and joined once (`series`)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

GRANULAR = ("pos", "theta", "vel", "omega", "energy_media", "energy_gravity", "energy_solid", "energy_solid_kinetic", "energy_solid_potential",
            "dissipated_viscous", "dissipated_friction", "input_work", "balance_error", "force_normal", "force_tangential", "wall_force")
STATE = ("pos", "theta", "vel", "omega")  # per granule: kept for the traced granules only
STEPS = ("t", "h", "iterations", "lam")
STEP_TYPES = {"t": float, "h": float, "iterations": np.int64, "lam": np.float32}


def _join(blocks: list, dtype=None) -> np.ndarray:
    if not blocks:
        return np.zeros(0, dtype or float)
    return np.concatenate(blocks).astype(dtype, copy=False) if dtype else np.concatenate(blocks)


@dataclass(frozen=True)
class Stored:
    """What a run keeps and its result file stores (`scenario.schema.OutputsSpec`): the indices of
    the granules whose state is kept (None: all), the groups of variables, and the gzip level."""

    traced: tuple | None = None
    contacts: bool = True
    walls: bool = True
    steps: bool = True
    solid: bool = True
    compression: int = 0

    @property
    def every_granule(self) -> bool:
        return self.traced is None


@dataclass
class Trajectory:
    _times: list = field(default_factory=list)  # blocks of output times
    _rec: dict = field(default_factory=lambda: defaultdict(list))  # name -> blocks (outputs, ...)
    _solid_times: list = field(default_factory=list)
    _solid: dict = field(default_factory=lambda: defaultdict(list))  # eta, eta_dot | q, v
    _steps: dict = field(default_factory=lambda: {k: [] for k in STEPS})
    solver: dict = field(default_factory=dict)  # settings and counters, for the result's attributes
    watch: object = None  # called with the latest step time whenever a solver logs steps (progress, wall limit)
    stored: Stored = Stored()  # what is kept: the state of the traced granules only

    def keep(self, stored: Stored) -> "Trajectory":
        self.stored = stored
        return self

    def record_block(self, times, obs: dict) -> None:
        """Outputs at `times` (K,), each entry of `obs` an array whose first axis has length K."""
        self._times.append(np.asarray(times, float))
        traced = self.stored.traced
        for k, v in obs.items():
            v = np.asarray(v)
            if k in STATE and traced is not None:
                v = v[:, list(traced)]
            self._rec[k].append(v)

    def record_solid_block(self, times, snap: dict) -> None:
        self._solid_times.append(np.asarray(times, float))
        for k, v in snap.items():
            self._solid[k].append(np.asarray(v))

    def log_steps(self, t, h, iterations, lam) -> None:
        for key, v in zip(STEPS, (t, h, iterations, lam)):
            self._steps[key].append(np.array(v, STEP_TYPES[key]))
        if self.watch is not None and len(t):
            self.watch(float(t[-1]))

    # ------------------------------------------------------------ reading
    @property
    def times(self) -> np.ndarray:
        return _join(self._times, float)

    @property
    def solid_times(self) -> np.ndarray:
        return _join(self._solid_times, float)

    @property
    def names(self) -> list:
        return list(self._rec)

    @property
    def solid_names(self) -> list:
        return list(self._solid)

    def series(self, name: str) -> np.ndarray:
        """Output quantity `name`, outputs along the first axis."""
        return _join(self._rec[name])

    def solid_series(self, name: str) -> np.ndarray:
        return _join(self._solid[name])

    def first(self, name: str):
        """The value of `name` at the first output."""
        return self._rec[name][0][0]

    def step_series(self, name: str) -> np.ndarray:
        """Per accepted step: t, h, iterations or lam (steps, contacts)."""
        return _join(self._steps[name], STEP_TYPES[name])

    # checkpoints: everything as flat named arrays
    def pack(self) -> dict:
        out = {f"rec:{k}": self.series(k) for k in self._rec}
        out.update({f"solid:{k}": self.solid_series(k) for k in self._solid})
        out.update({f"step:{k}": self.step_series(k) for k in STEPS})
        out["times"] = self.times
        out["solid_times"] = self.solid_times
        return out

    @classmethod
    def unpack(cls, arrays: dict) -> "Trajectory":
        tr = cls()
        tr._times = [np.asarray(arrays["times"], float)]
        tr._solid_times = [np.asarray(arrays["solid_times"], float)]
        for key, v in arrays.items():
            kind, _, name = key.partition(":")
            if kind == "rec":
                tr._rec[name] = [np.asarray(v)]
            elif kind == "solid":
                tr._solid[name] = [np.asarray(v)]
            elif kind == "step":
                tr._steps[name] = [np.asarray(v, STEP_TYPES[name])]
        return tr
