"""Scenario -> simulation -> result Dataset, and the run summary."""

from __future__ import annotations

import time

import numpy as np
import xarray as xr

from . import scenario as S
from .checkpoint import fingerprint
from .coupling.rigid import simulate_rigid
from .granular.system import Stepper
from .results import base_attrs, granular_dataset


def run_scenario(sc: S.Scenario, progress=None, checkpoint=None, resume=None) -> xr.Dataset:
    """Run a validated scenario and return its result Dataset."""
    system, state, media = S.build_granular(sc, sc.base)
    sim = sc.simulation
    kind = sc.solid.kind if sc.solid is not None else "rigid"
    t0 = time.perf_counter()
    fp = fingerprint(S.to_toml(sc))
    if kind == "rigid":
        stepper = Stepper(system, substep=True)
        rec = simulate_rigid(stepper, state, sim.duration, sim.dt, sim.output_every, progress,
                             checkpoint if sim.checkpoint_every > 0 else None, sim.checkpoint_every, resume, fp)
        steps = int(round(rec.times[-1] / sim.dt))
        solver = {"name": "rk4-rigid", "dt": sim.dt, "steps": steps}
    else:
        from .coupling.coupled import simulate_coupled

        return simulate_coupled(sc, progress, checkpoint, resume)
    wall = time.perf_counter() - t0
    solver["wall_time_s"] = wall
    solver["neighbour_rebuilds"] = stepper.rebuilds
    attrs = base_attrs(S.to_toml(sc), solver)
    attrs["solid_kind"] = kind
    ds = granular_dataset(rec.times, system.labels, system.media, system.medium_index, rec.rec, attrs)
    return ds


def summarize(ds: xr.Dataset) -> dict:
    """Numbers for the end-of-run table and --json-summary."""
    w = ds["input_work"].values
    wmax = float(np.max(np.abs(w))) if w.size else 0.0
    err = np.abs(ds["balance_error"].values)
    speed = np.hypot(ds["v_x"].values, ds["v_y"].values)
    peak = speed.max(axis=0)
    out = {
        "scenario": _scenario_name(ds),
        "solid": ds.attrs.get("solid_kind", ""),
        "steps": int(ds.attrs.get("solver_steps", 0)),
        "wall_time_s": float(ds.attrs.get("solver_wall_time_s", float("nan"))),
        "simulated_time_s": float(ds["time"].values[-1]),
        "input_work_J": wmax,
        "max_balance_error_J": float(err.max()) if err.size else 0.0,
        "max_balance_error_rel": float(err.max() / wmax) if wmax > 0 else float(err.max()),
        "peak_speed": {},
    }
    for m in np.unique(ds["medium"].values):
        sel = ds["medium"].values == m
        g = int(np.argmax(np.where(sel, peak, -1)))
        out["peak_speed"][str(m)] = {"granule": str(ds["granule"].values[g]), "m_per_s": float(peak[g])}
    for key in ("solver_mean_iterations", "solver_min_step"):
        if key in ds.attrs:
            out[key[7:]] = float(ds.attrs[key])
    return out


def _scenario_name(ds) -> str:
    import tomllib

    try:
        return tomllib.loads(ds.attrs["scenario"]).get("name", "")
    except Exception:  # noqa: BLE001 - a summary must not fail on foreign files
        return ""
