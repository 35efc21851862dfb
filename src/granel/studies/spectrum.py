"""Frequency-resolved transmission and nonreciprocity: the measures of one harmonically driven run
(`run_measures`: mobility, transmissibility, harmonics, period, steadiness, the energy balance
(13)) for the `spectrum` study mode (`modes.SpectrumMode`), the nonreciprocity
20 log10(mobility_fwd / mobility_bwd) [dB], and the spectrum Dataset with the band measures beside
the runs' linearised chain's (`spectrum_chain`); its figure and report are `spectrum_report`'s.
docs/narrowband.md ("The measures, and why mobility", "Band measures") defines them."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import xarray as xr
from pydantic import BaseModel, ConfigDict, Field

FREQUENCY_FIELD = "excitations.0.frequency"
AMPLITUDE_FIELD = "excitations.0.amplitude"
DIRECTIONS = ("fwd", "bwd")
# each run's measures (`run_measures`) and their units ("1": a ratio; period: in drive periods)
PER_DIRECTION = {"mobility": "m/(N s)", "transmissibility": "1", "drift": "1", "drive_velocity": "m/s",
                 "measured_velocity": "m/s", "solid_force": "1", "wall_force": "1", "harmonic2": "1", "harmonic3": "1",
                 "subharmonic2": "1", "period": "1", "steady": "1", "balance": "1"}
# the linearised chain's response per direction over frequency (`linear_spectrum`), and units
LINEAR = {"transmissibility_linear": "1", "mobility_linear": "m/(N s)", "wall_force_linear": "1"}
# the band measures of a transmissibility curve (`curve_bands`), per amplitude and direction
# measured, per direction for the linearised chain (suffixed _linear)
BAND_MEASURES = {"passband_db": "dB", "cutoff_hz": "Hz", "db20_hz": "Hz", "wall_force_db": "dB",
                 "optical_bottom_hz": "Hz", "optical_top_hz": "Hz", "gap_attenuation_db": "dB"}
# a granule is driven along the chain when its direction and the chain's axis agree to this (1 - |cos|)
ALONG = 1e-6
# the response repeats within this (RMS over RMS) from period to period in a steady window
STEADY_RTOL = 2e-2
# a nonreciprocity is read where both mobilities are within this factor of the largest at that
# amplitude (60 dB): far below it, deep in a stop band, they can be at the run's floor of transients
RESOLVED = 1e-3


class SpectrumSpec(BaseModel):
    """The `[spectrum]` table of a sweep in spectrum mode."""

    model_config = ConfigDict(extra="forbid")
    drive: str = Field(min_length=1, description="the driven granule, MEDIUM:LABEL")
    measure: str = Field(min_length=1, description="the measured granule, MEDIUM:LABEL")
    both_directions: bool = True
    cycles: float = Field(40.0, gt=0, description="drive periods per run")
    window_cycles: float = Field(10.0, gt=0, description="the last periods analysed")
    ramp_cycles: float = Field(5.0, ge=0, description="periods of the drive's smooth ramp-up")
    samples_per_period: int = Field(24, ge=8, le=1000, description="outputs per drive period")

    def model_post_init(self, _):
        if self.window_cycles + self.ramp_cycles > self.cycles:
            raise ValueError(f"window_cycles ({self.window_cycles:g}) + ramp_cycles ({self.ramp_cycles:g}) exceed cycles "
                             f"({self.cycles:g}): the window would include the ramp")

    def runs(self) -> list[tuple[str, str, str]]:
        """(direction, driven granule, measured granule) of each run of a case."""
        out = [("fwd", self.drive, self.measure)]
        if self.both_directions:
            out.append(("bwd", self.measure, self.drive))
        return out

    def overrides(self, frequency: float, driven: str) -> list[str]:
        """The scenario overrides of one run at `frequency` driving `driven`."""
        return ['excitations.0.kind="harmonic"', f'excitations.0.granule="{driven}"', "excitations.0.t0=0.0",
                f"excitations.0.ramp_cycles={self.ramp_cycles!r}",
                f"simulation.duration={self.cycles / frequency!r}",
                f"simulation.output_every={1.0 / (frequency * self.samples_per_period)!r}"]


# ---------------------------------------------------------------- command-line values

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_HZ = {"hz": 1.0, "khz": 1e3, "mhz": 1e6}


def parse_frequency(text: str) -> float:
    """'2kHz' -> 2000.0; '1.5e4' -> 15000.0 (bare numbers are hertz)."""
    m = re.fullmatch(rf"\s*({_NUM})\s*([a-zA-Z]*)\s*", text)
    unit = m.group(2).lower() if m else None
    if not m or (unit and unit not in _HZ):
        raise ValueError(f"not a frequency: {text!r} (use e.g. 2kHz, 500Hz, 1.5e4)")
    f = float(m.group(1)) * _HZ.get(unit or "hz")
    if not (math.isfinite(f) and f > 0):
        raise ValueError(f"not a positive frequency: {text!r}")
    return f


def parse_frequencies(text: str, linear: bool = False) -> list[float]:
    """'1kHz:40kHz:20' -> 20 frequencies from 1 to 40 kHz, geometric (linear if `linear`);
    '2kHz,5kHz,10kHz' -> those."""
    text = text.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise ValueError(f"{text!r}: give START:STOP:COUNT, e.g. 1kHz:40kHz:20")
        a, b = parse_frequency(parts[0]), parse_frequency(parts[1])
        try:
            n = int(parts[2])
        except ValueError:
            raise ValueError(f"{text!r}: COUNT must be a whole number, got {parts[2]!r}") from None
        if n < 1:
            raise ValueError(f"{text!r}: COUNT must be at least 1")
        vals = np.linspace(a, b, n) if linear else np.geomspace(a, b, n)
        return [float(v) for v in vals]
    vals = [parse_frequency(p) for p in text.split(",") if p.strip()]
    if not vals:
        raise ValueError("no frequency given")
    return vals


def parse_amplitudes(text: str) -> list[float]:
    """'10,100,1000' or '10N,100N' -> force amplitudes [N], each positive and finite."""
    out = []
    for p in (q.strip() for q in text.split(",")):
        if not p:
            continue
        m = re.fullmatch(rf"({_NUM})\s*(N?)", p)
        v = float(m.group(1)) if m else float("nan")
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"not a positive force amplitude: {p!r} (use e.g. 10,100 or 10N)")
        out.append(v)
    if not out:
        raise ValueError("no amplitude given")
    return out


# ---------------------------------------------------------------- one run's measures

def touching_wall(ds, label: str, direction) -> int | None:
    """The index of the wall granule `label` touches at the first output (its centre over the
    segment, its overlap above -ROUND_OFF of its radius, `granular.geometry`), the most nearly
    along `direction` of them; None when it touches none. Read from the result's model record."""
    from ..granular.geometry import ROUND_OFF
    from ..io.results import granule_column

    if not ds.sizes.get("wall", 0):
        return None
    g = granule_column(ds, label, "finding the wall a granule touches")
    medium = str(ds["medium"].values[g])
    p = np.array([ds["x"].values[0, g], ds["y"].values[0, g]])
    R = float(ds["granule_radius"].values[g])
    best, score = None, -1.0
    for w in range(ds.sizes["wall"]):
        if str(ds["wall_medium"].values[w]) not in ("", medium):
            continue
        p0, p1 = np.asarray(ds["wall_p0"].values[w], float), np.asarray(ds["wall_p1"].values[w], float)
        n = np.asarray(ds["wall_normal"].values[w], float)
        tangent = (p1 - p0) / np.hypot(*(p1 - p0))
        along = float((p - p0) @ tangent)
        if 0.0 <= along <= float(np.hypot(*(p1 - p0))) and R - float((p - p0) @ n) > -ROUND_OFF * R:
            if abs(float(n @ direction)) > score:
                best, score = w, abs(float(n @ direction))
    return best


def run_measures(ds, measured: str, window_cycles: float) -> dict:
    """The measures of one harmonically driven run at granule `measured` (docs/narrowband.md, "The
    measures, and why mobility")."""
    from ..analysis.balance import relative_balance_error
    from ..analysis.narrowband import drive_of, harmonic_amplitudes, response_period, steady_window
    from ..analysis.reciprocity import pushed_along
    from ..io.results import granule_column, require

    drive = drive_of(ds)
    f, F = drive.frequency, abs(drive.amplitude)
    T = 1.0 / f
    t = ds["time"].values

    def along(label):
        d = pushed_along(ds, label)
        g = granule_column(ds, label, "the harmonic measures")
        return ds["v_x"].values[:, g] * d[0] + ds["v_y"].values[:, g] * d[1]

    hi = t[-1]
    window = (hi - window_cycles * T, hi)
    vb = along(measured)
    amps = harmonic_amplitudes(t, vb, f, orders=(1, 2, 3), subharmonics=(2,), window=window)
    va = harmonic_amplitudes(t, along(drive.granule), f, orders=(1,), subharmonics=(), window=window)["f"]
    require(ds, ["contact_force_normal"] * bool(ds.sizes.get("contact", 0)), "the harmonic measures")
    if ds.sizes.get("contact", 0):
        fs = harmonic_amplitudes(t, ds["contact_force_normal"].values.sum(axis=1), f, orders=(1,), subharmonics=(),
                                 window=window)["f"]
    else:
        fs = 0.0
    w = touching_wall(ds, measured, pushed_along(ds, measured))
    require(ds, ["wall_force_normal"] * (w is not None), "the harmonic measures")
    fw = math.nan if w is None else harmonic_amplitudes(t, ds["wall_force_normal"].values[:, w], f, orders=(1,),
                                                         subharmonics=(), window=window)["f"]
    # the same transmissibility over the window before: how much it still changes (NaN if that window meets the ramp)
    before = (hi - 2 * window_cycles * T, hi - window_cycles * T)
    ramp_end = drive.t0 + drive.ramp_cycles * T
    if before[0] >= ramp_end - 1e-9 * T:
        at = [harmonic_amplitudes(t, v, f, orders=(1,), subharmonics=(), window=before)["f"]
              for v in (vb, along(drive.granule))]
        drift = abs(amps["f"] / va / (at[0] / at[1]) - 1.0) if va > 0 and at[0] > 0 and at[1] > 0 else math.nan
    else:
        drift = math.nan
    steady = steady_window(t[t >= window[0] - 1e-12 * hi], vb[t >= window[0] - 1e-12 * hi], T, rtol=STEADY_RTOL, periods=2)
    scale = np.abs(ds["input_work"].values).max()
    v1 = amps["f"]
    return {
        "mobility": v1 / F,
        "transmissibility": v1 / va if va > 0 else float("nan"),
        "drift": drift,
        "drive_velocity": va,
        "measured_velocity": v1,
        "solid_force": fs / F,
        "wall_force": fw / F,
        "harmonic2": amps["2f"] / v1 if v1 > 0 else float("nan"),
        "harmonic3": amps["3f"] / v1 if v1 > 0 else float("nan"),
        "subharmonic2": amps["f/2"] / v1 if v1 > 0 else float("nan"),
        "period": float(response_period(t, vb, T, window=window)),
        "steady": float(steady is not None and steady[0] <= window[0] + 1e-9 * T),
        "balance": relative_balance_error(ds, scale),
    }


def case_metrics(runs: dict, spec: SpectrumSpec) -> dict:
    """A case's metrics: each run's measures suffixed by its direction, and the nonreciprocity."""
    out = {}
    for direction, _, measured in spec.runs():
        for k, v in run_measures(runs[direction], measured, spec.window_cycles).items():
            out[f"{k}_{direction}"] = float(v)
    if spec.both_directions:
        out["nonreciprocity_db"] = float(20.0 * np.log10(out["mobility_fwd"] / out["mobility_bwd"])) \
            if out["mobility_fwd"] > 0 and out["mobility_bwd"] > 0 else float("nan")
    return out


def case_metric_units(spec: SpectrumSpec) -> dict[str, str]:
    """The names of `case_metrics`, with their units."""
    out = {f"{k}_{direction}": unit for direction, _, _ in spec.runs() for k, unit in PER_DIRECTION.items()}
    if spec.both_directions:
        out["nonreciprocity_db"] = "dB"
    return out


def band_metrics(spec: SpectrumSpec, per_frequency: list[dict]) -> dict[str, float]:
    """A band's measures from its frequencies' `case_metrics`: per direction the band's mean and
    largest mobility and transmissibility in dB (20 log10, mobility re 1 m/(N s)), the share of
    steady runs and the largest balance error; the mean, smallest and largest nonreciprocity."""
    out: dict[str, float] = {}

    def db(values):
        v = np.asarray(values, float)
        return 20.0 * np.log10(np.where(v > 0, v, np.nan))

    for d, _, _ in spec.runs():
        for q in ("mobility", "transmissibility"):
            x = db([m[f"{q}_{d}"] for m in per_frequency])
            out[f"{q}_{d}_db"] = float(np.mean(x))
            out[f"{q}_{d}_db_max"] = float(np.max(x))
        out[f"steady_share_{d}"] = float(np.mean([m[f"steady_{d}"] for m in per_frequency]))
        out[f"balance_{d}"] = float(np.max([m[f"balance_{d}"] for m in per_frequency]))
    if spec.both_directions:
        nr = np.array([m["nonreciprocity_db"] for m in per_frequency], float)
        out.update(nonreciprocity_db=float(np.mean(nr)), nonreciprocity_db_min=float(np.min(nr)),
                   nonreciprocity_db_max=float(np.max(nr)))
    return out


def band_metric_units(spec: SpectrumSpec) -> dict[str, str]:
    """The names of `band_metrics`, with their units."""
    out = {}
    for d, _, _ in spec.runs():
        out.update({f"mobility_{d}_db": "dB re 1 m/(N s)", f"transmissibility_{d}_db": "dB",
                    f"mobility_{d}_db_max": "dB re 1 m/(N s)", f"transmissibility_{d}_db_max": "dB",
                    f"steady_share_{d}": "1", f"balance_{d}": "1"})
    if spec.both_directions:
        out.update(nonreciprocity_db="dB", nonreciprocity_db_min="dB", nonreciprocity_db_max="dB")
    return out


# ---------------------------------------------------------------- the linearised chain and the bands

def spectrum_chain(run, spec: SpectrumSpec):
    """The linearised chain that a spectrum's runs share (`analysis.chain.linear_chain` of one of
    its runs: the static state does not depend on the drive). ChainError (a ValueError) when the
    run has none, or its drive or measured granule is not a bead of it or is driven across it."""
    from ..analysis.chain import ChainError, linear_chain
    from ..analysis.reciprocity import pushed_along
    from ..analysis.result_model import result_system

    chain = linear_chain(run, result_system(run))
    for label in dict.fromkeys((spec.drive, spec.measure)):
        chain.position(label)
        d = pushed_along(run, label)
        if 1.0 - abs(float(d @ np.asarray(chain.axis))) > ALONG:
            raise ChainError(f"granule {label} is driven and measured along ({d[0]:.3g}, {d[1]:.3g}), not along "
                             f"the chain ({chain.axis[0]:.3g}, {chain.axis[1]:.3g}): its one-dimensional model does "
                             "not apply")
    return chain


def linear_spectrum(chain, spec: SpectrumSpec, frequencies) -> dict[str, np.ndarray]:
    """The linearised chain's measures (LINEAR) per direction (spec.runs()) and frequency: the
    transmissibility |v_B / v_A|, the mobility |v_B| / F and the force of the wall holding the
    measured bead, if one does, over the drive (`analysis.chain.chain_response`)."""
    from ..analysis.chain import chain_response

    runs = spec.runs()
    out = {k: np.full((len(runs), len(frequencies)), np.nan) for k in LINEAR}
    for r, (_, driven, measured) in enumerate(runs):
        a, b = chain.position(driven), chain.position(measured)
        end = {0: 0, chain.n - 1: 1}.get(b)
        walled = end is not None and chain.ends[end].holder != "" and not chain.ends[end].on_solid
        for k, f in enumerate(frequencies):
            resp = chain_response(chain, float(f), driven)
            out["transmissibility_linear"][r, k] = abs(resp.velocity[b] / resp.velocity[a])
            out["mobility_linear"][r, k] = abs(resp.velocity[b])
            if walled:
                out["wall_force_linear"][r, k] = abs(resp.end_force[end])
    return out


def curve_bands(f, T, wall, curve=None, diatomic: bool = False) -> dict[str, float]:
    """The BAND_MEASURES of one transmissibility curve T over the frequencies f (ascending;
    non-finite points left out) and the wall force over the drive (`wall`): the pass band
    (`analysis.bands.pass_band`), the wall force's mean over it in dB, and for a diatomic chain
    the second band and the gap (`analysis.bands.second_band`). `curve(f)`, the curve in dB as a
    function, places the crossings exactly (the linearised chain's)."""
    from ..analysis.bands import pass_band, second_band, to_db

    f, y, wdb = np.asarray(f, float), to_db(T), to_db(wall)
    ok = np.isfinite(y)
    out = dict.fromkeys(BAND_MEASURES, math.nan)
    if ok.sum() < 2:
        return out
    f, y, wdb = f[ok], y[ok], wdb[ok]
    pb = pass_band(f, y, curve)
    inside = np.isfinite(wdb[:pb.stop])
    out.update(passband_db=pb.level_db, cutoff_hz=pb.edge_hz, db20_hz=pb.db20_hz,
               wall_force_db=float(np.mean(wdb[:pb.stop][inside])) if inside.any() else math.nan)
    if diatomic:
        sb = second_band(f, y, pb, curve)
        out.update(optical_bottom_hz=sb.bottom_hz, optical_top_hz=sb.top_hz, gap_attenuation_db=sb.gap_attenuation_db)
    return out


def chain_summary(chain, edges) -> str:
    """One line on the linearised chain: its beads, kind, stiffness and ends."""
    def end(e):
        if not e.holder:
            return "free"
        damped = "damped" if e.damping > 0 else "undamped"
        what = "the solid" if e.holder == "solid" else f"wall {e.holder}, {damped}"
        return f"{what} ({e.stiffness:.4g} N/m)"

    kind = f"{edges.kind}, K = {edges.stiffness:.4g} N/m" if edges is not None else "neither monatomic nor diatomic"
    return (f"{chain.beads[0]}..{chain.beads[-1]}: {chain.n} beads, {kind}; ends: {end(chain.ends[0])} and "
            f"{end(chain.ends[1])}")


def curves_selection(ds: xr.Dataset):
    """(frequency, amplitude values, a selection of the other axes at their first index)."""
    rest = {d: 0 for d in ds["mobility"].dims if d not in ("frequency", "amplitude", "direction")}
    return ds.isel(rest) if rest else ds, rest


def add_bands(out: xr.Dataset, spec: SpectrumSpec, chain=None, note: str = "") -> xr.Dataset:
    """The spectrum Dataset `out` with its band measures (BAND_MEASURES over amplitude x
    direction, from the measured transmissibility at the first value of any other axis) and,
    given the linearised chain, its curves (LINEAR), its band measures (suffixed _linear) and
    the infinite chain's band edges (`band_edge_hz`); attribute `chain` says which chain, or
    `chain_note` why there is none."""
    from ..analysis.bands import to_db
    from ..analysis.chain import band_edges, chain_response

    sub, _ = curves_selection(out)
    f = sub["frequency"].values
    order = np.argsort(f)
    edges = band_edges(chain) if chain is not None else None
    diatomic = edges is not None and edges.kind == "diatomic"
    dirs = list(out["direction"].values)
    amps = list(sub["amplitude"].values) if "amplitude" in sub.dims else [None]
    measured = [[curve_bands(f[order], one["transmissibility"].sel(direction=d).values[order],
                             one["wall_force"].sel(direction=d).values[order], diatomic=diatomic) for d in dirs]
                for one in (sub.sel(amplitude=a) if a is not None else sub for a in amps)]
    for name, unit in BAND_MEASURES.items():
        vals = np.array([[m[name] for m in row] for row in measured])
        dims = ("amplitude", "direction") if amps[0] is not None else ("direction",)
        out[name] = (dims, vals if amps[0] is not None else vals[0], {"units": unit})
    if chain is None:
        out.attrs["chain_note"] = note or "no linearised chain"
        return out
    lin = linear_spectrum(chain, spec, f)
    for name, unit in LINEAR.items():
        out[name] = (("direction", "frequency"), lin[name], {"units": unit})
    measures = []
    for j, (_, driven, measured) in enumerate(spec.runs()):
        a, b = chain.position(driven), chain.position(measured)

        def curve(x, driven=driven, a=a, b=b):
            r = chain_response(chain, x, driven)
            return float(to_db([abs(r.velocity[b] / r.velocity[a])])[0])

        measures.append(curve_bands(f[order], lin["transmissibility_linear"][j][order],
                                    lin["wall_force_linear"][j][order], curve, diatomic))
    for name, unit in BAND_MEASURES.items():
        out[f"{name}_linear"] = (("direction",), np.array([m[name] for m in measures]), {"units": unit})
    if edges is not None:
        names = ["cut-off"] if edges.kind == "monatomic" else ["acoustic top", "optical bottom", "optical top"]
        out["band_edge_hz"] = (("band_edge",), np.array(edges.edges_hz),
                               {"units": "Hz", "long_name": "the infinite chain's band edges with the linearised "
                                                            "chain's masses and springs"})
        out = out.assign_coords(band_edge=("band_edge", names))
    out.attrs["chain"] = chain_summary(chain, edges)
    return out


# ---------------------------------------------------------------- the spectrum Dataset

def spectrum_dataset(summary: xr.Dataset, spec: SpectrumSpec, chain=None, note: str = "") -> xr.Dataset:
    """A spectrum sweep's summary with `frequency` and `amplitude` as dimensions (renamed from the
    axes on excitations.0.frequency / amplitude) and a `direction` dimension (fwd, bwd) for the
    per-run measures; nonreciprocity_db, status and any other axis as they are; the band
    measures and, given the runs' linearised chain (`spectrum_chain`), its own (`add_bands`;
    `note`: why there is no chain)."""
    ren = {k: v for k, v in (("excitations_0_frequency", "frequency"), ("excitations_0_amplitude", "amplitude"))
           if k in summary.dims}
    s = summary.rename(ren)
    dirs = [d for d, _, _ in spec.runs()]
    out = xr.Dataset(coords={k: v for k, v in s.coords.items()})
    out = out.assign_coords(direction=("direction", dirs))
    for name in PER_DIRECTION:
        parts = [s[f"{name}_{d}"] if f"{name}_{d}" in s else xr.full_like(s["status"], np.nan, dtype=float) for d in dirs]
        out[name] = xr.concat(parts, dim="direction").assign_coords(direction=dirs)
    for name in ("nonreciprocity_db", "status"):
        if name in s:
            out[name] = s[name]
    units = {"frequency": "Hz", "amplitude": "N", **PER_DIRECTION, "nonreciprocity_db": "dB"}
    for k, u in units.items():
        if k in out.variables:
            out[k].attrs["units"] = u
    out["direction"].attrs["long_name"] = (f"fwd: drive {spec.drive}, measure {spec.measure}; "
                                           f"bwd: drive {spec.measure}, measure {spec.drive}")
    out.attrs.update({k: v for k, v in summary.attrs.items()})
    out.attrs["drive"], out.attrs["measure"] = spec.drive, spec.measure
    return add_bands(out, spec, chain, note)


def resolved(one: xr.Dataset) -> np.ndarray:
    """Over frequency, at one amplitude: where both directions' mobilities are at least RESOLVED
    of the largest (the nonreciprocity is a measure there, not the ratio of two floors)."""
    mob = one["mobility"].transpose("direction", ...).values
    top = np.nanmax(mob) if np.isfinite(mob).any() else np.nan
    return np.all(mob >= RESOLVED * top, axis=0)


def stored_chain(spec, case_list: list[dict], out_dir) -> tuple[object, str]:
    """(The linearised chain of a spectrum's runs, `spectrum_chain`, or None; why there is none):
    read from the first stored forward run, in `out_dir`/cases, of a case (of `case_list`, the
    sweep `spec`'s) at the first value of every axis besides frequency and amplitude (the axes
    the report reads)."""
    from ..analysis.chain import ChainError
    from ..io.results import ResultFileError, read_netcdf

    free = {a.dim for a in spec.axes if a.field in (FREQUENCY_FIELD, AMPLITUDE_FIELD)}
    dims = [a.dim for a in spec.axes]
    for case in case_list:
        if any(i != 0 for d, i in zip(dims, case["index"]) if d not in free):
            continue
        path = Path(out_dir) / "cases" / f"{case['tag']}__fwd.nc"
        if not path.exists():
            continue
        try:
            run = read_netcdf(path)
            return spectrum_chain(run, spec.spectrum), ""
        except ChainError as e:
            return None, str(e)
        except (ResultFileError, OSError, ValueError, KeyError):
            continue  # unreadable, or of an earlier granel: try the next case's
    return None, "no stored run of the spectrum to read its chain from"
