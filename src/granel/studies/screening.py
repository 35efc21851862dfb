"""Multi-fidelity design studies: a design's `[screening]` (its trials at a looser accuracy),
the order of the screened trials, and the confirmed ones (the best run again at the design's own
accuracy by `design_search.confirm_best`, their values under the study's `confirmed` attribute)."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field


def _accuracy_override(item: str) -> str:
    """A screening's override: simulation.FIELD=VALUE, nothing else."""
    key = item.split("=", 1)[0].strip()
    if "=" not in item or not key.startswith("simulation.") or key.count(".") != 1:
        raise ValueError("a screening sets simulation fields only (simulation.FIELD=VALUE): it changes the accuracy, "
                         "not the design")
    return item


class ScreeningSpec(BaseModel):
    """Multi-fidelity search: every trial runs at the looser accuracy of `overrides` (simulation
    fields only: a screening changes how accurately a design is run, not the design), and the
    `confirm` best trials are run again at the design's own accuracy; the best design is the
    best of those."""

    model_config = ConfigDict(extra="forbid")
    overrides: list[Annotated[str, AfterValidator(_accuracy_override)]] = Field(
        min_length=1, description="the trials' accuracy, e.g. 'simulation.rtol=1e-4'")
    confirm: int = Field(10, ge=1, le=1000, description="the best trials run again at the design's own accuracy")


def screened_ranking(spec, study) -> list:
    """The feasible finished trials, best first by their screened values: one objective by its
    value, several by Pareto rank (the front first) and then the first objective."""
    from optuna.trial import TrialState

    ok = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
          if all(c <= 0 for c in t.user_attrs.get("constraints", []))]
    signs = np.array([1.0 if d == "minimize" else -1.0 for d in spec.directions])
    if not ok:
        return []
    v = np.array([t.values for t in ok], float) * signs
    rank = np.zeros(len(ok), int)
    left = set(range(len(ok)))
    level = 0
    while left:  # Pareto levels (one objective: each trial its own level, by value)
        front = {k for k in left if not any(np.all(v[j] <= v[k]) and np.any(v[j] < v[k]) for j in left)}
        for k in front:
            rank[k] = level
        left -= front
        level += 1
    order = sorted(range(len(ok)), key=lambda k: (rank[k], v[k, 0], ok[k].number))
    return [ok[k] for k in order]


class ConfirmedTrial:
    """A trial as a screened study reports it: its number, parameters and attributes, with the
    objective values of its run at the design's own accuracy."""

    def __init__(self, trial, values, constraints):
        self._trial, self.values, self.constraints = trial, list(values), list(constraints)

    def __getattr__(self, name):
        return getattr(self._trial, name)

    @property
    def screened_values(self) -> list[float]:
        """The objective values at the trials' (screened) accuracy."""
        return list(self._trial.values)


def confirmed_trials(spec, study) -> list:
    """The confirmed trials of a screened study that ran ok at the design's own accuracy, as
    `ConfirmedTrial`s, in their screened order."""
    held = study.user_attrs.get("confirmed", {})
    out = []
    for t in screened_ranking(spec, study):
        c = held.get(str(t.number))
        if c is not None and c.get("values") is not None:
            out.append(ConfirmedTrial(t, c["values"], c.get("constraints", [])))
    return out
