"""Local refinement after a global search: the `auto` sampler of a single-objective design whose
variables are all continuous (`design_search.make_sampler`). After the global phase
(`global_trials`), each trial is a step of a local model fitted to the finished trials on the
variables' search scale: a linear fit of the signed misfit and the step to its zero set for a
target objective, a quadratic fit and the step to its minimiser for a direction objective.
docs/design.md ("Searches that land: the local refinement") describes the models, the steps and
when the global sampler takes a trial back."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from optuna.distributions import FloatDistribution
from optuna.samplers import BaseSampler
from optuna.trial import TrialState

# a step shorter than this share of the range is no step: the refinement has converged
RESOLUTION = 1e-9
# singular values of a fit below this share of its largest are dropped (a direction that the
# fitted points do not span has no slope)
RCOND = 1e-8
# the lengths tried along a step, in turn, for a trial asked while others run (a step's multiple)
STRIDES = (1.0, 1.5, 0.5, 2.0, 0.25, 3.0)
# a proposal closer than this share of its step to a running or finished trial's point is taken
SEPARATION = 0.1


@dataclass(frozen=True)
class Scale:
    """A continuous variable's search scale: its range (of the logarithm for a log variable)
    mapped onto [0, 1]."""

    name: str
    low: float
    high: float
    log: bool

    def to_unit(self, x: float) -> float:
        lo, hi, v = (math.log(self.low), math.log(self.high), math.log(x)) if self.log else (self.low, self.high, x)
        return (v - lo) / (hi - lo)

    def from_unit(self, u: float) -> float:
        u = min(1.0, max(0.0, float(u)))
        if self.log:
            x = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            x = self.low + u * (self.high - self.low)
        return min(self.high, max(self.low, x))


@dataclass(frozen=True)
class Samples:
    """Finished trials as the refinement sees them: their points on the unit cube (k, n) and
    the quantity of each it fits (the signed misfit for a root, the value to minimise else)."""

    points: np.ndarray
    values: np.ndarray

    def unique(self) -> "Samples":
        """One sample per point (a value asked again is the same run)."""
        _, keep = np.unique(np.round(self.points, 15), axis=0, return_index=True)
        keep = np.sort(keep)
        return Samples(self.points[keep], self.values[keep])


@dataclass(frozen=True)
class Step:
    """A proposed move from the best sample: where from, by how much."""

    start: np.ndarray
    delta: np.ndarray


def _lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(A, b, rcond=RCOND)[0]


def _reach(start: np.ndarray, fitted: np.ndarray) -> float:
    """How far a step may go: twice the spread of the fitted points about its start."""
    return 2.0 * float(np.max(np.linalg.norm(fitted - start, axis=1)))


def _capped(start: np.ndarray, delta: np.ndarray, fitted: np.ndarray) -> Step:
    """The step limited to `_reach`."""
    reach = _reach(start, fitted)
    size = float(np.linalg.norm(delta))
    if size > reach > 0:
        delta = delta * (reach / size)
    return Step(start, delta)


def root_step(s: Samples) -> Step | None:
    """The shortest step from the sample of smallest |s| to the zero set of a linear fit of s
    over the n + 2 samples of smallest |s| (n variables); None with fewer samples or no slope."""
    n = s.points.shape[1]
    if len(s.values) < n + 1:
        return None
    order = np.argsort(np.abs(s.values), kind="stable")[: n + 2]
    x, y = s.points[order], s.values[order]
    d = x - x[0]
    coef = _lstsq(np.column_stack([np.ones(len(y)), d]), y)
    g = coef[1:]
    gg = float(g @ g)
    if not gg > 0:
        return None
    return _capped(x[0], -y[0] * g / gg, x)


def _quadratic_terms(d: np.ndarray) -> np.ndarray:
    """The columns of a full quadratic in d (k, n): 1, d_i, d_i d_j (i <= j)."""
    n = d.shape[1]
    cols = [np.ones(len(d))] + [d[:, i] for i in range(n)]
    cols += [d[:, i] * d[:, j] for i in range(n) for j in range(i, n)]
    return np.column_stack(cols)


def quadratic_step(s: Samples) -> Step | None:
    """The step from the best sample (smallest value) to the minimiser of a quadratic fitted
    over the (n + 1)(n + 2) / 2 best samples, or along its steepest descent, as far as the cap,
    where the fit is not convex; None with too few samples or a flat fit."""
    n = s.points.shape[1]
    terms = (n + 1) * (n + 2) // 2
    if len(s.values) < terms:
        return None
    order = np.argsort(s.values, kind="stable")[:terms]
    x, y = s.points[order], s.values[order]
    coef = _lstsq(_quadratic_terms(x - x[0]), y)
    g = coef[1 : n + 1]
    H = np.zeros((n, n))
    k = n + 1
    for i in range(n):
        for j in range(i, n):
            H[i, j] = H[j, i] = coef[k] * (2.0 if i == j else 1.0)
            k += 1
    w, V = np.linalg.eigh(H)
    if w.min() > RCOND * abs(w).max():  # convex, on the fit's own scale
        return _capped(x[0], -V @ ((V.T @ g) / w), x)
    size = float(np.linalg.norm(g))
    if not size > 0:
        return None
    return Step(x[0], -g / size * _reach(x[0], x))


def place(step: Step, taken: np.ndarray, running: np.ndarray) -> np.ndarray | None:
    """The point at which to put the next trial: the step's end, or (when a running trial is
    there already) another of `STRIDES` along it; clipped to the unit cube. None when the step
    is shorter than `RESOLUTION`, or every stride lands on a point taken (finished) or running."""
    size = float(np.linalg.norm(step.delta))
    if not size >= RESOLUTION:
        return None
    near = max(SEPARATION * size, RESOLUTION)
    for stride in STRIDES:
        p = np.clip(step.start + stride * step.delta, 0.0, 1.0)
        if any(len(q) and np.min(np.linalg.norm(q - p, axis=1)) < near for q in (taken, running)):
            continue
        return p
    return None


def propose(s: Samples, root: bool, running: np.ndarray) -> np.ndarray | None:
    """The next point of the refinement (`root_step` for a target, else `quadratic_step`, then
    `place`), or None: the global sampler's turn."""
    s = s.unique()
    step = root_step(s) if root else quadratic_step(s)
    if step is None:
        return None
    return place(step, s.points, running.reshape(-1, s.points.shape[1]))


# ---------------------------------------------------------------- as an Optuna sampler


@dataclass(frozen=True)
class Goal:
    """The single objective as the refinement fits it: a target metric's signed misfit (a root),
    or the objective's value, negated when it is maximised (a minimum)."""

    metric: str
    target: float | None
    sign: float

    @property
    def root(self) -> bool:
        return self.target is not None

    def quantity(self, trial) -> float | None:
        """The fitted quantity of a finished trial, or None when it has none."""
        if self.target is None:
            v = self.sign * float(trial.values[0])
        else:
            m = trial.user_attrs.get("metrics", {}).get(self.metric)
            v = m / self.target - 1.0 if isinstance(m, (int, float)) else math.nan
        return v if math.isfinite(v) else None


def global_trials(trials: int, startup: int) -> int:
    """The global sampler's share of a study of `trials` trials: a third, and at least its
    `startup` (random) trials."""
    return max(startup, trials // 3)


class RefiningSampler(BaseSampler):
    """`global_sampler` for the first `after` finished trials, and whenever `propose` gives
    way; the refinement's steps on the `scales` (every variable of the design) otherwise."""

    def __init__(self, global_sampler: BaseSampler, scales: list[Scale], goal: Goal, after: int):
        self.global_sampler, self.scales, self.goal, self.after = global_sampler, list(scales), goal, int(after)
        self._dists = {c.name: FloatDistribution(c.low, c.high, log=c.log) for c in self.scales}

    def _finished(self, study) -> list:
        return study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))

    def _ready(self, study) -> bool:
        return len(self._finished(study)) >= self.after

    def _unit(self, trial) -> list[float] | None:
        if not all(c.name in trial.params for c in self.scales):
            return None
        return [c.to_unit(trial.params[c.name]) for c in self.scales]

    def infer_relative_search_space(self, study, trial):
        space = self.global_sampler.infer_relative_search_space(study, trial)
        return {**space, **self._dists} if self._ready(study) else space

    def sample_relative(self, study, trial, search_space):
        if self._ready(study):
            p = self.proposal(study)
            if p is not None:
                return {c.name: c.from_unit(u) for c, u in zip(self.scales, p)}
        return self.global_sampler.sample_relative(study, trial, search_space)

    def proposal(self, study) -> np.ndarray | None:
        """The refinement's next point on the unit cube from the study's finished and running
        trials, or None (`propose`)."""
        pts, vals = [], []
        for t in self._finished(study):
            u, q = self._unit(t), self.goal.quantity(t)
            if u is not None and q is not None:
                pts.append(u)
                vals.append(q)
        if not pts:
            return None
        running = [u for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
                   if (u := self._unit(t)) is not None]
        s = Samples(np.array(pts, float), np.array(vals, float))
        return propose(s, self.goal.root, np.array(running, float).reshape(-1, len(self.scales)))

    def sample_independent(self, study, trial, param_name, param_distribution):
        return self.global_sampler.sample_independent(study, trial, param_name, param_distribution)

    def before_trial(self, study, trial):
        self.global_sampler.before_trial(study, trial)

    def after_trial(self, study, trial, state, values):
        self.global_sampler.after_trial(study, trial, state, values)

    def reseed_rng(self):
        self.global_sampler.reseed_rng()
