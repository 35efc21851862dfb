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


def peak_displacement(ds, model, modes=None) -> tuple[float, float]:
    """The largest displacement of the solid's drawn nodes over its stored outputs [m] (|u| of
    `SolidModel.full_displacement`: a bending plate's or string's deflection along the line the
    granules touch, a plate's in-plane motion at its mesh nodes) and the stored time it occurs
    [s]. A modal result maps the modes that moved to the nodes at once, then combines them by the
    modal coordinates over time; a nodal one maps its states. ValueError for a result without
    the solid's state."""
    from ..io.results import require

    if "solid_x" not in ds:
        require(ds, ["solid_eta"], "the solid's displacement")
    times = ds["solid_time"].values
    if not len(times):
        return 0.0, float("nan")
    if "solid_x" in ds:
        u = np.moveaxis(model.full_displacement(ds["solid_x"].values.astype(float).T), 2, 0)
    else:
        if modes is None:
            from ..solid.mode_cache import all_modes

            modes = all_modes(model)
        eta = ds["solid_eta"].values.astype(float)
        moved = np.flatnonzero(np.abs(eta).max(axis=0) > 0)
        every = len(moved) == modes.shapes.shape[1]
        shapes = model.full_displacement(np.asarray(modes.shapes if every else modes.shapes[:, moved], float))
        u = np.tensordot(eta[:, moved], shapes, axes=([1], [2]))  # (outputs, nodes, 2)
    size = np.hypot(u[..., 0], u[..., 1])
    k = int(np.unravel_index(np.argmax(size), size.shape)[0])
    return float(size.max()), float(times[k])
