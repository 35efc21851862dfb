"""Reciprocity metrics for a pair of runs with swapped excitation and measurement points (the
paper's Fig. 3 compares v_3C with v_C3): arrivals, peaks, energy shares, the spectral centroid of
the modal energies of eq. (15), and granel's nonreciprocity index
NRI = ||s_fwd - s_bwd||_2 / (||s_fwd||_2 + ||s_bwd||_2) in [0, 1]. docs/analysis.md
("Reciprocity") defines the signals and the metrics."""

from __future__ import annotations

import numpy as np

from ..granular.loads import KINDS
from ..io.model import read_record
from ..io.results import granule_column, require_states


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
    g = granule_column(ds, label, "the diode's metrics")
    return float(np.hypot(ds["v_x"].values[:, g], ds["v_y"].values[:, g]).max())


def excitation_of(ds) -> tuple[str, np.ndarray]:
    """(granule label, unit direction) of the first load of a run (its model record); without
    loads, of its first striker, along its initial velocity."""
    rec = read_record(ds)
    if not rec.loads:
        if not rec.strikers:
            raise ValueError("the run has neither an excitation nor an initial velocity: nothing was driven")
        g = rec.strikers[0]
        require_states(ds, "finding the striker's direction", [g])
        v = np.array([ds["v_x"].values[0, g], ds["v_y"].values[0, g]], float)
        return rec.labels[g], v / np.hypot(*v) if np.hypot(*v) > 0 else v
    e = rec.loads[0]
    return rec.labels[e.granule], np.asarray(e.direction, float)


def toward_solid(ds, label: str) -> np.ndarray:
    """Unit vector from granule `label` toward the solid (the record's; NaN for a medium away
    from the solid)."""
    rec = read_record(ds)
    return np.asarray(rec.toward_solid[rec.labels.index(label)], float)


def measured_along(ds, label: str) -> np.ndarray:
    """The direction granule `label`'s response is measured along: toward the solid for a medium
    beside it; for one away from the solid, the run's drive direction (`excitation_of`)."""
    d = toward_solid(ds, label)
    return d if np.isfinite(d).all() else excitation_of(ds)[1]


def pushed_along(ds, label: str) -> np.ndarray:
    """The direction the run's first load would push granule `label`: toward (or away from) the
    solid for `label`'s medium when the load was given so, else the load's own vector."""
    e = read_record(ds).loads[0]
    d = toward_solid(ds, label) * e.toward
    return d if e.toward != 0 and np.isfinite(d).all() else np.asarray(e.direction, float)


def directed_velocity(ds, label: str, direction) -> np.ndarray:
    g = granule_column(ds, label, "the diode's metrics")
    return ds["v_x"].values[:, g] * direction[0] + ds["v_y"].values[:, g] * direction[1]


def nonreciprocity_index(s_fwd, s_bwd) -> float:
    a, b = np.asarray(s_fwd, float), np.asarray(s_bwd, float)
    den = np.linalg.norm(a) + np.linalg.norm(b)
    return float(np.linalg.norm(a - b) / den) if den > 0 else 0.0


def solid_arrival(ds, fraction: float = 0.01) -> float:
    """First time the solid holds `fraction` of the dynamic input (`dynamic_input`), its energy
    counted from its static state (`dynamic_energy`); NaN when nothing drives the run."""
    w, _ = dynamic_input(ds)
    if not w > 0 or "energy_solid" not in ds:
        return float("nan")
    e, _ = dynamic_energy(ds, None)
    return arrival_time(ds["time"].values, e, fraction, w)


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


def static_loads(ds) -> list[tuple[int, np.ndarray]]:
    """The static preload of a run: (granule index, force vector [N]) of each constant load when
    the run starts from their equilibrium (`simulation.equilibrate`); [] otherwise (a constant
    load applied to a medium at rest is a step load, part of the dynamic input)."""
    if "equilibrium_contact" not in ds:  # the run did not start from a static equilibrium
        return []
    return [(e.granule, KINDS[e.kind].from_params(e.params).preload * np.asarray(e.direction, float))
            for e in read_record(ds).loads if KINDS[e.kind].static]


def static_work(ds, medium: str | None = None) -> np.ndarray:
    """The static preload's work since t = 0 on the granules of `medium` (all by default):
    sum F . (r(t) - r(0)), exact for a constant force; zeros without a preload."""
    w = np.zeros(ds.sizes["time"])
    media = ds["medium"].values
    for g, F in static_loads(ds):
        if medium is None or str(media[g]) == medium:
            require_states(ds, "the preload's work", [g])
            w += F[0] * (ds["x"].values[:, g] - ds["x"].values[0, g]) + F[1] * (ds["y"].values[:, g] - ds["y"].values[0, g])
    return w


def weights(ds, medium: str | None = None) -> list[tuple[int, np.ndarray]]:
    """(granule index, its weight m g [N]) of the granules of `medium` (all by default) when the
    run has gravity (the model record's); [] otherwise."""
    rec = read_record(ds)
    g = np.asarray(rec.gravity, float)
    if not np.any(g):
        return []
    media = ds["medium"].values
    return [(k, float(rec.mass[k]) * g) for k in range(rec.n) if medium is None or str(media[k]) == medium]


def gravity_work(ds, medium: str | None = None) -> np.ndarray:
    """Gravity's work since t = 0 on the granules of `medium`: sum m g . (r(t) - r(0)), the fall
    of their gravitational energy; zeros without gravity."""
    w = np.zeros(ds.sizes["time"])
    held = weights(ds, medium)
    if held:
        require_states(ds, "gravity's work on a medium", [k for k, _ in held])
    for k, F in held:
        w += F[0] * (ds["x"].values[:, k] - ds["x"].values[0, k]) + F[1] * (ds["y"].values[:, k] - ds["y"].values[0, k])
    return w


def dynamic_input(ds) -> tuple[float, str | None]:
    """(W, why W is NaN): the largest input work less the static preload's (`static_work`) over
    the run, or, for a striker (no load but a preload), the energy it holds at the start. NaN
    when the scenario holds nothing dynamic: no transient load, moving wall or initial motion,
    and no constant load applied at rest (a preload's equilibrium residual moves the granules by
    round-off, which is no input)."""
    rec = read_record(ds)
    preload = bool(static_loads(ds))
    loads = [e for e in rec.loads if not KINDS[e.kind].static or not preload]
    loads += [w for w in rec.walls if w.drive[1] > 0]  # a shaker (frequency > 0)
    striker = bool(rec.strikers)
    if not loads and not striker:
        return float("nan"), ("nothing drives the run beyond its static preload (no transient load, moving wall or "
                              "initial motion)" if preload else "nothing drives the run (no load, moving wall or "
                              "initial motion)")
    w = float(np.max(ds["input_work"].values - static_work(ds)))
    if loads:
        return (w, None) if w > 0 else (float("nan"), "the loads do no work within the run")
    if preload:
        return float("nan"), ("a striker on a precompressed medium: the result does not separate its initial "
                              "motion from the equilibrium's energy")
    return input_energy(ds), None


def dynamic_energy(ds, medium: str | None) -> tuple[np.ndarray, str | None]:
    """(E(t), why it is NaN) of a medium (None: the solid) counted from its static state: under
    a preload or, from an equilibrium, under its weight, E(t) - E(0) less its static loads' and
    gravity's work (`static_work`, `gravity_work`; E(0) is the equilibrium's, the medium at rest),
    else E(t). To second order in the motion this is the medium's kinetic
    energy and its contacts' elastic energy about equilibrium."""
    name = "energy_solid" if medium is None else f"energy_{medium.lower()}"
    e = np.asarray(ds[name].values, float)
    if not static_loads(ds) and not (medium is not None and "equilibrium_contact" in ds and weights(ds, medium)):
        return e, None
    if medium is not None:
        sel = ds["medium"].values == medium
        require_states(ds, f"the energy of medium {medium} about its preloaded equilibrium", np.flatnonzero(sel))
        if any(np.any(ds[v].values[0, sel] != 0) for v in ("v_x", "v_y", "omega")):
            return np.full_like(e, np.nan), (f"medium {medium} moves at the start of a precompressed run: the result "
                                              "does not separate its motion from the equilibrium's energy")
    if medium is None:
        return e - e[0], None
    return e - e[0] - static_work(ds, medium) - gravity_work(ds, medium), None


def run_metrics(ds, measured: str, modes=None, model=None) -> dict:
    """Per-run numbers: arrival at the measured granule (`pulse_arrival`: 5 % of the measured
    peak, NaN unless that peak reaches 1e-3 of the driven granule's) and at the solid (1 % of the
    input), peak velocity, energy transmitted to the far medium, spectral centroid of the solid.

    Energy shares are of the dynamic input W (`dynamic_input`: the loads' largest work less a
    static preload's, or a striker's energy), each energy counted from its static state
    (`dynamic_energy`), so that a preload's stored energy and its work count for nothing;
    `notes` holds the reason for each one that is NaN (nothing dynamic to share)."""
    label, d = excitation_of(ds)
    t = ds["time"].values
    w, why = dynamic_input(ds)
    far = far_medium(ds, label)
    v = directed_velocity(ds, measured, measured_along(ds, measured))
    e_far, why_far = dynamic_energy(ds, far)
    why_far = why or why_far
    e_solid = dynamic_energy(ds, None)[0] if "energy_solid" in ds else np.zeros_like(t)
    nan = float("nan")
    out = {
        "excited": label,
        "measured": measured,
        "arrival_measured_s": pulse_arrival(t, v, driven_peak_speed(ds, label)),
        "arrival_solid_s": solid_arrival(ds) if "energy_solid" in ds else nan,
        "peak_velocity_m_s": float(np.abs(v).max()),
        "far_medium": far,
        "energy_far_peak_frac": float(e_far.max() / w) if why_far is None else nan,
        "energy_far_final_frac": float(e_far[-1] / w) if why_far is None else nan,
        "solid_energy_peak_frac": float(e_solid.max() / w) if why is None else nan,
        "input_work_J": w,  # the dynamic loads' work, or a striker's energy
    }
    notes = {k: why_far for k in ("energy_far_peak_frac", "energy_far_final_frac") if why_far}
    notes.update({k: why for k in ("solid_energy_peak_frac", "input_work_J", "arrival_solid_s") if why})
    try:
        out["spectral_centroid_hz"] = spectral_centroid(ds, modes, model)
    except ValueError:
        out["spectral_centroid_hz"] = nan
    out["notes"] = notes
    return out


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
