"""Normalised energy densities, eq. (14): w / w0 with w = E / V per element or granule and
w0 = 1/2 m v0^2 / V0, the peak kinetic energy density of the excited granule."""

from __future__ import annotations

import numpy as np

from ..granular.bundles import state_size, state_views
from ..granular.materials import granule_volume
from ..io.results import granule_column, require_states


def excited_reference(ds) -> float:
    """w0 of eq. (14), 1/2 m v0^2 / V of the excited granule (v0: its peak speed), its mass and
    radius from the result's model record."""
    from ..io.model import read_record
    from .reciprocity import excitation_of

    label, _ = excitation_of(ds)
    g = granule_column(ds, label, "the energy density's reference w0 (eq. 14)")
    rec = read_record(ds)
    v0 = float(np.hypot(ds["v_x"].values[:, g], ds["v_y"].values[:, g]).max())
    return 0.5 * float(rec.mass[g]) * v0**2 / granule_volume(float(rec.radius[g]))


def granule_energy_density(system, y_state_energies, radius) -> np.ndarray:
    """w of eq. (14) per granule: its energy (kinetic + rotational + potential, eq. 11) over its
    volume."""
    return np.asarray(y_state_energies) / granule_volume(np.asarray(radius, float))


def solid_energy_density(model, q, v) -> np.ndarray:
    """w of eq. (14) per element of the solid: (kinetic + strain energy) / volume."""
    return model.element_energy_density(q, v)


def granule_states(ds, idx: np.ndarray) -> np.ndarray:
    """The granular state vectors y (see granular.kernels) at output indices idx: (len(idx), 6n+3)."""
    require_states(ds, "the granules' energy density")
    x, y = ds["x"].values[idx], ds["y"].values[idx]
    n = x.shape[1]
    Y = np.zeros((len(idx), state_size(n)))
    v = state_views(Y, n)
    v.pos[..., 0], v.pos[..., 1] = x, y
    v.theta[:] = ds["theta"].values[idx]
    v.vel[..., 0], v.vel[..., 1] = ds["v_x"].values[idx], ds["v_y"].values[idx]
    v.spin[:] = ds["omega"].values[idx]
    return Y


def granule_energies(system, Y: np.ndarray, SU: np.ndarray | None = None) -> np.ndarray:
    """Per-granule energy (kinetic + rotational + contact-potential share, eq. 11) for each state
    row of Y, with contact points displaced by SU[f] (nc, 2). One Stepper serves all frames; its
    neighbour list is rebuilt (`Stepper.maybe_refresh`) only when a granule has moved by half the
    skin since the last build, so it always holds every touching pair, in the order a fresh list
    would (`figures.granule_energies_at` is this for one frame)."""
    from ..granular.system import GranularState, Stepper

    n = system.n
    st = Stepper(system)
    out = np.empty((len(Y), n))
    for f, y in enumerate(Y):
        st.maybe_refresh(state_views(y, n).pos)
        kin, rot, pot = st.energies(GranularState(y, 0.0), None if SU is None else SU[f])
        out[f] = kin + rot + pot
    return out
