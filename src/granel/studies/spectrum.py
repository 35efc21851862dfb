"""Frequency-resolved transmission and nonreciprocity: the measures of the `spectrum` study mode
(`modes.SpectrumMode`) and the `granel spectrum` command's inputs and outputs.

Each case drives one granule harmonically (the scenario's first excitation made a harmonic at the
case's frequency and amplitude, ramped up over `ramp_cycles`) for `cycles` drive periods, sampled
`samples_per_period` times a period, and measures over the last `window_cycles` periods:

    mobility          |V_B(f)| / F        the measured granule's velocity amplitude at the drive
                                          frequency, along its own drive direction, per newton
    transmissibility  |V_B(f)| / |V_A(f)| over the driven granule's velocity amplitude
    drift             |its value over the window / over the window_cycles before - 1|: how much
                      it still changes (NaN when the window before meets the ramp)
    solid_force       |F_solid(f)| / F    the force the solid takes at f over the drive's
    wall_force        |F_wall(f)| / F     the normal force of the wall the measured granule touches
                                          (the one most nearly along its drive direction) over the
                                          drive's; NaN when it touches none
    harmonic2, 3      |V_B(kf)| / |V_B(f)|, subharmonic2 |V_B(f/2)| / |V_B(f)|
    period            the response's period in drive periods (1, 2, ...; 0: none within 8)
    steady            1 if the window's periods repeat within 2 %, else 0
    balance           max |energy balance (13)| / max input work

Both directions (drive A measure B, then drive B measure A) give the nonreciprocity
20 log10(mobility_fwd / mobility_bwd) [dB], which reads 0 dB for a linear, reciprocal system
(docs/narrowband.md, "The measures, and why mobility").

Over frequency, the measured transmissibility gives the band measures (`analysis.bands`: the
pass band's level, its cut-off and 20 dB point, a diatomic chain's optical band and gap), each
beside the same measure of the linearised chain (`analysis.chain`) that the runs share, read from
a stored run (`spectrum_chain`), and the infinite chain's band edges (docs/narrowband.md, "Band
measures")."""

from __future__ import annotations

import math
import re
import tomllib
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

def measuring_direction(sc: dict, label: str) -> np.ndarray:
    """The unit direction along which granule `label` is measured: the direction the scenario's
    first excitation would push it (`toward_solid` resolved for its medium, or the vector)."""
    from ..analysis.reciprocity import toward_solid

    d = sc["excitations"][0].get("direction", "toward_solid")
    if isinstance(d, str):
        return toward_solid(sc, label) * (1.0 if d == "toward_solid" else -1.0)
    v = np.asarray(d, float)
    return v / np.hypot(*v)


def touching_wall(ds, label: str, direction) -> int | None:
    """The index of the wall granule `label` touches at the first output (its centre over the
    segment, its overlap above -ROUND_OFF of its radius, `granular.geometry`), the most nearly
    along `direction` of them; None when it touches none. Read from the result's model record."""
    from ..granular.geometry import ROUND_OFF

    if not ds.sizes.get("wall", 0):
        return None
    labels = [str(g) for g in ds["granule"].values]
    g = labels.index(label)
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
    """The measures of one harmonically driven run (module docstring) at granule `measured`."""
    from ..analysis.narrowband import drive_of, harmonic_amplitudes, response_period, steady_window

    sc = tomllib.loads(ds.attrs["scenario"])
    drive = drive_of(ds)
    f, F = drive.frequency, abs(drive.amplitude)
    T = 1.0 / f
    t = ds["time"].values
    labels = list(ds["granule"].values)

    def along(label):
        d = measuring_direction(sc, label)
        g = labels.index(label)
        return ds["v_x"].values[:, g] * d[0] + ds["v_y"].values[:, g] * d[1]

    hi = t[-1]
    window = (hi - window_cycles * T, hi)
    vb = along(measured)
    amps = harmonic_amplitudes(t, vb, f, orders=(1, 2, 3), subharmonics=(2,), window=window)
    va = harmonic_amplitudes(t, along(drive.granule), f, orders=(1,), subharmonics=(), window=window)["f"]
    if "contact_force_normal" in ds and ds.sizes.get("contact", 0):
        fs = harmonic_amplitudes(t, ds["contact_force_normal"].values.sum(axis=1), f, orders=(1,), subharmonics=(),
                                 window=window)["f"]
    else:
        fs = 0.0
    w = touching_wall(ds, measured, measuring_direction(sc, measured))
    fw = math.nan if w is None else harmonic_amplitudes(t, ds["wall_force_normal"].values[:, w], f, orders=(1,),
                                                         subharmonics=(), window=window)["f"]
    # the same transmissibility over the window before: how much it still changes (NaN if that window meets the ramp)
    before = (hi - 2 * window_cycles * T, hi - window_cycles * T)
    ramp_end = drive.t0 + float(sc["excitations"][0].get("ramp_cycles", 0.0)) * T
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
        "balance": float(np.abs(ds["balance_error"].values).max() / scale) if scale > 0 else float("nan"),
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
    from ..analysis.result_model import result_system

    chain = linear_chain(run, result_system(run))
    sc = tomllib.loads(run.attrs["scenario"])
    for label in dict.fromkeys((spec.drive, spec.measure)):
        chain.position(label)
        d = measuring_direction(sc, label)
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


def add_bands(out: xr.Dataset, spec: SpectrumSpec, chain=None, note: str = "") -> xr.Dataset:
    """The spectrum Dataset `out` with its band measures (BAND_MEASURES over amplitude x
    direction, from the measured transmissibility at the first value of any other axis) and,
    given the linearised chain, its curves (LINEAR), its band measures (suffixed _linear) and
    the infinite chain's band edges (`band_edge_hz`); attribute `chain` says which chain, or
    `chain_note` why there is none."""
    from ..analysis.bands import to_db
    from ..analysis.chain import band_edges, chain_response

    sub, _ = _curves(out)
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


def _curves(ds: xr.Dataset):
    """(frequency, amplitude values, a selection of the other axes at their first index)."""
    rest = {d: 0 for d in ds["mobility"].dims if d not in ("frequency", "amplitude", "direction")}
    return ds.isel(rest) if rest else ds, rest


def plot_spectrum(ds: xr.Dataset, output):
    """Four panels over drive frequency, one colour per amplitude, forward solid and backward
    dashed: the transmissibility |V_B| / |V_A| and the mobility |V_B| / F, with the linearised
    chain's (black) and the infinite chain's band edges (grey) when there is a chain; the nonreciprocity
    [dB] (open symbols where a mobility is 60 dB below its peak, `resolved`); and, with several
    amplitudes, its map over frequency x amplitude. Any other sweep axis at its first value."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..viz.plots import save

    sub, rest = _curves(ds)
    f = sub["frequency"].values / 1e3
    amps = sub["amplitude"].values if "amplitude" in sub.dims else [None]
    has_map = "nonreciprocity_db" in sub and "amplitude" in sub.dims and len(amps) > 1
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), squeeze=False)
    (ax_t, ax_m), (ax_n, ax_map) = axes
    colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(amps)))
    for c, a in zip(colors, amps):
        one = sub.sel(amplitude=a) if a is not None else sub
        for d, style in zip(one["direction"].values, ("-", "--")):
            label = f"{a:g} N, {d}" if a is not None else d
            ax_t.plot(f, one["transmissibility"].sel(direction=d).values, style, color=c, marker="o", ms=3, label=label)
            ax_m.plot(f, one["mobility"].sel(direction=d).values, style, color=c, marker="o", ms=3, label=label)
        if "nonreciprocity_db" in one:
            nr, ok = one["nonreciprocity_db"].values, resolved(one)
            ax_n.plot(f, np.where(ok, nr, np.nan), "-o", color=c, ms=3, label=f"{a:g} N" if a is not None else None)
            ax_n.plot(f[~ok], nr[~ok], "o", mfc="none", color=c, ms=3)
    if "transmissibility_linear" in sub:  # the linearised chain, at the same frequencies
        for ax, name in ((ax_t, "transmissibility"), (ax_m, "mobility")):
            measured = sub[name].values[np.isfinite(sub[name].values) & (sub[name].values > 0)]
            for d, style in zip(sub["direction"].values, ("-", "--")):  # a wide grey band under the measured curves
                ax.plot(f, sub[f"{name}_linear"].sel(direction=d).values, style, color="0.4", lw=4, alpha=0.35,
                        zorder=0, label=f"linearised chain, {d}")
            if measured.size:  # the linear chain's stop band falls far below any run's floor: keep the runs in view
                ax.set_ylim(bottom=measured.min() / 10, top=measured.max() * 10)
    if "band_edge_hz" in sub:
        for ax in (ax_t, ax_m):
            for k, (name, edge) in enumerate(zip(sub["band_edge"].values, sub["band_edge_hz"].values)):
                ax.axvline(edge / 1e3, color="0.5", lw=0.8, ls="--",
                           label="infinite chain's band edges" if not k else None)
    route = f"fwd: {ds.attrs.get('drive')} -> {ds.attrs.get('measure')}"
    ax_t.set_ylabel("transmissibility |V_measured| / |V_driven|")
    ax_t.set_title(route, fontsize=9)
    ax_m.set_ylabel("mobility |V_measured| / F [m/(N s)]")
    ax_m.set_title(route, fontsize=9)
    for ax in (ax_t, ax_m):
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    ax_n.axhline(0.0, color="0.6", lw=0.8)
    ax_n.set_ylabel("nonreciprocity 20 log10(mobility fwd / bwd) [dB]")
    ax_n.set_title("open symbols: a mobility 60 dB below its peak (deep stop band)", fontsize=8)
    if "nonreciprocity_db" in sub and (len(amps) > 1 or amps[0] is not None):
        ax_n.legend(fontsize=7)
    wide = f.max() > 5 * f.min()  # a log frequency axis over wide ranges only
    for ax in (ax_t, ax_m, ax_n, ax_map):
        ax.set_xlabel("drive frequency [kHz]")
        ax.set_xscale("log" if wide else "linear")
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    if has_map:
        vals = np.array([np.where(resolved(sub.sel(amplitude=a)), sub["nonreciprocity_db"].sel(amplitude=a).values, np.nan)
                         for a in amps])  # blank where a mobility is at its floor
        top = np.nanmax(np.abs(vals)) if np.isfinite(vals).any() else 1.0
        m = ax_map.pcolormesh(f, amps, vals, shading="nearest", cmap="RdBu_r", vmin=-top, vmax=top)
        if max(amps) > 5 * min(amps):
            ax_map.set_yscale("log")
        ax_map.set_yticks(amps, [f"{a:g}" for a in amps])
        ax_map.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax_map.set_ylabel("drive amplitude [N]")
        fig.colorbar(m, ax=ax_map, label="nonreciprocity [dB] (blank: stop band)")
    else:
        ax_map.set_visible(False)
    if rest:
        fig.suptitle(", ".join(f"{k} = {ds[k].values[0]}" for k in rest), fontsize=9)
    fig.tight_layout()
    return save(fig, output)


def spectrum_report(ds: xr.Dataset) -> str:
    """A short Markdown report: what was driven and measured, and per amplitude the strongest
    nonreciprocity, the band where the forward mobility stays within 20 dB of its peak, and how
    many runs were steady or failed."""
    sub, rest = _curves(ds)
    f = sub["frequency"].values
    lines = [f"# Spectrum: {ds.attrs.get('name', '')}", "",
             f"Drive {ds.attrs.get('drive')} (fwd) and {ds.attrs.get('measure')} (bwd), harmonic force, "
             f"{len(f)} frequencies from {f.min() / 1e3:.3g} to {f.max() / 1e3:.3g} kHz.", ""]
    if rest:
        lines += [f"Other axes at their first value: {', '.join(f'{k} = {ds[k].values[0]}' for k in rest)}.", ""]
    lines += ["| amplitude [N] | strongest nonreciprocity [dB] (mobilities within 60 dB of peak) | at [kHz] | fwd pass band (within 20 dB of peak) [kHz] "
              "| steady runs | failed cases |", "|---|---|---|---|---|---|"]
    amps = sub["amplitude"].values if "amplitude" in sub.dims else [None]
    for a in amps:
        one = sub.sel(amplitude=a) if a is not None else sub
        nr = one["nonreciprocity_db"].values if "nonreciprocity_db" in one else np.full(len(f), np.nan)
        nr = np.where(resolved(one), nr, np.nan)
        if np.isfinite(nr).any():
            k = int(np.nanargmax(np.abs(nr)))
            strongest, at = f"{nr[k]:+.2f}", f"{f[k] / 1e3:.3g}"
        else:
            strongest, at = "n/a", "n/a"
        mob = one["mobility"].sel(direction="fwd").values
        band = "n/a"
        if np.isfinite(mob).any() and np.nanmax(mob) > 0:
            ok = f[mob >= np.nanmax(mob) * 0.1]
            band = f"{ok.min() / 1e3:.3g} - {ok.max() / 1e3:.3g}"
        steady = one["steady"].values
        failed = int(np.sum(one["status"].values != "ok")) if "status" in one else 0
        lines.append(f"| {a if a is None else f'{a:g}'} | {strongest} | {at} | {band} | "
                     f"{int(np.nansum(steady))} of {steady.size} | {failed} |")
    bal = np.nanmax(ds["balance"].values) if np.isfinite(ds["balance"].values).any() else float("nan")
    lines += ["", f"Largest energy-balance error (13) of any run, over its input work: {bal:.2e}.", "",
              "Mobility |V(f)| / F: the measured granule's velocity amplitude at the drive frequency, along its own "
              "drive direction, per newton of drive. A linear reciprocal system has equal mobilities both ways "
              "(0 dB). A run is steady when its last periods repeat within 2 %."]
    return "\n".join(lines + band_report(ds)) + "\n"


# the rows of the band measures' table: (measure, label of a monatomic chain's, of a diatomic
# chain's, the infinite chain's edge it stands beside, or None)
BAND_ROWS = [("passband_db", "pass band level [dB]", "acoustic band level [dB]", None),
             ("cutoff_hz", "cut-off, 3 dB below it [kHz]", "acoustic band top, 3 dB below it [kHz]", 0),
             ("db20_hz", "20 dB point [kHz]", "20 dB point of the acoustic band [kHz]", None),
             ("optical_bottom_hz", None, "optical band bottom [kHz]", 1),
             ("optical_top_hz", None, "optical band top [kHz]", 2),
             ("gap_attenuation_db", None, "gap's mean attenuation [dB]", None),
             ("wall_force_db", "wall force over drive, mean over the pass band [dB]",
              "wall force over drive, mean over the acoustic band [dB]", None)]


def band_report(ds: xr.Dataset) -> list[str]:
    """The report's lines on the band measures (`add_bands`): per direction, each measured one
    per amplitude beside the linearised chain's and the infinite chain's, and the grid step
    where the linearised chain's edge lies (the resolution of a measured edge)."""
    if "cutoff_hz" not in ds:
        return []
    f = np.sort(ds["frequency"].values)
    diatomic = "band_edge" in ds.coords and ds.sizes["band_edge"] == 3
    amps = list(ds["amplitude"].values) if "amplitude" in ds["cutoff_hz"].dims else [None]
    lines = ["", "## Band measures", "",
             f"Linearised chain: {ds.attrs['chain']}." if "chain" in ds.attrs else
             f"No linearised chain: {ds.attrs.get('chain_note', '')}.",
             "", "From the transmissibility |V_measured| / |V_driven| over frequency (docs/narrowband.md, \"Band "
             "measures\"): the pass band runs up to the first frequency more than 20 dB below the mean (in dB) of "
             "those below it, still falling; its level is that mean; an edge lies 3 dB below a band's level, the "
             "20 dB point 20 dB below it. Measured edges are interpolated between the frequencies run; the "
             "linearised chain's (its exact response, the same definitions on the same frequencies) are exact, "
             "the grid step there is the resolution.", ""]
    head = "| measure | direction | " + " | ".join(f"{a:g} N" if a is not None else "measured" for a in amps)
    lines += [head + " | linearised chain | infinite chain | grid step there [kHz] |",
              "|" + "---|" * (len(amps) + 5)]

    def cell(v, unit):
        return "n/a" if not np.isfinite(v) else (f"{v / 1e3:.4g}" if unit == "Hz" else f"{v:.2f}")

    for name, mono, dia, edge in BAND_ROWS:
        label = dia if diatomic else mono
        if label is None:
            continue
        unit = BAND_MEASURES[name]
        for d in ds["direction"].values:
            got = [float(ds[name].sel(direction=d, amplitude=a)) if a is not None else float(ds[name].sel(direction=d))
                   for a in amps]
            lin = float(ds[f"{name}_linear"].sel(direction=d)) if f"{name}_linear" in ds else math.nan
            inf = float(ds["band_edge_hz"].values[edge]) if edge is not None and "band_edge_hz" in ds else math.nan
            step = "n/a"
            if unit == "Hz" and np.isfinite(lin) and f[0] < lin < f[-1]:
                k = int(np.searchsorted(f, lin))
                step = f"{(f[k] - f[k - 1]) / 1e3:.3g}"
            lines.append(f"| {label} | {d} | " + " | ".join(cell(v, unit) for v in got) +
                         f" | {cell(lin, unit)} | {cell(inf, unit)} | {step} |")
    return lines


def write_spectrum(summary: xr.Dataset, spec: SpectrumSpec, path, chain=None, note: str = "") -> xr.Dataset:
    """A spectrum sweep's outputs beside each other, each written atomically: PATH (.nc, the
    `spectrum_dataset` with the runs' linearised `chain`, if any), its figure (.png) and its
    report (.md). Returns the Dataset."""
    from ..guard.owners import text_mark
    from ..guard.writing import write_text
    from ..io.results import write_netcdf

    path = Path(path)
    ds = spectrum_dataset(summary, spec, chain, note)
    write_netcdf(ds, path)
    plot_spectrum(ds, path.with_suffix(".png"))
    write_text(path.with_suffix(".md"), text_mark("<!--") + "\n" + spectrum_report(ds))
    return ds
