"""Reciprocity metrics for a pair of runs with swapped excitation and measurement points.

Forward run: the shock on granule A, the response measured at granule B; backward run: the
shock on B, measured at A. For a linear, reciprocal system v_B(fwd) . d_B equals v_A(bwd) . d_A,
where d_X is the direction of the force applied at X in the run that excites X (Betti-Rayleigh
reciprocity with identical load histories). The paper's Fig. 3
compares v_3C (granule 3 when C is shocked) with v_C3 (granule C when 3 is shocked).

Nonreciprocity index (ours):
    NRI = ||s_fwd - s_bwd||_2 / (||s_fwd||_2 + ||s_bwd||_2)  in [0, 1],
with s_fwd(t) = v_B(t) . d_B from the forward run and s_bwd(t) = v_A(t) . d_A from the backward
run, on the common time grid. NRI = 0 for a reciprocal response, 1 when the two signals are
opposite; it is scale-free, so shock levels can be compared.
"""

from __future__ import annotations

import tomllib

import numpy as np


def arrival_time(t, signal, fraction: float = 0.05, reference: float | None = None) -> float:
    """First time |signal| reaches `fraction` of `reference` (default: its own peak); NaN if never."""
    s = np.abs(np.asarray(signal, float))
    ref = s.max() if reference is None else reference
    if ref <= 0:
        return float("nan")
    idx = np.flatnonzero(s >= fraction * ref)
    if not len(idx):
        return float("nan")
    k = int(idx[0])
    if k == 0:
        return float(t[0])
    # linear interpolation between the samples around the crossing
    y0, y1 = s[k - 1], s[k]
    thr = fraction * ref
    return float(t[k - 1] + (thr - y0) / (y1 - y0) * (t[k] - t[k - 1]))


# a measured peak below this fraction of the driven granule's peak speed is no arrival (noise)
ARRIVAL_FLOOR = 1e-3


def pulse_arrival(t, signal, driven_peak: float, fraction: float = 0.05, floor: float = ARRIVAL_FLOOR) -> float:
    """Arrival of a pulse at a measured granule, relative to the input.

    Rule: the first time |signal| reaches `fraction` (5 %) of its own peak, provided that peak is
    at least `floor` (1e-3) times `driven_peak`, the peak speed of the driven granule; NaN when the
    measured peak stays below that floor (the pulse has not arrived: what the signal holds then is
    round-off, ~1e-19 m/s, on which a threshold relative to its own peak alone would fire) or when
    nothing was driven (driven_peak <= 0 or not finite)."""
    s = np.abs(np.asarray(signal, float))
    if not len(s) or not np.isfinite(driven_peak) or driven_peak <= 0 or not s.max() >= floor * driven_peak:
        return float("nan")
    return arrival_time(t, s, fraction)


def driven_peak_speed(ds, label: str) -> float:
    """The peak speed of granule `label` (the driven one: the input side of `pulse_arrival`)."""
    g = list(ds["granule"].values).index(label)
    return float(np.hypot(ds["v_x"].values[:, g], ds["v_y"].values[:, g]).max())


def excitation_of(ds) -> tuple[str, np.ndarray]:
    """(granule label, unit direction) of the first excitation of a run; without excitations,
    of its first initial velocity (a striker)."""
    sc = tomllib.loads(ds.attrs["scenario"])
    if not sc.get("excitations"):
        if not sc.get("initial_velocities"):
            raise ValueError("the run has neither an excitation nor an initial velocity: nothing was driven")
        iv = sc["initial_velocities"][0]
        v = np.asarray(iv["v"], float)
        return iv["granule"], v / np.hypot(*v) if np.hypot(*v) > 0 else v
    e = sc["excitations"][0]
    d = e.get("direction", "toward_solid")
    label = e["granule"]
    if isinstance(d, str):
        vec = toward_solid(sc, label) * (1.0 if d == "toward_solid" else -1.0)
    else:
        vec = np.asarray(d, float)
        vec = vec / np.hypot(*vec)
    return label, vec


def directed_velocity(ds, label: str, direction) -> np.ndarray:
    g = list(ds["granule"].values).index(label)
    return ds["v_x"].values[:, g] * direction[0] + ds["v_y"].values[:, g] * direction[1]


def nonreciprocity_index(s_fwd, s_bwd) -> float:
    a, b = np.asarray(s_fwd, float), np.asarray(s_bwd, float)
    den = np.linalg.norm(a) + np.linalg.norm(b)
    return float(np.linalg.norm(a - b) / den) if den > 0 else 0.0


def solid_arrival(ds, fraction: float = 0.01) -> float:
    """First time the solid holds `fraction` of the input work."""
    w = float(ds["input_work"].values.max())
    return arrival_time(ds["time"].values, ds["energy_solid"].values, fraction, w) if w > 0 else float("nan")


def far_medium(ds, excited_label: str) -> str:
    media = [m for m in dict.fromkeys(ds["medium"].values)]
    own = excited_label.split(":")[0]
    others = [m for m in media if m != own]
    return str(others[0]) if others else own


def spectral_centroid(ds, modes=None, model=None) -> float:
    """Modal-energy-weighted mean frequency of the solid's response [Hz]:
    sum f_n <E_n> / sum <E_n>, with <E_n> the time average of eq. (15)."""
    if "solid_time" not in ds:
        return float("nan")
    from .modal import modal_coordinates, modal_energies

    t, X, Xd, w = modal_coordinates(ds, modes, model)
    E = modal_energies(X, Xd, w)
    avg = np.trapezoid(E, t, axis=0)
    tot = avg.sum()
    return float((w / (2 * np.pi)) @ avg / tot) if tot > 0 else float("nan")


def input_energy(ds) -> float:
    """The energy a run was given: the loads' largest work, or (a striker, no loads) the
    energy it holds at the start [J]."""
    w = float(ds["input_work"].values.max())
    if w > 0:
        return w
    held = [f"energy_{str(m).lower()}" for m in dict.fromkeys(ds["medium"].values)] + ["energy_solid"]
    return float(sum(ds[v].values[0] for v in held if v in ds))


def run_metrics(ds, measured: str, modes=None, model=None) -> dict:
    """Per-run numbers: arrival at the measured granule (`pulse_arrival`: 5 % of the measured
    peak, NaN unless that peak reaches 1e-3 of the driven granule's) and at the solid (1 % of the
    input work), peak velocity, energy transmitted to the far medium, spectral centroid of the solid."""
    label, d = excitation_of(ds)
    t = ds["time"].values
    w = input_energy(ds)
    far = far_medium(ds, label)
    v = directed_velocity(ds, measured, toward_solid(tomllib.loads(ds.attrs["scenario"]), measured))
    e_far = ds[f"energy_{far.lower()}"].values / w if w > 0 else np.zeros_like(t)
    out = {
        "excited": label,
        "measured": measured,
        "arrival_measured_s": pulse_arrival(t, v, driven_peak_speed(ds, label)),
        "arrival_solid_s": solid_arrival(ds) if "energy_solid" in ds else float("nan"),
        "peak_velocity_m_s": float(np.abs(v).max()),
        "far_medium": far,
        "energy_far_peak_frac": float(e_far.max()),
        "energy_far_final_frac": float(e_far[-1]),
        "solid_energy_peak_frac": float(ds["energy_solid"].values.max() / w) if w > 0 else 0.0,
        "input_work_J": w,  # the loads' work, or a striker's energy
    }
    try:
        out["spectral_centroid_hz"] = spectral_centroid(ds, modes, model)
    except ValueError:
        out["spectral_centroid_hz"] = float("nan")
    return out


def toward_solid(sc: dict, label: str) -> np.ndarray:
    """Unit vector from granule `label`'s medium toward the solid (scenario as a dict)."""
    medium = label.split(":")[0]
    side = next((m.get("side", "none") for m in sc["media"] if m["name"] == medium), "none")
    return np.array([1.0, 0.0]) if side == "left" else np.array([-1.0, 0.0])


def reciprocity_metrics(fwd, bwd, modes=None, model=None) -> dict:
    """Metrics of a forward/backward pair. fwd excites A and is measured at B = bwd's excited
    granule; bwd excites B and is measured at A."""
    A, dA = excitation_of(fwd)
    B, dB = excitation_of(bwd)
    s_fwd = directed_velocity(fwd, B, dB)
    s_bwd = directed_velocity(bwd, A, dA)
    n = min(len(s_fwd), len(s_bwd))
    m_f = run_metrics(fwd, B, modes, model)
    m_b = run_metrics(bwd, A, modes, model)
    return {
        "forward": m_f,
        "backward": m_b,
        "nonreciprocity_index": nonreciprocity_index(s_fwd[:n], s_bwd[:n]),
        "arrival_ratio": m_f["arrival_measured_s"] / m_b["arrival_measured_s"] if m_b["arrival_measured_s"] else float("nan"),
        "faster_direction": _faster(A, B, m_f["arrival_measured_s"], m_b["arrival_measured_s"]),
    }


def _faster(A: str, B: str, fwd: float, bwd: float) -> str:
    """The direction whose pulse arrives first; 'undetermined' unless both arrived."""
    if not (np.isfinite(fwd) and np.isfinite(bwd)):
        return "undetermined (no arrival in at least one direction)"
    return f"{B} <- {A}" if fwd < bwd else f"{A} <- {B}"
