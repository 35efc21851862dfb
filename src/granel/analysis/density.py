"""Normalised energy densities, eq. (14): w / w0 with w = E / V per element or granule and
w0 = 1/2 m v0^2 / V0, the peak kinetic energy density of the excited granule."""

from __future__ import annotations

import numpy as np


def excited_reference(ds) -> float:
    """w0 = 1/2 m v0^2 / V of the excited granule (v0: its peak speed)."""
    from .reciprocity import excitation_of

    label, _ = excitation_of(ds)
    g = list(ds["granule"].values).index(label)
    import tomllib

    sc = tomllib.loads(ds.attrs["scenario"])
    medium = label.split(":")[0]
    med = next(m for m in sc["media"] if m["name"] == medium)
    R = med["radius"]
    rho = sc["materials"][med.get("material", "steel")]["rho"]
    V = 4 / 3 * np.pi * R**3
    v0 = float(np.hypot(ds["v_x"].values[:, g], ds["v_y"].values[:, g]).max())
    return 0.5 * rho * V * v0**2 / V


def granule_energy_density(system, y_state_energies, radius) -> np.ndarray:
    """Energy per granule volume from per-granule energies (kinetic + rotational + potential)."""
    return np.asarray(y_state_energies) / (4 / 3 * np.pi * np.asarray(radius) ** 3)


def solid_energy_density(model, q, v) -> np.ndarray:
    """(kinetic + strain energy) / volume of each element of the solid."""
    kin, pot = model.element_energies(q, v)
    return (np.asarray(kin) + np.asarray(pot)) / model.element_volume


def beam_energy_density_grid(model, q, v, nx: int = 21) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's interpolation of beam element energies across the width (Sec. IV): kinetic
    energy uniform across the width, strain energy parabolic (zero on the neutral axis), each
    integrating back to the element's energy. Returns (x (nx,), y edges (ne+1,), w (ne, nx))."""
    kin, pot = model.element_energies(q, v)
    vol = model.element_volume
    depth = model.info["width"]
    s = np.linspace(-0.5, 0.5, nx)
    shape = 12.0 * s**2  # the mean of 12 s^2 over s in [-1/2, 1/2] is 1
    w = (kin / vol)[:, None] + (pot / vol)[:, None] * shape[None, :]
    return model.nodes[0, 0] + s * depth, model.nodes[:, 1], w
