"""The neighbour search: which points lie closer than a distance, for the contact pairs of a
system (`system.build_neighbours`), a lattice's neighbours (`packing`) and initial overlaps
(`geometry`)."""

from __future__ import annotations

import numpy as np


# below this many granules, all pairs are compared directly (n^2 / 2 distances, a few MB at most);
# above, a k-d tree finds them (scipy.spatial is imported only then: its import is slow)
DIRECT_PAIRS = 2000


def close_pairs(pos: np.ndarray, cutoff: float) -> np.ndarray:
    """The pairs (i < j) of points closer than `cutoff`, as an (m, 2) integer array."""
    n = len(pos)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    if n > DIRECT_PAIRS:
        from scipy.spatial import cKDTree

        return cKDTree(pos).query_pairs(cutoff, output_type="ndarray").astype(np.int64)
    i, j = np.triu_indices(n, 1)
    close = np.hypot(*(pos[j] - pos[i]).T) <= cutoff
    return np.stack([i[close], j[close]], axis=1).astype(np.int64)
