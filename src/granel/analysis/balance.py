"""The energy balance (13) of a result against an energy scale."""

from __future__ import annotations

import numpy as np


def _largest(ds, name: str, relative_to_start: bool = False) -> float:
    if name not in ds:
        return 0.0
    v = np.asarray(ds[name].values, float)
    if not v.size:
        return 0.0
    return float(np.abs(v - v[0] if relative_to_start else v).max())


def balance_scale(ds) -> tuple[float, str]:
    """The energy the balance (13) of a result is measured against [J], and its name: the largest
    of the loads' input work, the energy stored at t = 0 (the granules' kinetic and contact
    energy, eq. 11, and the solid's: a preloaded medium's) and the work gravity does on the
    granules (the change of their gravitational potential); (0, "input work") for a result in
    which nothing stores or moves energy."""
    media = [str(m) for m in np.unique(np.asarray(ds["medium"].values))] if "medium" in ds else []
    stored = sum(_first(ds, f"energy_{m.lower()}") for m in media) + _first(ds, "energy_solid")
    candidates = [(_largest(ds, "input_work"), "input work"), (abs(stored), "initial stored energy"),
                  (_largest(ds, "energy_gravity", relative_to_start=True), "work of gravity")]
    return max(candidates, key=lambda c: c[0])


def _first(ds, name: str) -> float:
    if name not in ds:
        return 0.0
    v = np.asarray(ds[name].values, float)
    return float(v[0]) if v.size else 0.0


def relative_balance_error(ds, scale: float | None = None) -> float:
    """The largest |E + D - W| of eq. (13) (a result's `balance_error`, counted from t = 0) over
    `scale` [J], by default `balance_scale`; NaN when the scale is not positive."""
    if scale is None:
        scale = balance_scale(ds)[0]
    err = np.abs(np.asarray(ds["balance_error"].values, float))
    return float(err.max() / scale) if scale > 0 and err.size else float("nan")
