"""Study modes: what one case of a sweep or a design runs, and what it measures.

A case is the base scenario with the study's and the case's overrides. Its mode gives the runs
it makes (one for `run`, both shock directions for `reciprocity`, a harmonic drive from each
end for `spectrum`), the case's metrics from their results, and what else of the study its
stored result depends on. The sweep engine and the design search use a mode only through
`StudyMode`; `MODES` maps the names a study file gives (`mode = "..."`) to them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np

from .. import scenario as S
from ..analysis.reciprocity import excitation_of, input_energy, reciprocity_metrics, run_metrics
from ..guard.exits import NotWritten
from . import spectrum, spectrum_report
from .spectrum import FREQUENCY_FIELD

# a case's runs: (key, scenario), the key naming the run's file and its result
Runs = list[tuple[str, S.Scenario]]

SIZE_UNITS = {"granular_mass_kg": "kg", "footprint_m2": "m^2"}
SETTINGS_TABLE = 'mode = "spectrum" needs a [spectrum] table (drive, measure, ...), and only that mode takes one'
BAND = "frequencies: a design in spectrum mode needs its band's frequencies [Hz], and only that mode takes them"
PEAK_METRICS = ("peak_contact_force_N", "peak_wall_force_N", "peak_solid_force_N")


class StudyMode(ABC):
    """One way of running and measuring a case. A mode implements `scenarios`, `metric_units`
    and `measure`, may refine the other methods, and is listed in `MODES`. Every method takes
    the study's `CaseSpec` (a sweep's or a design's), whose `mode` names this one."""

    name: ClassVar[str]

    @abstractmethod
    def scenarios(self, spec, base: str, overrides: list[str], values: dict, check_usage: bool = True) -> Runs:
        """The runs of one case: the scenario at `base` with `overrides` (the study's and the
        case's), and what the mode sets for each run; `values` holds the case's axis values
        by field. `check_usage`: refuse an override that no run uses (`scenario.load`)."""

    @abstractmethod
    def metric_units(self, spec) -> dict[str, str]:
        """Every metric `measure` reports, with its unit ("1": a ratio)."""

    @abstractmethod
    def measure(self, spec, scenarios: Runs, runs: dict) -> tuple[dict[str, float], dict[str, str]]:
        """A case's metrics from the results of its runs (`runs`, by key), and why, for each
        metric that is NaN because the runs cannot give it."""

    def fingerprint(self, spec) -> dict:
        """What a case's stored result depends on beyond its scenarios and overrides: the mode
        and the study's settings for a mode (its pair and [spectrum] table), whether or not this
        mode reads them; stored cases are matched on these keys."""
        return {"mode": self.name, "pair": list(spec.pair),
                "spectrum": spec.spectrum.model_dump() if spec.spectrum is not None else None}

    def check(self, spec, base: str, overrides: list[str], values: dict) -> None:
        """Fail before anything runs (ScenarioError naming the field) when the mode's settings
        do not fit a case's scenario (arguments as `scenarios`'); nothing to check by default."""

    def check_settings(self, spec) -> None:
        """ValueError when a study holds another mode's settings, or lacks its own: the
        [spectrum] table belongs to spectrum mode alone."""
        if spec.spectrum is not None:
            raise ValueError(SETTINGS_TABLE)

    def check_axes(self, fields: set[str]) -> None:
        """ValueError when a sweep's axes (the fields they set) do not serve the mode."""

    def check_band(self, frequencies) -> None:
        """ValueError when a design's band of drive frequencies does not fit the mode: spectrum
        mode alone takes one."""
        if frequencies is not None:
            raise ValueError(BAND)

    def sweep_outputs(self, spec) -> tuple[str, ...]:
        """The files a sweep in this mode writes beside its summary.nc."""
        return ()

    def finish_sweep(self, spec, summary, out_dir, case_list: list[dict]) -> None:
        """Write `sweep_outputs` from the sweep's summary and its cases (`out_dir`/cases)."""

    def energy_scale(self, ds) -> float:
        """What a run's energies are divided by in a design's report: its input energy."""
        return max(input_energy(ds), 1e-300)

    energy_label: ClassVar[str] = "energy / input work"
    energy_title: ClassVar[str] = "energy held (tighter accuracy)"

    def describe(self, spec) -> str:
        """What a report adds after the mode's name (the reciprocity mode's pair)."""
        return ""

    def trial_cases(self, spec, case: dict) -> list[tuple[dict, str]]:
        """The cases a design's trial runs, each with the words that place a failure in it:
        the trial's own case by default."""
        return [(case, "")]

    def trial_metrics(self, spec, per_case: list[dict]) -> dict[str, float]:
        """A trial's metrics from its cases' metrics, in `trial_cases` order."""
        return per_case[0]

    def trial_metric_units(self, spec) -> dict[str, str]:
        """Every metric of a design's trial, with its unit: what its objectives and constraints
        may name."""
        return self.metric_units(spec)


class RunMode(StudyMode):
    """One run of the scenario as it is, measured at the pair's granule that the first load
    does not drive. Its metrics: `analysis.reciprocity.run_metrics`, the chain's cut-off
    (`chain_metrics`), the size and the peak forces (`force_metrics`)."""

    name = "run"
    UNITS = {"arrival_measured_s": "s", "arrival_solid_s": "s", "peak_velocity_m_s": "m/s",
             "energy_far_peak_frac": "1", "energy_far_final_frac": "1", "solid_energy_peak_frac": "1",
             "input_work_J": "J", "spectral_centroid_hz": "Hz", "cutoff_Hz": "Hz", "peak_solid_displacement_m": "m"}

    def scenarios(self, spec, base, overrides, values, check_usage=True):
        return [("run", S.load(base, overrides, check_usage))]

    def metric_units(self, spec):
        return {**self.UNITS, **force_metric_units(["run"])}

    def measure(self, spec, scenarios, runs):
        ds = runs["run"]
        label, _ = excitation_of(ds)
        measured = spec.pair[0] if label == spec.pair[1] else spec.pair[1]
        r = run_metrics(ds, measured)
        metrics = {k: float(v) for k, v in r.items() if isinstance(v, (int, float))}
        chain, notes = chain_metrics(ds)
        solid, solid_notes = solid_metrics(ds)
        return {**metrics, **chain, **solid, **force_metrics(scenarios, runs)}, {**r["notes"], **notes, **solid_notes}


class ReciprocityMode(StudyMode):
    """Both directions of a shock: forward drives the pair's second granule and measures at the
    first, backward the reverse. Its metrics: the nonreciprocity index and each direction's
    (`analysis.reciprocity.reciprocity_metrics`, suffixed _fwd / _bwd), the size and the peak
    forces of each run."""

    name = "reciprocity"
    UNITS = {"nonreciprocity_index": "1", "arrival_fwd_s": "s", "arrival_bwd_s": "s", "peak_velocity_fwd": "m/s",
             "peak_velocity_bwd": "m/s", "energy_far_fwd": "1", "energy_far_bwd": "1", "solid_energy_fwd": "1",
             "solid_energy_bwd": "1", "centroid_fwd_hz": "Hz", "centroid_bwd_hz": "Hz", "arrival_solid_fwd_s": "s",
             "arrival_solid_bwd_s": "s"}
    # each direction's metric of `reciprocity_metrics` -> the case's metric, and the notes that follow them
    PER_DIRECTION = {"arrival_measured_s": "arrival_{}_s", "peak_velocity_m_s": "peak_velocity_{}",
                     "energy_far_peak_frac": "energy_far_{}", "solid_energy_peak_frac": "solid_energy_{}",
                     "spectral_centroid_hz": "centroid_{}_hz", "arrival_solid_s": "arrival_solid_{}_s"}
    NOTED = ("energy_far_peak_frac", "solid_energy_peak_frac", "arrival_solid_s")

    @staticmethod
    def keys(spec) -> list[str]:
        """The runs' keys, forward first: shock-<the driven granule's label without ':'>."""
        a, b = spec.pair
        return [f"shock-{exc.replace(':', '')}" for exc in (b, a)]

    def scenarios(self, spec, base, overrides, values, check_usage=True):
        a, b = spec.pair
        return [(key, S.load(base, overrides + [f'excitations.0.granule="{exc}"'], check_usage))
                for key, exc in zip(self.keys(spec), (b, a))]

    def metric_units(self, spec):
        return {**self.UNITS, **force_metric_units(self.keys(spec))}

    def describe(self, spec):
        return f", pair {spec.pair[0]} / {spec.pair[1]}"

    def measure(self, spec, scenarios, runs):
        fwd, bwd = self.keys(spec)
        m = reciprocity_metrics(runs[fwd], runs[bwd])
        metrics = {"nonreciprocity_index": m["nonreciprocity_index"]}
        for key, name in self.PER_DIRECTION.items():
            metrics.update({name.format(way): m[side][key] for way, side in (("fwd", "forward"), ("bwd", "backward"))})
        notes = {self.PER_DIRECTION[key].format(way): why for way, side in (("fwd", "forward"), ("bwd", "backward"))
                 for key, why in m[side]["notes"].items() if key in self.NOTED}
        return {**metrics, **force_metrics(scenarios, runs)}, notes


class SpectrumMode(StudyMode):
    """A harmonic drive at the case's frequency (its value of `excitations.0.frequency`) from the
    [spectrum] table's drive granule and, with both_directions, from its measured one
    (`spectrum.SpectrumSpec`). Its metrics: `spectrum.case_metrics`, the size and the peak forces
    of each run. A design's trial runs one case per frequency of its band (`frequencies`), and
    its metrics are the band's (`spectrum.band_metrics`, the size, the band's largest peaks)."""

    name = "spectrum"
    # a narrowband drive on a preloaded system does little work against the energy the preload
    # stores: its report shows the energies in joules
    energy_label = "energy held [J]"
    energy_title = "energy held (tighter accuracy), first frequency"

    def energy_scale(self, ds):
        return 1.0

    def check_settings(self, spec):
        if spec.spectrum is None:
            raise ValueError(SETTINGS_TABLE)

    def check_axes(self, fields):
        if FREQUENCY_FIELD not in fields:
            raise ValueError(f"a spectrum needs an axis on {FREQUENCY_FIELD}")

    def check_band(self, frequencies):
        if frequencies is None:
            raise ValueError(BAND)

    def sweep_outputs(self, spec):
        return ("spectrum.nc", "spectrum.png", "spectrum.md")

    def finish_sweep(self, spec, summary, out_dir, case_list):
        path = Path(out_dir) / "spectrum.nc"
        try:
            spectrum_report.write_spectrum(summary, spec.spectrum, path, *spectrum.stored_chain(spec, case_list, out_dir))
        except OSError as e:
            raise NotWritten("the spectrum", path, e) from e

    def scenarios(self, spec, base, overrides, values, check_usage=True):
        f = float(values[FREQUENCY_FIELD])
        if not (np.isfinite(f) and f > 0):
            raise S.ScenarioError(f"{FREQUENCY_FIELD}: a drive frequency must be positive, got {f!r}")
        return [(d, S.load(base, overrides + spec.spectrum.overrides(f, driven), check_usage))
                for d, driven, _ in spec.spectrum.runs()]

    def metric_units(self, spec):
        return {**spectrum.case_metric_units(spec.spectrum), **force_metric_units(self._directions(spec))}

    def measure(self, spec, scenarios, runs):
        return {**spectrum.case_metrics(runs, spec.spectrum), **force_metrics(scenarios, runs)}, {}

    def check(self, spec, base, overrides, values):
        """Refuse (naming `spectrum.drive` or `spectrum.measure`) granules the case's scenario
        lacks, or both directions driving one granule; builds the case's granular systems,
        which also checks their scenarios."""
        from ..scenario.build import build_granular

        sp = spec.spectrum
        if sp.both_directions and sp.drive == sp.measure:
            raise S.ScenarioError(f"spectrum.measure = {sp.measure!r}: the same granule as spectrum.drive; both "
                                  "directions need two granules")
        f = float(values[FREQUENCY_FIELD])
        for _, driven, _ in sp.runs():
            try:
                sc = S.load(base, overrides + sp.overrides(f, driven))
                system = build_granular(sc, sc.base)[0]
            except S.ScenarioError as e:
                if "excitations.0.granule" in str(e) and "no such granule" in str(e):
                    which = "drive" if driven == sp.drive else "measure"
                    raise S.ScenarioError(f"spectrum.{which} = {driven!r}: no such granule in {spec.base}") from None
                raise
            if sp.measure not in system.labels:  # measured in every direction, driven only in both
                raise S.ScenarioError(f"spectrum.measure = {sp.measure!r}: no such granule in {spec.base} (e.g. "
                                      f"{system.labels[-1]!r})")

    def trial_cases(self, spec, case):
        return [({"index": [*case["index"], k], "overrides": {**case["overrides"], FREQUENCY_FIELD: float(f)},
                  "tag": f"{case['tag']}-f{k:03d}"}, f"at {f:g} Hz") for k, f in enumerate(spec.frequencies)]

    def trial_metrics(self, spec, per_case):
        out = spectrum.band_metrics(spec.spectrum, per_case)
        for key in per_case[0]:
            if key in SIZE_UNITS:
                out[key] = float(per_case[0][key])
            elif key.startswith("peak_"):
                out[key] = float(np.max([m[key] for m in per_case]))
        return out

    def trial_metric_units(self, spec):
        return {**spectrum.band_metric_units(spec.spectrum), **force_metric_units(self._directions(spec))}

    @staticmethod
    def _directions(spec) -> list[str]:
        return [d for d, _, _ in spec.spectrum.runs()]


# the study modes by the name a study file gives
MODES: dict[str, StudyMode] = {m.name: m for m in (ReciprocityMode(), RunMode(), SpectrumMode())}
# the type of a study's `mode` field: one of MODES (pydantic refuses any other, naming the field)
ModeName = Literal[tuple(MODES)]  # type: ignore[valid-type]


def study_mode(name: str) -> StudyMode:
    """The mode called `name`; ValueError naming the field for an unknown one."""
    try:
        return MODES[name]
    except (KeyError, TypeError):
        raise ValueError(f"mode = {name!r}: not a study mode; choose from {', '.join(map(repr, MODES))}") from None


# ---------------------------------------------------------------- metrics every mode reports


def chain_metrics(ds) -> tuple[dict[str, float], dict[str, str]]:
    """A run's chain metrics and, for each one that is NaN, why: cutoff_Hz, the cut-off of a
    precompressed monatomic chain rung by a pulse (`analysis.narrowband.cutoff_frequency`: its
    highest mode measured in the free response, over the mode's share of the cut-off for the
    chain's ends). A run without a static precompression is NaN at once, its reason noted."""
    from ..analysis.narrowband import CutoffError, cutoff_frequency
    from ..analysis.result_model import result_system

    try:
        if "equilibrium_contact" not in ds:
            raise CutoffError("the run has no static precompression (simulation.equilibrate = true with a constant "
                              "load): a cut-off belongs to a precompressed chain")
        return {"cutoff_Hz": cutoff_frequency(ds, result_system(ds)).cutoff_hz}, {}
    except CutoffError as e:
        return {"cutoff_Hz": float("nan")}, {"cutoff_Hz": str(e)}


def solid_metrics(ds) -> tuple[dict[str, float], dict[str, str]]:
    """peak_solid_displacement_m: the largest displacement of the solid's drawn nodes over the
    run (`analysis.solid.peak_displacement`; a plate in bending's deflection along the line the
    granules strike), read through the result's model record; 0 without an elastic solid (a
    rigid one or none moves nothing, as the peak forces are 0 without their contacts). NaN, with
    the reason, for a run that did not store its solid's state (simulation.outputs.solid = false)."""
    from ..analysis.result_model import result_modes, result_solid
    from ..analysis.solid import peak_displacement

    name = "peak_solid_displacement_m"
    model = result_solid(ds)
    if not model.ndof:
        return {name: 0.0}, {}
    if "solid_time" not in ds or ("solid_eta" not in ds and "solid_x" not in ds):
        return {name: float("nan")}, {name: "the run stores no solid state (simulation.outputs.solid = false)"}
    modes = result_modes(ds) if "solid_eta" in ds else None
    return {name: peak_displacement(ds, model, modes)[0]}, {}


def run_suffixes(keys: list[str]) -> list[str]:
    """The suffix of each run's peak forces in its case's metrics: none for one run, _fwd and
    _bwd for two (forward first), _KEY for any run after the first of more."""
    return ["_fwd", "_bwd"] if len(keys) == 2 else ["", *(f"_{k}" for k in keys[1:])]


def force_metrics(scenarios: Runs, runs: dict) -> dict[str, float]:
    """A case's size and peak forces (`analysis.contacts`): granular_mass_kg, footprint_m2 (of
    the first run's scenario) and, per run, peak_contact_force_N and peak_wall_force_N, suffixed
    as `run_suffixes` says."""
    from ..analysis.contacts import design_size, peak_forces  # lazy: a slow import
    from ..analysis.result_model import result_system

    out: dict[str, float] = {}
    for k, ((key, _), suffix) in enumerate(zip(scenarios, run_suffixes([key for key, _ in scenarios]))):
        system = result_system(runs[key])
        if k == 0:
            out.update(design_size(system))
        peaks = peak_forces(runs[key], system)
        for name in PEAK_METRICS:
            out[name.replace("_N", f"{suffix}_N")] = peaks[name]
    return out


def force_metric_units(keys: list[str]) -> dict[str, str]:
    """The names of `force_metrics` for runs with these keys, with their units."""
    return {**SIZE_UNITS, **{name.replace("_N", f"{s}_N"): "N" for name in PEAK_METRICS for s in run_suffixes(keys)}}
