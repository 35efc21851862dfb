"""The solid's stored state, whatever its representation: mass-normalised modal coordinates
(solid_eta, solid_eta_dot: q = Phi eta) for solids with all modes, reduced nodal coordinates
(solid_x, solid_v) for solids too large for them. Analysis and figures read the solid through
these functions and `modal.modal_coordinates`, never through the solver that ran."""

from __future__ import annotations

import numpy as np


def nearest_solid_outputs(ds, times) -> np.ndarray:
    """Indices of the stored solid states nearest to `times`."""
    from ..io.results import require

    require(ds, ["solid_time"], "the solid's state")
    st = ds["solid_time"].values
    return np.abs(st[None, :] - np.atleast_1d(np.asarray(times, float))[:, None]).argmin(axis=1)


def reduced_states(ds, times, model=None, modes=None) -> tuple[np.ndarray, np.ndarray]:
    """The solid's reduced (q, v), shape (len(times), ndof) each, at the stored solid times
    nearest to `times`; modal results need the solid's `modes` (or its `model` to compute them)."""
    k = nearest_solid_outputs(ds, times)
    if "solid_x" in ds:
        return ds["solid_x"].values[k].astype(float), ds["solid_v"].values[k].astype(float)
    if modes is None:
        from ..solid.mode_cache import all_modes

        modes = all_modes(model)
    phi = modes.shapes
    return (phi @ ds["solid_eta"].values[k].astype(float).T).T, (phi @ ds["solid_eta_dot"].values[k].astype(float).T).T
