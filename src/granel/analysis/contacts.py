"""Peak contact forces of a run and the size of a design: what shock-mitigation objectives and
design constraints read.

Granule-granule forces are not stored in a result; they are rebuilt at the outputs from the
positions with the elastic Hertz law (eq. 2, F = A delta^(3/2), A of eq. 3 with E* and R* of
eq. 4), so a peak is the largest sampled one (docs/performance.md gives how close it comes).
Wall and solid forces are the recorded ones (`wall_force_normal`,
`contact_force_normal`, which include the damping of eq. 3).
"""

from __future__ import annotations

import numpy as np

from ..granular.materials import pair_coefficients
from ..granular.static import hertz_force_stiffness
from ..io.results import require, require_states


def _pairs(system) -> np.ndarray:
    """Every pair of granules of one medium (contacts exist only within a medium): (k, 2)."""
    i, j = np.triu_indices(system.n, 1)
    same = system.medium_index[i] == system.medium_index[j]
    return np.stack([i[same], j[same]], axis=1)


def peak_pair_force(ds, system) -> float:
    """The largest elastic Hertz force between two granules over the outputs [N] (eq. 2)."""
    pairs = _pairs(system)
    if not len(pairs):
        return 0.0
    i, j = pairs[:, 0], pairs[:, 1]
    A = pair_coefficients(system.bodies(i), system.bodies(j), 0.0)[0]
    require_states(ds, "the largest force between granules")
    x, y = ds["x"].values, ds["y"].values  # (time, granule)
    peak = 0.0
    for start in range(0, x.shape[0], 512):  # blocks of outputs: memory stays at 512 x pairs
        gap = np.hypot(x[start:start + 512, j] - x[start:start + 512, i], y[start:start + 512, j] - y[start:start + 512, i])
        peak = max(peak, float(hertz_force_stiffness(A, system.radius[i] + system.radius[j] - gap)[0].max()))
    return peak


def peak_forces(ds, system) -> dict[str, float]:
    """peak_contact_force_N (any granule pair, wall or solid contact), peak_pair_force_N,
    peak_wall_force_N and peak_solid_force_N of a run (0 where there is no such contact)."""
    walls, contacts = ds.sizes.get("wall", 0), ds.sizes.get("contact", 0)
    require(ds, ["wall_force_normal"] * bool(walls) + ["contact_force_normal"] * bool(contacts), "the peak forces")
    wall = float(np.nanmax(ds["wall_force_normal"].values)) if walls and ds.sizes.get("time", 0) else 0.0
    solid = float(np.nanmax(ds["contact_force_normal"].values)) if contacts and ds.sizes.get("time", 0) else 0.0
    pair = peak_pair_force(ds, system)
    return {"peak_contact_force_N": max(pair, wall, solid), "peak_pair_force_N": pair,
            "peak_wall_force_N": max(wall, 0.0), "peak_solid_force_N": max(solid, 0.0)}


def design_size(system) -> dict[str, float]:
    """granular_mass_kg (all granules) and footprint_m2 (the bounding box of the granules'
    discs, an area in the plane of the model) of a built granular system."""
    lo = (system.pos0 - system.radius[:, None]).min(axis=0)
    hi = (system.pos0 + system.radius[:, None]).max(axis=0)
    return {"granular_mass_kg": float(system.mass.sum()), "footprint_m2": float(np.prod(hi - lo))}
