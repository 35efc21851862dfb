"""Searches that land (issue 30, item 2): with at most 60 trials, any seed and one or two
workers, a design study's best trial must lie within 1 % of the exact answer of a closed-form
inverse problem. TPE alone lingers a few tenths of a per cent to a per cent away on flat
objectives, so the `auto` sampler of a single-objective study with continuous variables refines
locally after its global phase (`granel.studies.refine`).

The inverse problems are on the precompressed chain of tests/test_design_cutoff.py (eight steel
beads on a rigid wall, rung by a weak pulse; its docstring gives the linearisation), whose
cut-off f_c = (1/pi) sqrt(K/m) goes as R^(-4/3) F0^(1/6):

1. the beads' radius R for a 12 kHz cut-off (F0 = 10 N);
2. the preload F0 for a 19 kHz cut-off (R = 5 mm): the flat one, 1 % in F0 being 0.17 % in f_c;
3. R and F0 together for a 12 kHz cut-off: every (R, F0) on the curve R^(-4/3) F0^(1/6) = const
   is exact, and a design's error is the relative error of its R against the curve's radius at
   its F0.

The slow tests measure each trial's cut-off from its own run (`cutoff_Hz`); the measure's own
error against the linearised chain is about 1e-6 here (4e-6 at most at 5 N, 1.5 ms;
tests/test_design_cutoff.py bounds it at 2e-4), far below the 1 % that the issue asks of the
search. The quick tests run the same studies on the closed form itself, through the same ask and
tell path as `run_design`.
"""

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from test_design_cutoff import CHAIN, E, NU, RHO, linear_chain

# the requirement: the best trial within 1 % of the exact answer
LANDS = 0.01
SEEDS = (1, 2, 3)  # the slow tests (granel runs)
QUICK_SEEDS = tuple(range(1, 11))  # the closed-form studies (a second for ten)


@dataclass(frozen=True)
class Problem:
    """A closed-form inverse problem on the chain's cut-off: its variables (TOML), target,
    overrides of the base chain, and the relative error of a design's values."""

    name: str
    variables: str
    target_hz: float
    overrides: tuple = ()

    def error(self, params: dict) -> float:
        R = params.get(RADIUS, 0.005)
        F = params.get(PRELOAD, 10.0)
        if RADIUS in params:  # the radius whose cut-off at this preload is the target
            return R / (0.005 * (linear_chain(0.005, F)[2] / self.target_hz) ** 0.75) - 1.0
        return F / (10.0 * (self.target_hz / linear_chain(0.005, 10.0)[2]) ** 6) - 1.0

    def cutoff(self, params: dict) -> float:
        """The linearised chain's cut-off at these values [Hz]."""
        return linear_chain(params.get(RADIUS, 0.005), params.get(PRELOAD, 10.0))[2]

    def design(self, seed: int, sampler: str = "auto", trials: int = 60) -> str:
        overrides = ", ".join(repr(o) for o in self.overrides)
        return f"""name = "{self.name}"
base = "{CHAIN.name}"
mode = "run"
pair = ["C:1", "C:8"]
overrides = [{overrides}]
trials = {trials}
seed = {seed}
sampler = "{sampler}"
{self.variables}
[[objectives]]
metric = "cutoff_Hz"
target = {self.target_hz}
"""


RADIUS, PRELOAD = "media.0.radii.0", "excitations.1.value"
TIED = ", ".join(f'"media.0.radii.{k}"' for k in range(1, 8))

PROBLEMS = {
    "radius": Problem("radius", f'[[variables]]\nfield = "{RADIUS}"\ntied = [{TIED}]\nlow = 0.002\nhigh = 0.010\n'
                                "log = true\n", 12000.0),
    "preload": Problem("preload", f'[[variables]]\nfield = "{PRELOAD}"\nlow = 5.0\nhigh = 50.0\nlog = true\n',
                       19000.0, ('simulation.duration="1.5ms"',)),  # f_c >= 15 kHz: 1.5 ms holds 23 periods
    "radius+preload": Problem("radius+preload", f'[[variables]]\nfield = "{RADIUS}"\ntied = [{TIED}]\nlow = 0.004\n'
                                                f'high = 0.008\nlog = true\n[[variables]]\nfield = "{PRELOAD}"\n'
                                                "low = 5.0\nhigh = 40.0\nlog = true\n", 12000.0),
}


def load(problem: Problem, folder: Path, seed: int, sampler: str = "auto", trials: int = 60):
    from granel.studies.design import load_design

    folder.mkdir(parents=True, exist_ok=True)
    (folder / CHAIN.name).write_text(CHAIN.read_text())
    (folder / "d.toml").write_text(problem.design(seed, sampler, trials))
    return load_design(folder / "d.toml")


# ---------------------------------------------------------------- the refinement against analytic functions


def iterate(f, starts, root: bool, steps: int) -> list[np.ndarray]:
    """The refinement's points, each evaluated and added to the samples before the next."""
    from granel.studies.refine import Samples, propose

    pts = [np.atleast_1d(np.asarray(p, float)) for p in starts]
    vals = [f(p) for p in pts]
    out = []
    for _ in range(steps):
        p = propose(Samples(np.array(pts), np.array(vals)), root, np.empty((0, pts[0].size)))
        if p is None:
            break
        pts.append(p)
        vals.append(f(p))
        out.append(p)
    return out


def test_the_root_refinement_converges_superlinearly():
    """A signed misfit s = exp(3 (u - u*)) - 1 from three points: each step's error e' is at most
    e^1.3 once e < 1e-2 (the secant method's order is 1.618; 1.3 leaves room for the steps
    before its asymptote, and a linear rule, e' = c e with c >= 0.1, fails it), down to 1e-8."""
    star = 0.37
    pts = iterate(lambda u: math.expm1(3 * (u[0] - star)), [[0.1], [0.8], [0.5]], True, 8)
    err = [abs(p[0] - star) for p in pts]
    assert min(err) < 1e-8
    for a, b in zip(err, err[1:]):
        if 1e-8 < a < 1e-2:
            assert b <= a**1.3, err


def test_the_minimum_refinement_converges_superlinearly():
    """A smooth 1-D minimum (cosh(4 (u - u*)) + (u - u*)^3) from three points: parabolic
    interpolation reaches 1e-6 within five steps; golden-section search from the same bracket
    would still be 0.7 x 0.618^5 = 0.06 wide. (Below about 1e-8, sqrt of the round-off of values
    near 1, no rule can place a minimum.)"""
    star = 0.37
    pts = iterate(lambda u: math.cosh(4 * (u[0] - star)) + (u[0] - star) ** 3, [[0.1], [0.8], [0.5]], False, 5)
    assert len(pts) == 5 and min(abs(p[0] - star) for p in pts) < 1e-6


def test_the_root_refinement_lands_on_a_curve_of_answers():
    """Two variables whose exact answers are a line a u0 - b u1 = c: from four points the steps
    reach it (|s| < 1e-9) within six steps, near its nearest stretch (within the distance of
    the best start from the line)."""
    a, b, c = 2.0, 0.5, 0.6

    def s(u):
        return math.expm1(a * u[0] - b * u[1] - c)

    starts = [[0.2, 0.3], [0.6, 0.7], [0.3, 0.9], [0.7, 0.2]]
    pts = iterate(s, starts, True, 6)
    assert min(abs(s(p)) for p in pts) < 1e-9
    best = min(starts, key=lambda p: abs(s(p)))
    gap = abs(a * best[0] - b * best[1] - c) / math.hypot(a, b)
    assert np.linalg.norm(pts[-1] - best) < 2 * gap


def test_a_trial_asked_while_others_run_goes_elsewhere_and_a_converged_step_gives_way():
    """A running trial at the step's end moves the next one along the step (1.5 times it);
    a step onto finished points at every stride, or shorter than RESOLUTION, gives way (None)."""
    from granel.studies.refine import RESOLUTION, STRIDES, Samples, Step, place, propose

    s = Samples(np.array([[0.2], [0.3], [0.5]]), np.array([-0.4, -0.2, 0.3]))
    first = propose(s, True, np.empty((0, 1)))
    second = propose(s, True, first.reshape(1, 1))
    start = s.points[1]
    assert second[0] - start[0] == pytest.approx(1.5 * (first[0] - start[0]), rel=1e-12)
    step = Step(np.array([0.5]), np.array([0.1]))
    taken = np.array([[0.5 + k * 0.1] for k in STRIDES])
    assert place(step, taken, np.empty((0, 1))) is None
    assert place(Step(np.array([0.5]), np.array([0.5 * RESOLUTION])), np.empty((0, 1)), np.empty((0, 1))) is None


def test_which_designs_refine():
    """`auto` refines one objective with continuous variables and no constraints; an integer or
    categorical variable, a constraint, several objectives or a named sampler keep the old
    samplers (tpe stays TPE alone)."""
    import optuna

    from granel.studies.design import DesignSpec
    from granel.studies.design_search import make_sampler
    from granel.studies.refine import RefiningSampler

    base = {"base": "x.toml", "mode": "run", "pair": ["C:1", "C:8"],
            "variables": [{"field": RADIUS, "low": 0.002, "high": 0.01}],
            "objectives": [{"metric": "cutoff_Hz", "target": 12000.0}]}

    def sampler(**change):
        return make_sampler(DesignSpec.model_validate({**base, **change}), 1)

    assert isinstance(sampler(), RefiningSampler)
    assert isinstance(sampler(objectives=[{"metric": "cutoff_Hz", "direction": "maximize"}]), RefiningSampler)
    assert type(sampler(sampler="tpe")) is optuna.samplers.TPESampler
    assert type(sampler(variables=[{"field": "media.0.columns.0", "low": 2, "high": 6, "integer": True}])) \
        is optuna.samplers.TPESampler
    assert type(sampler(constraints=[{"metric": "granular_mass_kg", "max": 1.0}])) is optuna.samplers.TPESampler
    two = [{"metric": "cutoff_Hz", "target": 12000.0}, {"metric": "granular_mass_kg", "direction": "minimize"}]
    assert type(sampler(objectives=two)) is optuna.samplers.NSGAIISampler


# ---------------------------------------------------------------- studies on the closed form


@dataclass(frozen=True)
class Study:
    """A finished study: each trial's values, in trial order, and the best trial's."""

    params: list
    best: dict


def ask_and_tell(spec, metrics, workers: int) -> Study:
    """The study `run_design` would run, each trial's metrics given by `metrics(params)` in place
    of a run: `workers` trials in flight, the oldest told first (one worker: ask, tell, ask ...),
    through `ask_trial` and `tell`; in memory (the journal's writes cost more than the trials)."""
    import optuna

    from granel.studies.design_search import ask_trial
    from granel.studies.design_trials import tell

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(directions=spec.directions)
    dists = {v.field: v.distribution() for v in spec.variables}
    flight = [ask_trial(study, spec, dists) for _ in range(min(workers, spec.trials))]
    asked = len(flight)
    while flight:
        t = flight.pop(0)
        tell(study, spec, t, {"status": "ok", "metrics": metrics(t.params)})
        if asked < spec.trials:
            flight.append(ask_trial(study, spec, dists))
            asked += 1
    return Study([dict(t.params) for t in study.get_trials()], dict(study.best_trial.params))


def closed_form_study(problem: Problem, seed: int, workers: int, sampler: str = "auto", trials: int = 60) -> Study:
    """A study of `problem` whose trials take the linearised chain's cut-off for a run's."""
    with tempfile.TemporaryDirectory() as d:
        spec, _ = load(problem, Path(d), seed, sampler, trials)
        return ask_and_tell(spec, lambda p: {"cutoff_Hz": problem.cutoff(p)}, workers)


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("name", list(PROBLEMS))
def test_closed_form_searches_land_within_one_percent(name, workers):
    """60 trials of `auto` on the closed form land within the issue's 1 % of the exact answer
    for seeds 1-10, on one worker and on two (trials in flight while others are asked). Measured
    over seeds 1-10: below 1.5e-9 for every one (TPE alone: up to 0.52 % on the radius, 1.07 %
    on the preload, 0.54 % on both)."""
    problem = PROBLEMS[name]
    for seed in QUICK_SEEDS:
        study = closed_form_study(problem, seed, workers)
        assert len(study.params) == 60
        assert abs(problem.error(study.best)) < LANDS, (seed, study.best)


def test_a_target_beyond_the_range_ends_at_its_bound_and_the_study_goes_on():
    """A 5 kHz cut-off needs beads larger than the range's 10 mm: the refinement steps to the
    bound once, then gives way to TPE (a step onto values tried); the study asks 60 distinct
    values, and its best is the bound's."""
    problem = Problem("beyond", PROBLEMS["radius"].variables, 5000.0)
    study = closed_form_study(problem, 1, 1)
    radii = [p[RADIUS] for p in study.params]
    assert len(set(radii)) == 60 and radii.count(0.010) == 1
    assert study.best[RADIUS] == 0.010


def mobility(F0: float, f=1e4, R=0.005, zeta=0.05) -> float:
    """|v / F| of a steel granule of radius R on a rigid wall, pressed by F0 and shaken at f:
    a mass m on the linearised Hertz spring k = 3/2 A^(2/3) F0^(1/3) (A = 4/3 E/(1 - nu^2)
    sqrt(R)) with a dashpot of 2 zeta m w. It peaks where k = m w^2: F0* = (m w^2 / (3/2
    A^(2/3)))^3 = 2.948 N (tests/test_design.py's spectrum objective)."""
    m, w = 4 / 3 * math.pi * R**3 * RHO, 2 * math.pi * f
    k = 1.5 * (4 / 3 * E / (1 - NU**2) * math.sqrt(R)) ** (2 / 3) * F0 ** (1 / 3)
    return w / math.hypot(k - m * w * w, 2 * zeta * m * w * w)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_closed_form_peak_is_found_within_one_percent(workers):
    """A direction objective (maximise the mobility of `mobility`, over F0 in 1.5-6 N, log): 40
    `auto` trials (the quadratic fit after TPE's 13) land within 1 % of F0* for seeds 1-10, on one
    worker and on two. Measured over seeds 1-10: below 1.5e-6 (TPE alone: up to 1.3 %, seed 1 on
    one worker)."""
    from granel.studies.design import DesignSpec

    m, w = 4 / 3 * math.pi * 0.005**3 * RHO, 2 * math.pi * 1e4
    star = (m * w * w / (1.5 * (4 / 3 * E / (1 - NU**2) * math.sqrt(0.005)) ** (2 / 3))) ** 3
    assert star == pytest.approx(2.948, rel=1e-3)
    for seed in QUICK_SEEDS:
        spec = DesignSpec.model_validate({"base": "x.toml", "mode": "run", "pair": ["G:1", "G:1"], "trials": 40,
                                          "seed": seed, "variables": [{"field": PRELOAD, "low": 1.5, "high": 6.0,
                                                                       "log": True}],
                                          "objectives": [{"metric": "peak_velocity_m_s", "direction": "maximize"}]})
        study = ask_and_tell(spec, lambda p: {"peak_velocity_m_s": mobility(p[PRELOAD])}, workers)
        assert len(study.params) == 40
        assert study.best[PRELOAD] == pytest.approx(star, rel=LANDS)


def test_one_worker_with_a_seed_repeats_its_study():
    """The refinement reads only the study's trials: on one worker the same seed asks the same
    values, trial for trial, and another seed other values."""
    problem = PROBLEMS["radius+preload"]

    def values(seed):
        return [tuple(sorted(p.items())) for p in closed_form_study(problem, seed, 1, trials=30).params]

    a = values(4)
    assert a == values(4) and a != values(5) and len(set(a)) == len(a)


# ---------------------------------------------------------------- studies on granel's runs


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("name", list(PROBLEMS))
def test_the_searches_land_on_the_measured_cutoff(tmp_path, name, workers):
    """Each trial's cut-off measured from its own run: 60 `auto` trials land within the issue's
    1 % of the exact answer for seeds 1-3, on one worker and on two; every trial runs. The
    measure's own error (about 1e-6 here) is far below it. docs/design.md tabulates the errors
    against TPE alone."""
    from granel.studies.design_search import DesignRunOptions, run_design

    problem = PROBLEMS[name]
    for seed in SEEDS:
        spec, base = load(problem, tmp_path / f"s{seed}", seed)
        res = run_design(spec, base, tmp_path / f"out{seed}", options=DesignRunOptions(workers=workers))
        assert (res["trials"]["status"].values == "ok").all()
        assert abs(problem.error(res["best"][0].params)) < LANDS, (seed, res["best"][0].params)


@pytest.mark.slow
def test_one_worker_with_a_seed_repeats_a_measured_study(tmp_path):
    """On granel's runs too: one worker and a seed, run twice, give the same trials (values and
    objective), refinement included (20 trials: the last 14 refine)."""
    from granel.studies.design_search import DesignRunOptions, run_design

    def trials(k):
        spec, base = load(PROBLEMS["preload"], tmp_path / f"s{k}", 2, trials=20)
        ds = run_design(spec, base, tmp_path / f"out{k}", options=DesignRunOptions(workers=1))["trials"]
        return list(ds[f"var_{PRELOAD}"].values), list(ds["objective_cutoff_Hz_misfit"].values)

    assert trials(0) == trials(1)
