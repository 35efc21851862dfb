"""The scenario schema (pydantic): every field, its type, range and default. Field-level
validation happens here; whole-scenario checks that need the built geometry in `scenario.build`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal, Union, get_args

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator, model_validator
from pydantic.fields import FieldInfo

from ..granular.loads import KINDS, PAPER_TAU, SHOCK_LEVELS, LoadHistory
from ..guard.exits import InputError
from ..granular.materials import Material
from ..io.units import parse_time


class ScenarioError(InputError):
    """An invalid scenario; the message names the field and the value. Exit code 2, or 4 when
    a file it refers to cannot be read."""


def _time(v):
    try:
        return parse_time(v)
    except ValueError as e:
        raise ValueError(str(e)) from None


def _leaf_types(annotation) -> set:
    """The plain types a field's annotation is built from (through unions, containers and
    Annotated metadata)."""
    args = get_args(annotation)
    if not args:
        return {annotation}
    return set().union(*(_leaf_types(a) for a in args if not isinstance(a, FieldInfo)))


def _misfit(value, leaves: set) -> str | None:
    """Why `value` does not fit a field made of `leaves` where pydantic would convert it: a
    boolean read as a number, or a number or string read as a boolean."""
    items = value if isinstance(value, (list, tuple)) else [value]
    if bool in leaves:
        if leaves <= {bool, type(None)} and any(not isinstance(v, bool) and v is not None for v in items):
            return "a boolean (true or false) is expected"
        return None
    if any(isinstance(v, bool) for v in items) and leaves & {float, int}:
        return "a boolean where a number is expected"
    return None


class _Strict(BaseModel):
    """Unknown fields are errors, every float must be finite (no nan, no inf), a boolean is never
    read as a number (pydantic would take true as 1) and a number never as a boolean."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_type_conversions(cls, data):
        if not isinstance(data, dict):
            return data
        for key, value in data.items():
            field = cls.model_fields.get(key)
            why = None if field is None else _misfit(value, _leaf_types(field.annotation))
            if why:
                # the formatter moves the field name into the location (`files.format_validation_error`)
                raise ValueError(f"@{key}@{value!r}@{why}")
        return data


class OutputsSpec(_Strict):
    """What a run's result file stores (README, "Results"): the energies and the balance (13) are
    always there; each group below can be left out, and the file is compressed."""

    granules: Union[Literal["all", "none"], list[str]] = Field(
        "all", description="the granules whose state is stored at each output: all, none, or a list of labels (traces)")
    contacts: bool = Field(True, description="the forces on the solid at each contact and the largest friction "
                           "eigenvalue between outputs (contact_force_*, lambda_max)")
    walls: bool = Field(True, description="the forces on each rigid wall (wall_force_*)")
    steps: bool = Field(True, description="the record of every accepted step (step_time, step_dt, step_iterations, step_lambda)")
    solid: bool = Field(True, description="the solid's state at its outputs (solid_eta, solid_eta_dot or solid_x, solid_v; "
                        "granel wavefield and the solid's figures need it)")
    compression: int = Field(1, ge=0, le=9, description="gzip level of the result file's arrays, with byte shuffling (0: "
                             "none); measured on the paper's run: docs/performance.md")

    @field_validator("granules")
    @classmethod
    def _labels(cls, v):
        if isinstance(v, list):
            if not v:
                raise ValueError("an empty list: give labels, or \"none\"")
            if len(set(v)) != len(v):
                raise ValueError(f"a label repeats: {sorted(x for x in set(v) if v.count(x) > 1)[0]!r}")
        return v


class SimulationSpec(_Strict):
    duration: float = 8e-4
    dt: float = 4e-8
    output_every: float = 1e-6
    solver: Literal["paper", "fast"] = "fast"  # coupled solver
    abstol: float = Field(1e-6, gt=0, description="absolute tolerance of eq. (A4) [N]")
    reltol: float = Field(1e-6, gt=0, description="relative tolerance of eq. (A4)")
    max_iterations: int = Field(50, ge=1)
    lambda_max: float = Field(0.5, gt=0, lt=1, description="B1: halve the step until max|lambda| <= this")
    max_halvings: int = Field(12, ge=0)
    checkpoint_every: float = 0.0
    solid_output_every: float = Field(0.0, description="interval of stored solid states (0: output_every)")
    integrator: Literal["exact", "newmark"] = Field("exact", description="the fast method's solid integrator: exact (modal, error-controlled steps) or newmark (modal Newmark at dt, the paper's solid scheme)")
    force_model: Literal["quadratic", "linear"] = Field("quadratic", description="exact integrator: the interface force over a step, the polynomial through its values at 0, h/2, h (quadratic) or at 0, h (linear)")
    adaptive: bool = Field(True, description="error-controlled steps (exact integrator); false: every step is dt")
    rtol: float = Field(1e-5, gt=0, lt=1, description="local error tolerance, relative to the largest speed the loads impart")
    atol: float = Field(1e-9, ge=0, description="absolute local error tolerance [m/s]")
    max_step: float = Field(1e-6, description="largest adaptive step [s]")
    mode_cutoff: Union[Literal["auto"], Annotated[float, Field(gt=0)]] = Field(
        "auto", description="exact integrator: eigenmodes above this frequency [Hz] are replaced by residual modes; auto: "
        "from rtol and the stiffest solid contact (granular.scales.auto_mode_cutoff)")
    ledger_tol: float = Field(8e-7, gt=0, lt=1, description="exact integrator: the energy balance (13) stays within this share of the largest load's energy")
    modes: Literal["all", "below_cutoff"] = Field("all", description="exact integrator: compute every eigenmode of the solid and the residual modes of those above mode_cutoff from them (all), or only the modes below mode_cutoff, by Lanczos, and the residual modes from a factorisation of K (below_cutoff: faster when the cut-off keeps few modes); solids beyond 8000 DOFs always take below_cutoff")
    equilibrate: bool = Field(False, description="start from the static equilibrium of the constant loads (preloads), granules and solid (granular.static)")
    balance_limit: float = Field(1e-2, gt=0, description="stop (exit 3) when the energy balance (13) is off by more than this share of the energy put in")
    overlap_limit: float = Field(0.1, gt=0, description="stop (exit 3) when a contact overlaps by more than this share of the smaller radius")
    outputs: OutputsSpec = Field(default_factory=OutputsSpec, description="what the result file stores")

    @field_validator("duration", "dt", "output_every", "checkpoint_every", "solid_output_every", "max_step", mode="before")
    @classmethod
    def _parse(cls, v):
        return _time(v)

    @field_validator("duration", "dt", "output_every", "max_step")
    @classmethod
    def _positive(cls, v):
        if not v > 0 or not math.isfinite(v):
            raise ValueError(f"must be a positive time, got {v!r}")
        return v

    @model_validator(mode="after")
    def _step_within_run(self):
        if "max_step" in self.model_fields_set and self.max_step > self.duration:
            raise ValueError(f"@max_step@{self.max_step!r}@the largest step must not exceed simulation.duration "
                             f"({self.duration:.3e} s)")
        return self

    @field_validator("checkpoint_every", "solid_output_every")
    @classmethod
    def _zero_or_positive(cls, v):
        if not v >= 0 or not math.isfinite(v):
            raise ValueError(f"must be a time >= 0 (0: none, or every output), got {v!r}")
        return v


class ContactSpec(_Strict):
    mu: float = Field(0.099, ge=0, le=10, description="Coulomb friction coefficient, eq. (5) (the paper's 0.099)")
    alpha_n: float = Field(6.313e-3, ge=0, description="Tsuji damping, eq. (3) (the paper's 6.313e-3; 0: undamped)")
    k_s: float = Field(100.0, gt=0, description="tanh smoothness of the friction law, eq. (5) [s/m]")


# the physical ranges granel's models hold in double precision (masses, stiffnesses and eigenvalues
# spanning more than these lose their digits): lengths from 0.1 um to 10 km, moduli up to 1e20 Pa,
# densities from 1e-3 (a rarefied gas) to 1e6 kg/m^3 (fifty times osmium's)
LENGTH_MIN, LENGTH_MAX = 1e-7, 1e4
# positions within 1 km of the origin: a granule's overlap with the solid (under a micrometre) is
# the difference of two positions, which keep eps |x| of their value (1e4 m left 2e-12 m: the
# steps fell to 1e-10 s and the ledger drifted); a solid's mesh is built in its own frame
COORDINATE_MAX = 1e3


class MaterialSpec(_Strict):
    E: float = Field(gt=0, le=1e20, description="Young's modulus [Pa]")
    rho: float = Field(ge=1e-3, le=1e6, description="density [kg/m^3]")
    nu: float = Field(gt=-1, lt=0.5, description="Poisson's ratio")

    def material(self) -> Material:
        return Material(self.E, self.rho, self.nu)


class PlateMeshSpec(_Strict):
    nx: int = Field(6, ge=2, description="elements across the width")
    layer_elements: int = Field(2, ge=2, le=2, description="elements on each rigid layer (the paper: 2)")
    growth: float = Field(1.6, gt=1.0, le=3.0, description="element size growth ratio away from contacts")
    max_size: float = Field(2.0e-3, gt=0, description="largest element size along the length [m]")
    x_growth: float = Field(1.5, ge=1.0, le=3.0, description="element width growth from the edges to the mid-line")
    layer_fraction: float = Field(0.1, gt=0, lt=1, description="rigid layer length / granule radius (paper: 1/10)")
    rigid_layers: bool = True


Edge = Literal["clamped", "simple", "fixed", "free"]
# the [solid] fields of the kinds struck across their surface, refused on the kinds that do not read them
SURFACE_FIELDS = frozenset({"shape", "edges", "surface_elements", "contact_refinement", "plate_theory", "tension",
                            "foundation", "bending_stiffness"})


class SolidSpec(_Strict):
    kind: Literal["plate", "beam", "string", "bending_plate", "membrane", "rigid", "none"] = "plate"
    material: str = "steel"
    x0: float = Field(0.0, ge=-COORDINATE_MAX, le=COORDINATE_MAX)
    y0: float = Field(0.0, ge=-COORDINATE_MAX, le=COORDINATE_MAX)
    width: float = Field(0.01, ge=LENGTH_MIN, le=LENGTH_MAX)
    length: float = Field(0.1, ge=LENGTH_MIN, le=LENGTH_MAX)
    thickness: float = Field(0.001, ge=LENGTH_MIN, le=LENGTH_MAX)
    beam_elements: int = Field(40, ge=2, description="elements along a beam or a string")
    mesh: PlateMeshSpec = PlateMeshSpec()
    clamped: tuple[bool, bool] = Field((True, True), description="(bottom, top) ends held: a string's deflection "
                                       "(and slope, if it bends) fixed there; a plate's or beam's end clamped")
    tension: float = Field(0.0, ge=0.0, le=1e12, description="string: its tension [N]; membrane: its tension per "
                           "length [N/m] (> 0)")
    foundation: float = Field(0.0, ge=0.0, le=1e18, description="string: an elastic foundation's stiffness per length "
                              "[N/m^2]; membrane, bending_plate: per area [N/m^3] (0: none)")
    bending_stiffness: bool = Field(False, description="string: add the cord's bending stiffness E I, I = thickness "
                                    "width^3 / 12 (a tensioned beam)")
    shape: Literal["rectangle", "disc"] = Field(
        "rectangle", description="bending_plate, membrane: a rectangle (length along y, thickness across the granular "
        "plane) or a disc (its diameter the length, centred on y0 + length / 2 in the granular plane)")
    edges: tuple[Edge, ...] | None = Field(
        None, min_length=1, max_length=4, description="bending_plate, membrane: a rectangle's four edges (bottom y0, "
        "top y0 + length, front z = -thickness/2, back z = +thickness/2), a disc's one (its rim): a plate's each "
        "clamped, simple (supported) or free (default clamped; a disc's rim clamped), a membrane's fixed or free "
        "(default fixed); every edge free (a disc's rim free) only on a foundation")
    surface_elements: int = Field(24, ge=2, le=400, description="bending_plate, membrane: elements along its length "
                                  "or diameter (and as many of the same size across its depth)")
    plate_theory: Literal["kirchhoff", "mindlin"] = Field(
        "kirchhoff", description="bending_plate: kirchhoff (thin: Morley triangles) or mindlin (thick: shear and "
        "rotary inertia, P2 triangles for the deflection and the rotations)")
    contact_refinement: int = Field(0, ge=0, le=6, description="bending_plate, membrane: halve the elements this "
                                    "many times toward the contacts (a graded mesh: at each level the triangles within "
                                    "four of that level's elements of a contact are split)")

    @model_validator(mode="after")
    def _kind(self):
        """What the kind itself refuses (`SolidKind.check`: a string without tension, ...), and the
        fields of the solids struck across their surface given to a kind that does not read them."""
        if self.kind != "none":
            from ..solid.kinds import KINDS, kind_of  # lazy: the solids' modules load scipy, which reading a file needs not

            kind = kind_of(self.kind)
            # fields away from their defaults (a result's scenario attribute holds every field)
            defaults = {f: type(self).model_fields[f].default for f in SURFACE_FIELDS}
            given = set() if kind.stand_in else {f for f in SURFACE_FIELDS if getattr(self, f) != defaults[f]}
            unread = sorted(given - kind.fields)
            if unread:
                readers = ", ".join(k for k, other in KINDS.items() if unread[0] in other.fields)
                raise ValueError(f"solid.{unread[0]}: a {self.kind} solid does not use it (it is read by {readers})")
            kind.check(self)
        return self


class MediumSpec(_Strict):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-]+$")
    side: Literal["left", "right", "none"] = "left"
    radius: float | None = Field(None, ge=LENGTH_MIN, le=LENGTH_MAX)
    material: str = "steel"
    columns: list[Annotated[int, Field(ge=1)]] | None = None
    center_y: float | None = Field(None, ge=-COORDINATE_MAX, le=COORDINATE_MAX,
                                   description="y of column 0's centre (default: the solid's mid-length, or 0)")
    face_x: float | None = Field(None, ge=-COORDINATE_MAX, le=COORDINATE_MAX, description="x of the face column 0 touches (default: the solid's face on this "
                                                   "side, or 0): a medium anywhere")
    grow: Literal["left", "right", "up", "down"] | None = Field(
        None, description="direction the columns stack away from the face (default: the side; required with "
                          "side = 'none'); up/down: horizontal rows from the face line y = face_y")
    face_y: float | None = Field(None, ge=-COORDINATE_MAX, le=COORDINATE_MAX, description="y of the face line of a medium growing up or down (default 0)")
    center_x: float | None = Field(None, ge=-COORDINATE_MAX, le=COORDINATE_MAX, description="x of column 0's centre for a medium growing up or down (default 0)")
    labels: Union[Literal["numeric", "alpha"], list[str]] = "numeric"
    channel_walls: bool | None = Field(None, description="rigid walls along the growth at both ends of column 0 "
                                                         "(default true, or as `walls` says)")
    outer_wall: bool | None = Field(None, description="a rigid wall beyond the last column (default false, or as "
                                                      "`walls` says)")
    walls: list[Literal["bottom", "top", "left", "right", "outer", "face"]] | None = Field(
        None, description="the rigid walls that close the medium, instead of channel_walls/outer_wall: the channel "
                          "walls (bottom/top for left/right growth, left/right for up/down), outer, face")
    undamped_walls: list[Literal["bottom", "top", "left", "right", "outer", "face"]] | None = Field(
        None, description="those of the medium's walls whose contacts have no dashpot (Hertz alone: elastic walls); "
                          "the others are damped (eq. 3 with m* = m)")
    gap: float = Field(0.0, ge=0)
    granules_file: str | None = None
    radii: list[Annotated[float, Field(ge=LENGTH_MIN, le=LENGTH_MAX)]] | None = Field(
        None, description="a straight chain of touching beads instead of a hexagonal packing: their radii [m], "
                          "from the face outward (label 1 is the outermost)")
    materials: list[str] | None = Field(None, description="a chain's bead materials, from the face outward "
                                                          "(default: `material` for every bead)")

    @field_validator("labels")
    @classmethod
    def _unique_labels(cls, v):
        if isinstance(v, list):
            seen = set()
            for k, lab in enumerate(v):
                if not lab.strip():
                    raise ValueError(f"labels.{k} is empty")
                if lab in seen:
                    raise ValueError(f"labels.{k} = {lab!r} repeats an earlier label: labels must be unique in a medium")
                seen.add(lab)
        return v

    @model_validator(mode="after")
    def _shape(self):
        if self.radii is not None:
            for key in ("granules_file", "columns", "radius"):
                if getattr(self, key) is not None:
                    raise ValueError(f"{key}: a chain (radii) takes neither granules_file nor columns and radius")
            if self.materials is not None and len(self.materials) != len(self.radii):
                raise ValueError(f"materials: {len(self.materials)} given for {len(self.radii)} beads (radii)")
            self._check_growth("a chain")
            self._check_walls(("face", "outer"), "a chain")
            self._check_undamped(tuple(self.walls or ()))
            return self
        if self.materials is not None:
            raise ValueError("materials: only a chain (radii) takes per-bead materials; a granules_file has a "
                             "material column")
        if self.granules_file is None:
            if self.columns is None or self.radius is None:
                raise ValueError("a medium needs either 'columns' and 'radius' (hexagonal packing) or 'granules_file'")
            self._check_growth("a hexagonal packing")
            vertical = self.grow in ("up", "down")
            for key in (("face_x", "center_y") if vertical else ("face_y", "center_x")):
                if getattr(self, key) is not None:
                    raise ValueError(f"{key}: not used by a medium growing {self.grow or self.side}; "
                                     + ("give face_y and center_x" if vertical else "give face_x and center_y"))
            if self.walls is not None:
                lo, hi = ("left", "right") if vertical else ("bottom", "top")
                given = {"channel_walls": (lo, hi), "outer_wall": ("outer",)}
                for key, names in given.items():
                    if getattr(self, key) is not None and getattr(self, key) != all(w in self.walls for w in names):
                        raise ValueError(f"walls = {self.walls} contradicts {key} = "
                                         f"{str(getattr(self, key)).lower()}: give one of them")
                self._check_walls((lo, hi, "outer", "face"), f"a medium growing {self.grow or self.side}")
                if len(set(self.walls)) != len(self.walls):
                    raise ValueError(f"walls: {self.walls} names a wall twice")
            else:  # the switches' defaults, visible in the resolved scenario (set without re-validation)
                if self.channel_walls is None:
                    self.__dict__["channel_walls"] = True
                if self.outer_wall is None:
                    self.__dict__["outer_wall"] = False
            self._check_undamped(self.wall_names())
        else:
            if self.undamped_walls is not None:
                raise ValueError("undamped_walls: a medium from granules_file has no walls of its own (give its "
                                 "[[walls]] damped = false)")
            for key in ("grow", "face_y", "center_x", "walls"):
                if getattr(self, key) is not None:
                    raise ValueError(f"{key}: a medium from granules_file takes its geometry from the file "
                                     "(add walls with [[walls]])")
        return self

    def _check_growth(self, what: str) -> None:
        """A medium away from the solid needs a growth direction; one beside it grows away from it."""
        if self.side == "none" and self.grow is None:
            raise ValueError(f"grow: {what} away from the solid (side = 'none') needs a growth direction: left, "
                             "right, up or down")
        if self.side != "none" and self.grow not in (None, self.side):
            raise ValueError(f"grow = {self.grow!r}: a medium on the {self.side} of the solid grows to the "
                             f"{self.side} (use side = 'none' for a medium elsewhere)")

    def _check_walls(self, allowed: tuple[str, ...], what: str) -> None:
        """`walls` names only walls of this medium, and a face wall only away from the solid."""
        for w in self.walls or []:
            if w not in allowed:
                raise ValueError(f"walls: {w!r} is not a wall of {what}; choose from {list(allowed)}")
        if self.walls is not None and "face" in self.walls and self.side != "none":
            raise ValueError("walls: 'face' would lie on the solid's face; only a medium with side = 'none' has a "
                             "face wall")

    def _check_undamped(self, walls: tuple[str, ...]) -> None:
        """`undamped_walls` names only walls the medium has, each once."""
        for w in self.undamped_walls or []:
            if w not in walls:
                raise ValueError(f"undamped_walls: {w!r} is not one of the medium's walls {list(walls)}")
        if self.undamped_walls is not None and len(set(self.undamped_walls)) != len(self.undamped_walls):
            raise ValueError(f"undamped_walls: {self.undamped_walls} names a wall twice")

    def wall_names(self) -> tuple[str, ...]:
        """The walls of a hexagonal packing: `walls`, or the channel and outer walls' switches."""
        if self.walls is not None:
            return tuple(self.walls)
        lo, hi = ("left", "right") if self.grow in ("up", "down") else ("bottom", "top")
        return ((lo, hi) if self.channel_walls else ()) + (("outer",) if self.outer_wall else ())


class WallMotionSpec(_Strict):
    """A shaker: the wall moves along its normal (into the granular side positive) as
    s = amplitude r sin(2 pi frequency (t - t0) + phase), r the drives' (1 - cos)/2 ramp."""

    amplitude: float = Field(description="[m]")
    frequency: float = Field(gt=0, description="[Hz]")
    phase: float = Field(0.0, description="[rad] at t0")
    ramp_cycles: float = Field(0.0, ge=0)
    t0: float = 0.0
    duration: float | None = Field(None, description="default: to the end of the run")

    @field_validator("t0", "duration", mode="before")
    @classmethod
    def _parse(cls, v):
        return None if v is None else _time(v)

    @model_validator(mode="after")
    def _starts_at_rest(self):
        if self.amplitude == 0:
            raise ValueError("amplitude: a moving wall needs a non-zero amplitude [m]")
        if self.duration is not None and not self.duration > 0:
            raise ValueError(f"duration: must be a positive time, got {self.duration!r}")
        if self.t0 < 0:
            raise ValueError(f"t0: must be >= 0, got {self.t0!r}")
        if self.t0 == 0 and self.ramp_cycles == 0 and math.sin(self.phase) != 0:
            raise ValueError("phase: the wall must start where it rests (the static equilibrium and the first output "
                             "are there): use phase = 0, ramp_cycles > 0 or t0 > 0")
        return self

    def drive(self):
        from ..granular.loads import WallDrive

        return WallDrive(self.amplitude, self.frequency, self.t0, self.duration if self.duration is not None else math.inf,
                         self.phase, self.ramp_cycles)


class WallSpec(_Strict):
    p0: tuple[float, float]
    p1: tuple[float, float]
    normal: tuple[float, float]
    medium: str = ""
    name: str = ""
    motion: WallMotionSpec | None = None
    damped: bool = Field(True, description="the Tsuji dashpot of eq. (3) at its contacts, with m* = m; false: Hertz "
                                           "alone (an elastic wall, no dissipation at its contacts)")

    @model_validator(mode="after")
    def _nondegenerate(self):
        if math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1]) <= 0:
            raise ValueError(f"wall has zero length: p0 = p1 = {self.p0}")
        if math.hypot(*self.normal) <= 0:
            raise ValueError("wall normal must be non-zero")
        return self


class ExcitationSpec(_Strict):
    granule: str = Field(min_length=1)
    kind: Literal[tuple(KINDS)] = "half_sine"  # the kinds of `granular.loads`
    shock: Literal["weak", "moderate", "strong"] | None = None
    fmax: float | None = None
    tau: float = PAPER_TAU
    t0: float = 0.0
    amplitude: float | None = None
    frequency: float | None = Field(None, gt=0, description="burst, harmonic [Hz]")
    cycles: float | None = Field(None, gt=0)
    phase: float = Field(0.0, description="harmonic: phase at t0 [rad]")
    ramp_cycles: float = Field(0.0, ge=0, description="harmonic, chirp: cycles of the smooth ramp-up (at f0 for a chirp)")
    duration: float | None = Field(None, description="harmonic (default: to the end of the run), chirp: how long it drives [s]")
    f0: float | None = Field(None, gt=0, description="chirp: start frequency [Hz]")
    f1: float | None = Field(None, gt=0, description="chirp: end frequency [Hz]")
    mode: Literal["linear", "log"] = Field("linear", description="chirp: linear or geometric (log) sweep")
    value: float | None = None
    file: str | None = None
    direction: Union[Literal["toward_solid", "away_from_solid"], tuple[float, float]] = "toward_solid"

    @field_validator("tau", "t0", "duration", mode="before")
    @classmethod
    def _parse(cls, v):
        return None if v is None else _time(v)

    @field_validator("duration")
    @classmethod
    def _duration_pos(cls, v):
        if v is not None and not v > 0:
            raise ValueError(f"must be a positive time, got {v!r}")
        return v

    @field_validator("tau")
    @classmethod
    def _tau_pos(cls, v):
        if not v > 0:
            raise ValueError(f"must be a positive time, got {v!r}")
        return v

    @field_validator("direction")
    @classmethod
    def _dir(cls, v):
        if isinstance(v, tuple) and math.hypot(*v) == 0:
            raise ValueError("direction vector must be non-zero")
        return v

    @model_validator(mode="after")
    def _needs(self):
        lacks = KINDS[self.kind].lacks(lambda name: getattr(self, name))
        if lacks:
            raise ValueError(lacks)
        return self

    def history(self, base: Path | None = None) -> LoadHistory:
        """The load's history (`granular.loads`, by its kind); a table is read from `file`,
        relative to `base`."""
        def read_table():
            from .tables import read_load_table

            path = Path(self.file)
            return read_load_table(base / path if base is not None and not path.is_absolute() else path)

        return KINDS[self.kind].from_fields(lambda name: getattr(self, name), read_table)


class InitialVelocitySpec(_Strict):
    granule: str
    v: tuple[float, float] = (0.0, 0.0)
    omega: float = 0.0


# the largest |component| of gravity a scenario may give [m/s^2]: 10^4 g, beyond any centrifuge
GRAVITY_MAX = 1e5


class Scenario(_Strict):
    name: str = "scenario"
    description: str = ""
    simulation: SimulationSpec = SimulationSpec()
    contact: ContactSpec = ContactSpec()
    materials: dict[str, MaterialSpec] = Field(default_factory=lambda: {"steel": MaterialSpec(E=200e9, rho=7850.0, nu=0.3)})
    solid: SolidSpec | None = SolidSpec()
    media: list[MediumSpec] = Field(min_length=1)
    walls: list[WallSpec] = Field(default_factory=list)
    excitations: list[ExcitationSpec] = Field(default_factory=list)
    initial_velocities: list[InitialVelocitySpec] = Field(default_factory=list)
    gravity: tuple[Annotated[float, Field(ge=-GRAVITY_MAX, le=GRAVITY_MAX)], Annotated[float, Field(ge=-GRAVITY_MAX, le=GRAVITY_MAX)]] = Field(
        (0.0, 0.0), description="the acceleration of gravity in the granular plane (x, y) [m/s^2], on every granule and "
        "on the solid, e.g. [0, -9.81] (default: none)")
    _base: Path | None = PrivateAttr(None)  # directory that relative file paths refer to

    @property
    def base(self) -> Path | None:
        return self._base

    @model_validator(mode="after")
    def _references(self):
        names = [m.name for m in self.media]
        if len(set(names)) != len(names):
            raise ValueError(f"media names must be unique, got {names}")
        for k, m in enumerate(self.media):
            if m.material not in self.materials:
                raise ValueError(f"media.{k}.material: unknown material {m.material!r}; defined: {sorted(self.materials)}")
            for j, name in enumerate(m.materials or []):
                if name not in self.materials:
                    raise ValueError(f"media.{k}.materials.{j}: unknown material {name!r}; defined: {sorted(self.materials)}")
        if self.solid is not None and self.solid.material not in self.materials:
            raise ValueError(f"solid.material: unknown material {self.solid.material!r}; defined: {sorted(self.materials)}")
        for k, w in enumerate(self.walls):
            if w.medium and w.medium not in names:
                raise ValueError(f"walls.{k}.medium: unknown medium {w.medium!r}; defined: {names}")
        return self


def present_solid(sc: Scenario):
    """The scenario's [solid] table, or None for `solid.kind = "none"` (granules, walls and loads only)."""
    return None if sc.solid is None or sc.solid.kind == "none" else sc.solid
