"""A tensioned string (a cord) lying in the granular plane along y, struck across it (along x):
rho A w_tt + EI w'''' - T w'' + k_f w = f, with T the tension, EI the bending stiffness (zero for
a perfectly flexible cord; the tensioned beam otherwise) and k_f an elastic foundation's stiffness
per length. Hermite cubic elements as the beam's (eq. 9); docs/solids.md ("String")."""

from __future__ import annotations

import numpy as np

from .base import Material, Slab, SolidModel
from .beam import BeamKind, hermite_line, hermite_mass, hermite_stiffness
from .dispersion import string_frequency


def geometric_stiffness(tension: float, l: float) -> np.ndarray:
    """The Hermite cubic element's stiffness of a tension T: T int w' v' dy over an element of
    length l (the consistent geometric stiffness matrix)."""
    return tension / (30.0 * l) * np.array([[36, 3 * l, -36, 3 * l], [3 * l, 4 * l * l, -3 * l, -l * l],
                                            [-36, -3 * l, 36, -3 * l], [3 * l, -l * l, -3 * l, 4 * l * l]])


def build_string(slab: Slab, material: Material, contacts, n_elements: int = 40, held=(True, True),
                 tension: float = 0.0, foundation: float = 0.0, bending: bool = False) -> SolidModel:
    """The string of the solid `slab`: a cord of section A = width x thickness (width in the granular
    plane, thickness out of it) and linear density rho A, under `tension` [N], on a foundation of
    `foundation` [N/m^2] (stiffness per length), with bending stiffness E I (I = thickness width^3 /
    12) if `bending`. Its ends are held where `held` says: the deflection fixed, and the slope too
    when it bends (a clamped tensioned beam); a free end slides across (its slope free). contacts:
    (name, edge 'left'/'right', y), each on a node."""
    A = slab.width * slab.thickness
    EI = material.E * slab.thickness * slab.width**3 / 12.0 if bending else 0.0
    l = slab.length / n_elements
    ke = geometric_stiffness(tension, l) + hermite_mass(foundation, l)
    if bending:
        ke = ke + hermite_stiffness(EI, l)
    end = (0, 1) if bending else (0,)
    fixed = tuple(end if h else () for h in held)
    info = {"EI": EI, "rhoA": material.rho * A, "tension": float(tension), "foundation": float(foundation),
            "width": slab.width, "thickness": slab.thickness}
    return hermite_line("string", slab, material.rho * A, ke, contacts, n_elements, fixed, info)


class StringKind(BeamKind):
    """The tensioned string (`build_string`), drawn, exported and sampled as the beam is."""

    name = "string"
    fields = BeamKind.fields | {"tension", "foundation", "bending_stiffness"}

    def check(self, section) -> None:
        if not section.tension > 0:
            raise ValueError("solid.tension: a string needs a tension > 0 [N] (a cord without tension and without "
                             "bending stiffness carries no transverse load; for a beam, kind = \"beam\")")
        if not any(section.clamped) and section.foundation == 0:
            raise ValueError("solid.clamped: a string held at neither end, on no foundation, moves across as a rigid "
                             "body; hold an end (clamped) or give it a foundation (solid.foundation)")

    def recipe_fields(self, section, material) -> dict:
        return super().recipe_fields(section, material) | dict(
            tension=section.tension, foundation=section.foundation, bending=section.bending_stiffness)

    def build(self, recipe) -> SolidModel:
        r = recipe
        return build_string(r.slab, r.material, [(c.name, c.edge, c.position[1]) for c in r.contacts], r.beam_elements,
                            r.clamped, r.tension, r.foundation, r.bending)

    def stress(self, model, x, E, nu):
        """The tension's stress T / A in every element, and the bending stress if it bends."""
        out = {"tension_stress": np.full(model.nelements, model.info["tension"] / model.info["area"])}
        return out | (super().stress(model, x, E, nu) if model.info["EI"] > 0 else {})

    def mode_kinds(self, model, shapes, which):
        return ["transverse" for _ in which]

    def branches(self, model, k, count=3):
        """The tensioned (beam's) branch on its foundation: f = sqrt((T k^2 + EI k^4 + k_f) / rho A) / 2 pi."""
        i = model.info
        return {"string": string_frequency(k, i["tension"], i["rhoA"], i["EI"], i["foundation"])}


STRING = StringKind()
