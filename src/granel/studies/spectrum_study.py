"""`granel spectrum` as a sweep: the sweep of a scenario's first excitation over frequencies x
amplitudes in spectrum mode (`spectrum_sweep`), its options checked (`plan_spectrum`), its cases
run beside the spectrum and the spectrum written (`run_spectrum`)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import xarray as xr

from .. import scenario as S
from ..guard.exits import InputError, NotWritten, option_value
from . import sweep as SW
from .spectrum import AMPLITUDE_FIELD, FREQUENCY_FIELD, parse_amplitudes, parse_frequencies, stored_chain
from .spectrum_report import write_spectrum


def spectrum_sweep(scenario: str, overrides, frequencies, amplitudes, **settings):
    """The sweep behind `granel spectrum`: `scenario` (a built-in name, or a file, then given by
    its absolute path) with `overrides`, in spectrum mode with `settings` (`SpectrumSpec`'s
    fields), over its first excitation's frequencies x amplitudes. pydantic's ValidationError for
    invalid settings."""
    builtin = scenario in S.builtin_names()
    return SW.SweepSpec.model_validate({
        "name": f"spectrum of {scenario if builtin else Path(scenario).stem}",
        "base": scenario if builtin else str(Path(scenario).resolve()), "overrides": list(overrides), "mode": "spectrum",
        "spectrum": settings,
        "axes": [{"field": FREQUENCY_FIELD, "values": list(frequencies)},
                 {"field": AMPLITUDE_FIELD, "values": list(amplitudes)}]})


def cases_folder(path):
    """Where `run_spectrum` keeps the runs of the spectrum written to `path`: PATH with .cases."""
    return Path(path).with_suffix(".cases")


def run_spectrum(spec, path, workers: int = 2, scheduler: str | None = None, progress=None) -> xr.Dataset:
    """Run every case of the spectrum sweep `spec` (`run_spec`, its files relative to the
    working folder; finished runs in `cases_folder(path)` are reused), then write the spectrum
    (`write_spectrum`: PATH, its .png and .md) and return it. `progress(case result)` after each
    case. A failed write of the spectrum is `guard.exits.NotWritten`; an OSError of the runs'
    folder passes as it is."""
    summary = SW.run_spec(spec, Path("."), cases_folder(path), workers, scheduler, progress)
    try:
        return write_spectrum(summary, spec.spectrum, path, *stored_chain(spec, SW.cases(spec), cases_folder(path)))
    except OSError as e:
        raise NotWritten("the spectrum", path, e) from e


# the command-line option of each field of `granel spectrum`'s settings (`spectrum.SpectrumSpec`)
SPECTRUM_OPTIONS = {"samples_per_period": "--samples", "spectrum.drive": "--drive", "spectrum.measure": "--measure"}


def _as_options(text: str) -> str:
    """A settings error in the command line's words: its fields named by their options."""
    for field, option in SPECTRUM_OPTIONS.items():
        text = text.replace(field, option)
    return text


def plan_spectrum(scenario: str, overrides, frequencies: str, amplitudes: str, out: Path, linear: bool = False,
                  **settings):
    """`granel spectrum`'s sweep (`spectrum_sweep`) from its options, every one checked before
    any computation (InputError or ScenarioError naming the option or the scenario), and its
    outputs (OUT, its .png and .md, its .cases folder) checked and made."""
    from pydantic import ValidationError

    from ..guard.outputs import OutputPlan
    from ..guard.reading import check_file

    for name in ("cycles", "window_cycles", "ramp_cycles"):
        if not np.isfinite(settings[name]):
            raise InputError(f"--{name.replace('_', '-')} {settings[name]}: give a finite number of periods")
    freqs = option_value("--frequencies", frequencies, lambda text: parse_frequencies(text, linear))
    amps = option_value("--amplitudes", amplitudes, parse_amplitudes)
    if scenario == S.STDIN:
        raise InputError("spectrum -: a spectrum's runs read their scenario in every worker; give a scenario file, not "
                         "standard input")
    if scenario not in S.builtin_names():
        if not os.path.lexists(scenario):  # neither a file nor a built-in name (nor a name too long for one)
            raise InputError(f"{scenario}: no such scenario file or built-in scenario ({', '.join(S.builtin_names())})")
        check_file(Path(scenario), "scenario")  # a folder, a FIFO, a dangling link, ...: exit 2 or 4 naming it
    try:
        spec = spectrum_sweep(scenario, overrides, freqs, amps, **settings)
    except ValidationError as e:
        lines = []
        for err in e.errors():
            field = ".".join(str(p) for p in err["loc"] if p != "spectrum")
            msg = err["msg"].removeprefix("Value error, ")
            if not field:  # a check of several settings: each named by its option in the message
                lines.append(re.sub(r"\b[a-z]+(?:_[a-z]+)+\b", lambda m: "--" + m.group(0).replace("_", "-"), msg))
                continue
            shown = repr(err.get("input"))
            lines.append(f"{SPECTRUM_OPTIONS.get(field, '--' + field.replace('_', '-'))} = "
                         f"{shown if len(shown) <= 80 else shown[:77] + '...'}: {msg}")
        raise InputError("invalid option: " + "; ".join(lines)) from None
    if Path(out).suffix != ".nc":
        raise InputError(f"-o {out}: give a NetCDF file name ending in .nc")
    try:
        SW.check_mode(spec, Path("."), SW.cases(spec)[0])
    except S.ScenarioError as e:
        msg = _as_options(str(e))
        raise S.ScenarioError(msg if scenario in msg or "--drive" in msg or "--measure" in msg
                              else f"{scenario}: {msg}", e.code) from None
    plan = OutputPlan(inputs=SW.sweep_inputs(spec, Path(".")))
    plan.file(out, "-o")
    plan.file(out.with_suffix(".png"), "-o (its figure)")
    plan.file(out.with_suffix(".md"), "-o (its report)")
    plan.folder(cases_folder(out), "-o (its .cases folder)", "spectrum", recognise=lambda p: (p / "cases").is_dir())
    plan.check().prepare()
    return spec
