"""The energy balance (13) of a result against an energy scale."""

from __future__ import annotations

import numpy as np


def relative_balance_error(ds, scale: float | None = None) -> float:
    """The largest |E + D - W| of eq. (13) (a result's `balance_error`, counted from t = 0) over
    `scale` [J], by default the largest |input work|; NaN when the scale is not positive."""
    if scale is None:
        w = np.abs(np.asarray(ds["input_work"].values, float))
        scale = float(w.max()) if w.size else 0.0
    err = np.abs(np.asarray(ds["balance_error"].values, float))
    return float(err.max() / scale) if scale > 0 and err.size else float("nan")
