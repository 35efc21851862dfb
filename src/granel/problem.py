"""The built problem: what the solvers receive (never the scenario itself).
May import: coupling, solid, granular."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .coupling.driver import Guards, Schedule, Stored
from .coupling.settings import SolverSettings
from .granular.system import GranularState, GranularSystem
from .solid.base import SolidModel


@dataclass
class Problem:
    """The granular system and its initial state, the solid model (rigid, beam or plate), the
    solver settings and the output schedule, and the scenario's text (stored with the results)."""

    system: GranularSystem
    state: GranularState
    solid: SolidModel
    settings: SolverSettings
    schedule: Schedule
    source: str = ""  # the scenario as TOML
    guards: Guards = Guards()  # the driver's stop rules
    solid_force0: np.ndarray | None = None  # (nc, 2) the static forces on the solid at t = 0 (a preload)
    equilibrium: dict | None = None  # the static equilibrium's numbers (granular.static.Equilibrium.summary)
    equilibrium_contacts: tuple | None = None  # its loaded contacts: names, forces, overlaps (Equilibrium.contacts)
    inputs: dict = field(default_factory=dict)  # {file name: content digest} of the files the scenario reads
    input_texts: dict = field(default_factory=dict)  # {file name: its text}: the result carries its whole model
    scales: tuple = (1.0, 1.0)  # the run's velocity [m/s] and energy [J] scales (granular.scales.load_scales)
    kinks: tuple = ()  # times where a load or a wall's motion is not smooth [s]
    stored: Stored = Stored()  # what the run keeps and its result stores (simulation.outputs)
    max_modes: int | None = None  # the most eigenmodes of a large solid (the automatic cut-off's cap)
