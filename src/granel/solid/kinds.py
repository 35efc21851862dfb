"""The kinds of solid by name (the scenario's solid.kind): each an object carrying its behaviour
(`base.SolidKind`), so that builders, solvers, analyses and pictures ask the kind instead of
testing its name."""

from __future__ import annotations

from .base import RigidKind, SolidKind, SolidModel
from .beam import BEAM
from .bending_plate import BENDING_PLATE
from .membrane import MEMBRANE
from .plate import PLATE
from .string import STRING

KINDS: dict[str, SolidKind] = {k.name: k for k in (PLATE, BEAM, STRING, BENDING_PLATE, MEMBRANE, RigidKind())}


def kind_of(solid) -> SolidKind:
    """The kind of a solid model, a recipe or a name; ValueError naming the known kinds."""
    name = solid if isinstance(solid, str) else solid.kind
    try:
        return KINDS[name]
    except KeyError:
        raise ValueError(f"unknown solid kind {name!r} ({', '.join(KINDS)})") from None


def is_elastic(name: str) -> bool:
    """Whether a solid of kind `name` moves (False for rigid, absent or unknown kinds)."""
    return name in KINDS and KINDS[name].elastic


__all__ = ["KINDS", "SolidKind", "SolidModel", "is_elastic", "kind_of"]
