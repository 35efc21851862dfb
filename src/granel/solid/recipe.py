"""What a solid is built from: its kind, geometry, material, mesh, clamping and contact points
(`SolidRecipe`), and the one function that builds it (`build_solid_model`). The scenario builder
writes a recipe; a result stores it as JSON, so that its solid is built again without the scenario
(the plate's assembly and the modes then come from their disk caches)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from .base import Material, Slab, SolidModel
from .kinds import kind_of
from .plate import PlateMesh


@dataclass(frozen=True)
class RecipeContact:
    """A contact point: its name (the granule's label), rest position, unit normal n_ik (granule ->
    solid; +x on the left face) and, on a plate, the length of its rigid layer."""

    name: str
    position: tuple[float, float]
    normal: tuple[float, float]
    layer: float = 0.0

    @property
    def edge(self) -> str:
        return "left" if self.normal[0] > 0 else "right"


@dataclass(frozen=True)
class SolidRecipe:
    """What a solid of `kind` (`solid.kinds`) is built from: the rectangle x0, y0, width, length
    and the out-of-plane thickness [m], Young's modulus E [Pa], Poisson's ratio nu, density rho
    [kg/m^3], the contacts, the plate's mesh, the beam's or string's element count, the clamped
    (held) ends (bottom, top), the string's tension [N], its foundation's stiffness per length
    [N/m^2] and whether it bends, and a bending plate's edges (bottom, top, front, back: clamped,
    simple or free; a disc's rim), shape (rectangle or disc), the levels of its mesh's grading toward
    the contacts and its theory (kirchhoff or mindlin). Fields a kind does not use keep their defaults."""

    kind: str
    contacts: tuple[RecipeContact, ...] = ()
    x0: float = 0.0
    y0: float = 0.0
    width: float = 0.0
    length: float = 0.0
    thickness: float = 0.0
    E: float = 0.0
    nu: float = 0.0
    rho: float = 0.0
    mesh: PlateMesh = field(default_factory=PlateMesh)
    beam_elements: int = 0
    clamped: tuple[bool, bool] = (True, True)
    tension: float = 0.0
    foundation: float = 0.0
    bending: bool = True
    edges: tuple[str, ...] = ()
    shape: str = "rectangle"
    refinement: int = 0
    theory: str = "kirchhoff"

    @property
    def slab(self) -> Slab:
        return Slab(self.x0, self.y0, self.width, self.length, self.thickness)

    @property
    def material(self) -> Material:
        return Material(self.E, self.rho, self.nu)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "SolidRecipe":
        """The recipe of `to_json`; ValueError (or KeyError, TypeError) for text that is not one."""
        d = json.loads(text)
        contacts = tuple(RecipeContact(str(c["name"]), (float(c["position"][0]), float(c["position"][1])),
                                       (float(c["normal"][0]), float(c["normal"][1])), float(c["layer"]))
                         for c in d.pop("contacts"))
        m = d.pop("mesh")
        mesh = PlateMesh(int(m["nx"]), float(m["growth"]), float(m["max_size"]), float(m["x_growth"]),
                         bool(m["rigid_layers"]))
        clamped = tuple(bool(c) for c in d.pop("clamped"))
        kind, elements = str(d.pop("kind")), int(d.pop("beam_elements"))
        bending = bool(d.pop("bending", True))
        edges = tuple(str(e) for e in d.pop("edges", ()))
        shape = str(d.pop("shape", "rectangle"))
        refinement = int(d.pop("refinement", 0))
        theory = str(d.pop("theory", "kirchhoff"))
        return cls(kind, contacts, mesh=mesh, beam_elements=elements, clamped=clamped, bending=bending, edges=edges,
                   shape=shape, refinement=refinement, theory=theory, **{k: float(v) for k, v in d.items()})


def build_solid_model(recipe: SolidRecipe) -> SolidModel:
    """The solid of a recipe, built by its kind (`solid.kinds`) and carrying the recipe
    (`SolidModel.recipe`); ValueError from the builders (a beam contact off a node or on a clamped
    one, layers that overlap, an unknown kind, ...)."""
    model = kind_of(recipe.kind).build(recipe)
    model.recipe = recipe
    return model
