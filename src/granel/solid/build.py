"""Scenario -> SolidModel, with contact points matched to the granular system's."""

from __future__ import annotations

from .base import SolidModel, rigid_solid
from .beam import build_beam
from .plate import LayerSpec, build_plate


def build_solid(sc, system) -> SolidModel:
    """The scenario's solid; one contact point per granule-solid contact of `system`, in the
    same order (names are the granule labels)."""
    s = sc.solid
    if s is None or s.kind == "rigid":
        return rigid_solid([(c.name, c.point, c.normal) for c in system.solid_contacts])
    mat = sc.materials[s.material]
    edges = ["left" if c.normal[0] > 0 else "right" for c in system.solid_contacts]
    if s.kind == "beam":
        return build_beam(s.x0, s.y0, s.width, s.length, s.thickness, mat.E, mat.rho,
                          [(c.name, e, c.point[1]) for c, e in zip(system.solid_contacts, edges)],
                          s.beam_elements, tuple(s.clamped))
    mesh = s.mesh
    layers = [LayerSpec(c.name, e, c.point[1], mesh.layer_fraction * float(system.radius[c.granule]))
              for c, e in zip(system.solid_contacts, edges)]
    return build_plate(s.x0, s.y0, s.width, s.length, s.thickness, mat.E, mat.nu, mat.rho, layers,
                       mesh.nx, mesh.growth, mesh.max_size, mesh.x_growth, mesh.rigid_layers, tuple(s.clamped))
