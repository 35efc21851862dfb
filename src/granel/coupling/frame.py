"""The solid's contact points as the coupled solvers see them: each one's unit normal and tangent,
and whether it can move tangentially (the beam's cannot) or at all (a rigid solid)."""

from __future__ import annotations

import numpy as np

from ..granular.system import GranularSystem
from ..solid.base import SolidModel
from . import core


def contact_frame(system: GranularSystem, model: SolidModel) -> core.ContactFrame:
    """Each contact's unit tangent t = k x n, whether it can move tangentially, whether the solid is rigid."""
    tangents = np.array([[-c.normal[1], c.normal[0]] for c in system.solid_contacts], float).reshape(-1, 2)
    has_t = np.array([c.dof_y >= 0 for c in model.contacts], bool)
    return core.ContactFrame(tangents, has_t, model.ndof == 0)


def contact_normals(system: GranularSystem) -> np.ndarray:
    """Each solid contact's unit normal n_ik, from the granule toward the solid (nc, 2)."""
    return np.array([c.normal for c in system.solid_contacts], float).reshape(-1, 2)
