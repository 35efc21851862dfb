"""Modal energies of the solid, eqs. (15)-(16) (Figs. 7 and 9).

With mass-normalised modes phi_n (phi' M phi = I), the modal coordinates of a reduced state q
are X = phi' M q, and the modal energy is E_n = 1/2 (Xdot_n^2 + w_n^2 X_n^2); the modal energies
sum to the solid energy 1/2 v'Mv + 1/2 q'Kq when all modes are kept.
"""

from __future__ import annotations

import numpy as np

from ..solid.modal import mode_energy


def modal_coordinates(ds, modes=None, model=None):
    """(times, X (nt, nm), Xdot (nt, nm), omega (nm)) from a result Dataset.

    Solids with all modes store modal coordinates (whichever method ran); a solid too large for
    them stores the reduced state q, v, projected here on `modes` (of `model` if not given)."""
    from ..io.results import require

    require(ds, ["solid_time"], "the solid's modal coordinates")
    t = ds["solid_time"].values
    if "solid_eta" in ds:
        return t, ds["solid_eta"].values.astype(float), ds["solid_eta_dot"].values.astype(float), ds["mode_omega"].values
    if "solid_x" not in ds:
        raise ValueError("the Dataset holds no solid state (rigid solid?)")
    if modes is None:
        if model is None:
            raise ValueError("give `modes` (or `model`) to project a reduced solid state on modes")
        from ..solid.mode_cache import all_modes

        modes = all_modes(model)
    M = model.M if model is not None else None
    if M is None:
        raise ValueError("projection needs the model's mass matrix")
    q = ds["solid_x"].values.astype(float)
    v = ds["solid_v"].values.astype(float)
    PhiM = (M @ modes.shapes).T  # (nm, ndof)
    return t, q @ PhiM.T, v @ PhiM.T, modes.omega


def modal_energies(X, Xdot, omega) -> np.ndarray:
    """E_n(t) of eq. (15) (`solid.modal.mode_energy`, kinetic plus strain): shape (nt, nm)."""
    kinetic, strain = mode_energy.py_func(np.asarray(X, float), np.asarray(Xdot, float), np.asarray(omega, float)[None, :])
    return kinetic + strain


def accumulated_modal_energy(E: np.ndarray, counts=(6, 100, 1000)) -> dict[int, np.ndarray]:
    """Sum of the leading N modal energies (eq. 15) vs time, for each N (Fig. 7)."""
    cum = np.cumsum(E, axis=1)
    return {int(n): cum[:, min(n, E.shape[1]) - 1] for n in counts}


def time_averaged_shares(E: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Each mode's share of the time-integrated solid energy, int E_n dt / int E dt: the terms of
    eq. (16)."""
    integ = np.trapezoid(E, t, axis=0)
    total = integ.sum()
    return integ / total if total > 0 else np.zeros(E.shape[1])


def time_averaged_accumulation(E: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Eq. (16): sum_{n<=N} int E_n dt / int E dt, for N = 1..nm (Fig. 9)."""
    return np.cumsum(time_averaged_shares(E, t))


def modes_for_fraction(accumulation: np.ndarray, fraction: float) -> int:
    """The smallest N whose time-averaged accumulation (16) reaches `fraction`."""
    idx = np.flatnonzero(accumulation >= fraction - 1e-12)
    return int(idx[0] + 1) if len(idx) else int(len(accumulation))
