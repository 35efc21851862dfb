"""A run's record, whatever solver produced it: per output, the granules and the energies of
eqs. (11)-(13) and the interface forces; at the solid's outputs, its state in mass-normalised
modal coordinates (or, for a solid too large for all modes, reduced nodal coordinates); per
accepted step, its size, iterations and friction eigenvalues (A9)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

GRANULAR = ("pos", "theta", "vel", "omega", "energy_media", "energy_solid", "energy_solid_kinetic", "energy_solid_potential",
            "dissipated_viscous", "dissipated_friction", "input_work", "balance_error", "force_normal", "force_tangential")
STEPS = ("t", "h", "iterations", "lam")


@dataclass
class Trajectory:
    times: list = field(default_factory=list)
    rec: dict = field(default_factory=lambda: defaultdict(list))
    solid_times: list = field(default_factory=list)
    solid: dict = field(default_factory=lambda: defaultdict(list))  # eta, eta_dot | q, v
    steps: dict = field(default_factory=lambda: {k: [] for k in STEPS})
    solver: dict = field(default_factory=dict)  # settings and counters, for the result's attributes
    watch: object = None  # called with the latest step time whenever a solver logs steps (progress, wall limit)

    def record(self, t: float, obs: dict) -> None:
        self.times.append(float(t))
        for k, v in obs.items():
            self.rec[k].append(v)

    def record_solid(self, t: float, snap: dict) -> None:
        self.solid_times.append(float(t))
        for k, v in snap.items():
            self.solid[k].append(v)

    def log_steps(self, t, h, iterations, lam) -> None:
        self.steps["t"].extend(np.asarray(t, float).tolist())
        self.steps["h"].extend(np.asarray(h, float).tolist())
        self.steps["iterations"].extend(np.asarray(iterations, np.int64).tolist())
        self.steps["lam"].extend(np.asarray(lam, np.float32))
        if self.watch is not None and len(t):
            self.watch(float(t[-1]))

    # checkpoints: everything as flat named arrays
    def pack(self) -> dict:
        out = {f"rec:{k}": np.asarray(v) for k, v in self.rec.items()}
        out.update({f"solid:{k}": np.asarray(v) for k, v in self.solid.items()})
        out.update({f"step:{k}": np.asarray(v) for k, v in self.steps.items()})
        out["times"] = np.asarray(self.times, float)
        out["solid_times"] = np.asarray(self.solid_times, float)
        return out

    @classmethod
    def unpack(cls, arrays: dict) -> "Trajectory":
        tr = cls()
        tr.times = list(arrays["times"])
        tr.solid_times = list(arrays["solid_times"])
        for key, v in arrays.items():
            kind, _, name = key.partition(":")
            if kind == "rec":
                tr.rec[name] = list(v)
            elif kind == "solid":
                tr.solid[name] = list(v)
            elif kind == "step":
                tr.steps[name] = list(v)
        return tr
