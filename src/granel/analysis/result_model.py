"""The models behind a result, from the record it carries (`io.model.read_record`, the one entry
point): its granular system (`result_system`), its solid built from the recorded recipe by
`solid.recipe.build_solid_model` (`result_solid`), and the solid's modes from their disk cache
(`result_modes`). Nothing here reads or builds the scenario."""

from __future__ import annotations

import functools

import numpy as np

from ..granular.loads import KINDS, WallDrive, load_history
from ..granular.packing import Wall
from ..granular.system import ContactLaw, Excitation, GranularSystem, SolidContact
from ..io.model import read_record
from ..io.results import ResultFileError
from ..solid.base import SolidModel, rigid_solid
from ..solid.kinds import KINDS as SOLID_KINDS
from ..solid.mode_cache import all_modes
from ..solid.recipe import SolidRecipe, build_solid_model


def result_system(ds, name="result") -> GranularSystem:
    """The granular system of a result: granules, contact law, walls, solid contacts and loads."""
    rec = read_record(ds, name)
    if any(e.kind not in KINDS for e in rec.loads):
        raise ResultFileError(f"{name}: damaged result (its model record: a load of unknown kind)", 2)
    loads = [Excitation(e.granule, e.direction, load_history(e.kind, e.params, np.array(e.times), np.array(e.values)),
                        e.toward) for e in rec.loads]
    walls = [Wall(p0=w.p0, p1=w.p1, normal=w.normal, medium=w.medium, name=w.name,
                  drive=WallDrive(*w.drive) if w.drive[1] != 0 else None, damped=w.damped)
             for w in rec.walls]
    contacts = [SolidContact(c.granule, c.position, c.normal, c.name) for c in rec.contacts]
    return GranularSystem(labels=list(rec.labels), medium_index=rec.medium_index, media=list(rec.media),
                          pos0=rec.position0, radius=rec.radius, mass=rec.mass, inertia=rec.inertia, E=rec.E, nu=rec.nu,
                          law=ContactLaw(rec.mu, rec.alpha_n, rec.k_s), walls=walls, solid_contacts=contacts,
                          excitations=loads, skin=rec.skin, toward_solid=rec.toward_solid, strikers=rec.strikers,
                          gravity=rec.gravity)


def result_solid(ds, name="result") -> SolidModel:
    """The solid of a result, built from its recorded recipe (cached per process; a rigid solid from
    its contacts). ResultFileError (code 2) naming `name` if it cannot be built or differs from the
    record (its DOFs, its contacts' DOFs)."""
    rec = read_record(ds, name)
    if rec.solid_kind not in SOLID_KINDS:
        raise ResultFileError(f"{name}: damaged result (its solid's kind {rec.solid_kind!r} is none of "
                              f"{', '.join(SOLID_KINDS)})", 2)
    if not SOLID_KINDS[rec.solid_kind].elastic:
        return rigid_solid([(c.name, c.position, c.normal) for c in rec.contacts])
    if not rec.solid_recipe:
        raise ResultFileError(f"{name}: its {rec.solid_kind} was not built from a recipe (solid.recipe): its model "
                              "cannot be built again", 2)
    try:
        model = _built(rec.solid_recipe)
    except (ValueError, KeyError, TypeError) as e:
        raise ResultFileError(f"{name}: damaged result (its solid's recipe: {type(e).__name__}: {e})", 2) from None
    dofs = [(c.dof_x, c.dof_y, c.dof_rotation) for c in model.contacts]
    if model.ndof != rec.solid_dofs or dofs != [c.dofs for c in rec.contacts]:
        raise ResultFileError(f"{name}: its solid, built from its recipe, has {model.ndof} DOFs and contacts at DOFs "
                              f"{dofs[:3]}...; its record says {rec.solid_dofs} DOFs and {[c.dofs for c in rec.contacts][:3]}"
                              "... (the solid's assembly changed since the result was written)", 2)
    return model


@functools.lru_cache(maxsize=8)
def _built(recipe: str) -> SolidModel:
    return build_solid_model(SolidRecipe.from_json(recipe))


_MODES: dict = {}


def result_modes(ds, name="result"):
    """All modes of a result's solid (`solid.mode_cache.all_modes`, from the disk cache), kept per
    process for the last solid asked for (a movie's frames and a figure's panels share them)."""
    key = read_record(ds, name).solid_digest
    if key not in _MODES:
        _MODES.clear()
        _MODES[key] = all_modes(result_solid(ds, name))
    return _MODES[key]

