"""`granel spectrum` and the spectrum mode of the sweep engine: the reciprocity theorem on a
linear (weakly driven, precompressed) chain, the Dataset it writes, resume, and hostile input
(every bad option a clean message naming it, exit 2, before any run)."""

import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app
from granel.studies.spectrum import SpectrumSpec, parse_amplitudes, parse_frequencies
from granel.studies.sweep import SweepSpec

CHAIN = Path(__file__).resolve().parents[1] / "scenarios" / "narrowband" / "precompressed-chain.toml"
runner = CliRunner()


def invoke(args):
    res = runner.invoke(app, [str(a) for a in args])
    out = " ".join(res.output.split())
    assert "Traceback" not in res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), repr(res.exception)
    return res.exit_code, out


def test_frequencies_and_amplitudes_parse():
    assert parse_frequencies("1kHz:40kHz:3") == pytest.approx([1e3, math.sqrt(40) * 1e3, 40e3])
    assert parse_frequencies("1kHz:3kHz:3", linear=True) == pytest.approx([1e3, 2e3, 3e3])
    assert parse_frequencies("500Hz, 2kHz,1.5e4") == [500.0, 2000.0, 15000.0]
    assert parse_amplitudes("10,100N, 0.5") == [10.0, 100.0, 0.5]
    for bad in ("", "1kHz:2kHz", "1kHz:2kHz:0", "1kHz:2kHz:x", "-1kHz", "0", "3 parsecs", "nan"):
        with pytest.raises(ValueError):
            parse_frequencies(bad)
    for bad in ("", "0", "-1", "inf", "ten"):
        with pytest.raises(ValueError):
            parse_amplitudes(bad)


def test_spectrum_sweep_files_are_checked():
    axis = {"field": "excitations.0.frequency", "values": [1e4]}
    table = {"drive": "C:1", "measure": "C:20"}
    with pytest.raises(ValueError, match=r"\[spectrum\] table"):
        SweepSpec.model_validate({"mode": "spectrum", "axes": [axis]})
    with pytest.raises(ValueError, match=r"only that mode"):
        SweepSpec.model_validate({"mode": "run", "spectrum": table, "axes": [axis]})
    with pytest.raises(ValueError, match=r"axis on excitations.0.frequency"):
        SweepSpec.model_validate({"mode": "spectrum", "spectrum": table,
                                  "axes": [{"field": "excitations.0.amplitude", "values": [1.0]}]})
    with pytest.raises(ValueError, match=r"window_cycles.*ramp_cycles.*exceed cycles"):
        SpectrumSpec(drive="C:1", measure="C:20", cycles=10, window_cycles=8, ramp_cycles=5)
    sp = SpectrumSpec(drive="C:1", measure="C:20", cycles=20, samples_per_period=20)
    ov = sp.overrides(1e4, "C:20")
    assert 'excitations.0.granule="C:20"' in ov and "simulation.duration=0.002" in ov
    assert any(o.startswith("simulation.output_every=5e-06") for o in ov)


@pytest.mark.parametrize("args, needle", [
    (["--drive", "C:99"], "--drive = 'C:99': no such granule"),
    (["--measure", "X:1"], "--measure = 'X:1': no such granule"),
    (["--measure", "C:1"], "the same granule as --drive"),
    (["--frequencies", "1kHz:2kHz"], "--frequencies 1kHz:2kHz: "),
    (["--amplitudes", "-3"], "--amplitudes -3: not a positive force amplitude"),
    (["--cycles", "4"], "exceed cycles"),
    (["--samples", "3"], "samples"),
    (["-o", "OUT/spec.txt"], "ending in .nc"),
])
def test_hostile_options(tmp_path, args, needle):
    base = {"--drive": "C:1", "--measure": "C:20", "--frequencies": "8kHz", "--amplitudes": "0.1",
            "-o": str(tmp_path / "spec.nc")}
    for k, v in zip(args[::2], args[1::2]):
        base[k] = v.replace("OUT", str(tmp_path))
    flat = [x for kv in base.items() for x in kv]
    code, out = invoke(["spectrum", CHAIN, *flat, "--both-directions"])
    assert code == 2, out
    assert needle in out, out
    assert not (tmp_path / "spec.cases").exists()  # nothing was run


def test_missing_scenario_and_unwritable_output(tmp_path):
    code, out = invoke(["spectrum", tmp_path / "none.toml", "--drive", "C:1", "--measure", "C:20", "--frequencies", "8kHz",
                        "--amplitudes", "0.1"])
    assert code == 2 and "no such scenario file" in out
    (tmp_path / "d.nc").mkdir()
    code, out = invoke(["spectrum", CHAIN, "--drive", "C:1", "--measure", "C:20", "--frequencies", "8kHz",
                        "--amplitudes", "0.1", "-o", tmp_path / "d.nc"])
    assert code == 2 and "is a folder" in out


@pytest.mark.slow  # a two-direction spectrum on a cluster (about 17 s)
def test_a_weakly_driven_chain_is_reciprocal(tmp_path):
    """The reciprocity theorem: a linear elastic (and viscously damped) system's transfer mobility
    is the same both ways. A precompressed chain driven by 0.1 N against its 10 N preload is
    linear to about 1 %: the mobilities from bead 1 to bead 20 and back agree within 0.02 dB at
    8 and 12 kHz (below its 17.3 kHz cut-off; measured over 40 cycles: 1.0e-4 and 5.8e-5 dB), while at 22 kHz,
    above it, the far bead hears 40 dB less than below. The command writes the spectrum
    (frequency x amplitude x direction), its figure and report, and a rerun reuses every run."""
    out = tmp_path / "spec.nc"
    args = ["spectrum", CHAIN, "--drive", "C:1", "--measure", "C:20", "--frequencies", "8kHz,12kHz,22kHz",
            "--amplitudes", "0.1", "--both-directions", "--cycles", "30", "--workers", "1", "-o", out]
    code, text = invoke(args)
    assert code == 0, text
    ds = xr.open_dataset(out)
    assert dict(ds["mobility"].sizes) == {"direction": 2, "frequency": 3, "amplitude": 1}
    assert list(ds["direction"].values) == ["fwd", "bwd"]
    nr = ds["nonreciprocity_db"].sel(amplitude=0.1).values
    assert abs(nr[0]) < 0.02 and abs(nr[1]) < 0.02, nr
    mob = ds["mobility"].sel(amplitude=0.1, direction="fwd").values
    assert mob[2] < 1e-2 * min(mob[0], mob[1]), mob
    assert np.nanmax(ds["balance"].values) < 1e-5
    assert out.with_suffix(".png").stat().st_size > 0 and "# Spectrum" in out.with_suffix(".md").read_text()
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "spec.cases" / "cases").glob("*.nc")}
    assert len(stamps) == 6
    code, _ = invoke(args)
    assert code == 0
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # resumed: no run repeated
    ds.close()
    assert S.load(str(CHAIN)).simulation.equilibrate
