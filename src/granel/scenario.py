"""TOML scenario files -> validated objects (pydantic), and objects -> the physical system.

Every error names the offending field and value. Validation happens in two layers:
field-level (types, signs, ranges, unknown keys) by pydantic, and whole-scenario checks
(overlapping granules, unknown labels, a step above the safe bound) in `check_scenario`.
"""

from __future__ import annotations

import copy
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
import tomli_w
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator, model_validator

from .excitation import PAPER_TAU, SHOCK_LEVELS, LoadHistory, constant_force, half_sine, harmonic_burst, read_force_csv
from .materials import Material
from .units import parse_time

# Hertz impact: contact duration = HERTZ_DURATION * delta_max / v = 2 (2/5) B(2/5, 1/2) delta_max / v
HERTZ_DURATION = 0.8 * math.gamma(0.4) * math.sqrt(math.pi) / math.gamma(0.9)


class ScenarioError(ValueError):
    """An invalid scenario; the message names the field and the value."""


def _time(v):
    try:
        return parse_time(v)
    except ValueError as e:
        raise ValueError(str(e)) from None


Seconds = Annotated[float, Field(gt=0)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


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

    @field_validator("duration", "dt", "output_every", "checkpoint_every", "solid_output_every", mode="before")
    @classmethod
    def _parse(cls, v):
        return _time(v)

    @field_validator("duration", "dt", "output_every")
    @classmethod
    def _positive(cls, v):
        if not v > 0 or not math.isfinite(v):
            raise ValueError(f"must be a positive time, got {v!r}")
        return v


class ContactSpec(_Strict):
    mu: float = Field(0.099, ge=0, le=10)
    alpha_n: float = Field(6.313e-3, ge=0)
    k_s: float = Field(100.0, gt=0)


class MaterialSpec(_Strict):
    E: float = Field(gt=0, description="Young's modulus [Pa]")
    rho: float = Field(gt=0, description="density [kg/m^3]")
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


class SolidSpec(_Strict):
    kind: Literal["plate", "beam", "rigid"] = "plate"
    material: str = "steel"
    x0: float = 0.0
    y0: float = 0.0
    width: float = Field(0.01, gt=0)
    length: float = Field(0.1, gt=0)
    thickness: float = Field(0.001, gt=0)
    beam_elements: int = Field(40, ge=2)
    mesh: PlateMeshSpec = PlateMeshSpec()
    clamped: tuple[bool, bool] = (True, True)


class MediumSpec(_Strict):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-]+$")
    side: Literal["left", "right", "none"] = "left"
    radius: float | None = Field(None, gt=0)
    material: str = "steel"
    columns: list[Annotated[int, Field(ge=1)]] | None = None
    center_y: float | None = None
    labels: Union[Literal["numeric", "alpha"], list[str]] = "numeric"
    channel_walls: bool = True
    outer_wall: bool = False
    gap: float = Field(0.0, ge=0)
    granules_file: str | None = None

    @model_validator(mode="after")
    def _shape(self):
        if self.granules_file is None:
            if self.columns is None or self.radius is None:
                raise ValueError("a medium needs either 'columns' and 'radius' (hexagonal packing) or 'granules_file'")
            if self.side == "none":
                raise ValueError("a hexagonal packing needs side = 'left' or 'right' of the solid")
        return self


class WallSpec(_Strict):
    p0: tuple[float, float]
    p1: tuple[float, float]
    normal: tuple[float, float]
    medium: str = ""
    name: str = ""

    @model_validator(mode="after")
    def _nondegenerate(self):
        if math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1]) <= 0:
            raise ValueError(f"wall has zero length: p0 = p1 = {self.p0}")
        if math.hypot(*self.normal) <= 0:
            raise ValueError("wall normal must be non-zero")
        return self


class ExcitationSpec(_Strict):
    granule: str = Field(min_length=1)
    kind: Literal["half_sine", "burst", "table", "constant"] = "half_sine"
    shock: Literal["weak", "moderate", "strong"] | None = None
    fmax: float | None = None
    tau: float = PAPER_TAU
    t0: float = 0.0
    amplitude: float | None = None
    frequency: float | None = Field(None, gt=0)
    cycles: float | None = Field(None, gt=0)
    value: float | None = None
    file: str | None = None
    direction: Union[Literal["toward_solid", "away_from_solid"], tuple[float, float]] = "toward_solid"

    @field_validator("tau", "t0", mode="before")
    @classmethod
    def _parse(cls, v):
        return _time(v)

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
        if self.kind == "half_sine":
            if self.fmax is None and self.shock is None:
                raise ValueError("a half_sine needs 'fmax' [N] or 'shock' (weak | moderate | strong)")
        elif self.kind == "burst":
            for f in ("amplitude", "frequency", "cycles"):
                if getattr(self, f) is None:
                    raise ValueError(f"a burst needs '{f}'")
        elif self.kind == "table":
            if self.file is None:
                raise ValueError("a table excitation needs 'file' (CSV of time,force)")
        elif self.kind == "constant" and self.value is None:
            raise ValueError("a constant excitation needs 'value' [N]")
        return self

    def peak_force(self) -> float:
        if self.kind == "half_sine":
            return abs(self.fmax if self.fmax is not None else SHOCK_LEVELS[self.shock])
        if self.kind == "burst":
            return abs(self.amplitude)
        if self.kind == "constant":
            return abs(self.value)
        return float("nan")

    def history(self, base: Path | None = None) -> LoadHistory:
        if self.kind == "half_sine":
            fmax = self.fmax if self.fmax is not None else SHOCK_LEVELS[self.shock]
            return half_sine(fmax, self.tau, self.t0)
        if self.kind == "burst":
            return harmonic_burst(self.amplitude, self.frequency, self.cycles, self.t0)
        if self.kind == "constant":
            return constant_force(self.value)
        path = Path(self.file)
        if base is not None and not path.is_absolute():
            path = base / path
        return read_force_csv(path)


class InitialVelocitySpec(_Strict):
    granule: str
    v: tuple[float, float] = (0.0, 0.0)
    omega: float = 0.0


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
        if self.solid is not None and self.solid.material not in self.materials:
            raise ValueError(f"solid.material: unknown material {self.solid.material!r}; defined: {sorted(self.materials)}")
        for k, w in enumerate(self.walls):
            if w.medium and w.medium not in names:
                raise ValueError(f"walls.{k}.medium: unknown medium {w.medium!r}; defined: {names}")
        return self


def _format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(scenario)"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown field"
        inp = e.get("input")
        shown = repr(inp) if not isinstance(inp, dict) else "{...}"
        if len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"{loc} = {shown}: {msg}")
    return "invalid scenario:\n  " + "\n  ".join(lines)


BUILTIN = ("paper",)


def builtin_names() -> list[str]:
    return [p.name[:-5] for p in resources.files("granel.scenarios").iterdir() if p.name.endswith(".toml")]


def load_raw(source: str | Path) -> tuple[dict, Path | None]:
    """TOML text of a built-in name or a file -> (dict, base directory for relative paths)."""
    src = str(source)
    if src in builtin_names():
        text = resources.files("granel.scenarios").joinpath(f"{src}.toml").read_text()
        return tomllib.loads(text), None
    path = Path(src)
    if not path.exists():
        raise ScenarioError(f"scenario {src!r}: no such file and not a built-in ({', '.join(builtin_names())})")
    try:
        return tomllib.loads(path.read_text()), path.parent
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: not valid TOML: {e}") from None


def _coerce(text: str):
    """A CLI override value: TOML literal if it parses, else a plain string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `a.b.c=value` overrides (list indices as numbers: media.1.radius=0.006)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise ScenarioError(f"override {item!r}: expected key=value, e.g. contact.mu=0.2")
        key, val = item.split("=", 1)
        parts = key.strip().split(".")
        node = raw
        for p in parts[:-1]:
            if isinstance(node, list):
                try:
                    node = node[int(p)]
                except (ValueError, IndexError):
                    raise ScenarioError(f"override {key!r}: no list item {p!r}") from None
            else:
                node = node.setdefault(p, {})
        last = parts[-1]
        if isinstance(node, list):
            try:
                node[int(last)] = _coerce(val)
            except (ValueError, IndexError):
                raise ScenarioError(f"override {key!r}: no list item {last!r}") from None
        else:
            node[last] = _coerce(val.strip())
    return raw


def validate(raw: dict, base: Path | None = None) -> Scenario:
    """Field validation, then whole-scenario checks; raises ScenarioError naming the field."""
    try:
        sc = Scenario.model_validate(raw)
    except ValidationError as e:
        raise ScenarioError(_format_validation_error(e)) from None
    check_scenario(sc, base)
    return sc


def load(source: str | Path, overrides: list[str] | None = None) -> Scenario:
    raw, base = load_raw(source)
    raw = apply_overrides(raw, overrides or [])
    sc = validate(raw, base)
    sc._base = base
    return sc


def to_toml(sc: Scenario) -> str:
    data = sc.model_dump(mode="json", exclude_none=True)
    return tomli_w.dumps(data)


# ---------------------------------------------------------------- building the system


def build_media(sc: Scenario, base: Path | None = None):
    from .granular.packing import hexagonal_columns, medium_from_table, read_granules_csv

    solid = sc.solid
    media = []
    for k, m in enumerate(sc.media):
        mat = sc.materials[m.material].material()
        if m.granules_file:
            path = Path(m.granules_file)
            if base is not None and not path.is_absolute():
                path = base / path
            try:
                rows = read_granules_csv(path)
                med = medium_from_table(m.name, rows, mat, m.side, {k: v.material() for k, v in sc.materials.items()})
            except (OSError, ValueError, KeyError) as e:
                raise ScenarioError(f"media.{k}.granules_file = {m.granules_file!r}: {e}") from None
            if np.any(med.radius <= 0):
                raise ScenarioError(f"media.{k}.granules_file = {m.granules_file!r}: radius must be positive")
        else:
            if solid is not None:
                face = solid.x0 if m.side == "left" else solid.x0 + solid.width
                cy = m.center_y if m.center_y is not None else solid.y0 + 0.5 * solid.length
            else:
                face = 0.0
                cy = m.center_y if m.center_y is not None else 0.0
            try:
                med = hexagonal_columns(m.name, m.columns, m.radius, mat, m.side, face, cy, m.labels,
                                        m.channel_walls, m.outer_wall, m.gap)
            except ValueError as e:
                raise ScenarioError(f"media.{k}: {e}") from None
        media.append(med)
    return media


def solid_contacts_for(sc: Scenario, media) -> list:
    """Contact points of the solid: the granules of column 0 of each medium beside the solid
    whose centre lies within the solid's length, at the face point nearest to the centre."""
    from .granular.system import SolidContact

    if sc.solid is None:
        return []
    s = sc.solid
    out, offset = [], 0
    for med in media:
        if med.side in ("left", "right"):
            face = s.x0 if med.side == "left" else s.x0 + s.width
            nrm = (1.0, 0.0) if med.side == "left" else (-1.0, 0.0)
            for g in range(med.n):
                x, y = med.pos[g]
                R = med.radius[g]
                dist = (face - x) * nrm[0]
                if s.y0 < y < s.y0 + s.length and dist < R * (1 + 1e-9) + 1e-12 and dist > 0:
                    out.append(SolidContact(offset + g, (face, float(y)), nrm, f"{med.name}:{med.labels[g]}"))
        offset += med.n
    return out


def excitation_direction(spec: ExcitationSpec, side: str) -> tuple[float, float]:
    if isinstance(spec.direction, tuple):
        return spec.direction
    toward = (1.0, 0.0) if side == "left" else (-1.0, 0.0)
    if side not in ("left", "right"):
        raise ScenarioError(f"excitation on {spec.granule}: direction 'toward_solid' needs a medium beside the solid; give a vector")
    return toward if spec.direction == "toward_solid" else (-toward[0], -toward[1])


def build_granular(sc: Scenario, base: Path | None = None):
    """Scenario -> GranularSystem (with solid contact points at rest) and initial state."""
    from .granular.packing import Wall
    from .granular.system import ContactLaw, Excitation, build_system, initial_state

    media = build_media(sc, base)
    law = ContactLaw(sc.contact.mu, sc.contact.alpha_n, sc.contact.k_s)
    labels = [f"{m.name}:{lab}" for m in media for lab in m.labels]
    side_of = {f"{m.name}:{lab}": m.side for m in media for lab in m.labels}
    exc = []
    for k, e in enumerate(sc.excitations):
        if e.granule not in labels:
            raise ScenarioError(f"excitations.{k}.granule = {e.granule!r}: no such granule (e.g. {labels[0]!r})")
        try:
            hist = e.history(base)
        except (OSError, ValueError) as err:
            raise ScenarioError(f"excitations.{k}.file = {e.file!r}: {err}") from None
        exc.append(Excitation(labels.index(e.granule), excitation_direction(e, side_of[e.granule]), hist))
    walls = [Wall(w.p0, w.p1, w.normal, w.medium, w.name) for w in sc.walls]
    system = build_system(media, law, solid_contacts_for(sc, media), exc, walls)
    vel = np.zeros((system.n, 2))
    om = np.zeros(system.n)
    for k, iv in enumerate(sc.initial_velocities):
        if iv.granule not in labels:
            raise ScenarioError(f"initial_velocities.{k}.granule = {iv.granule!r}: no such granule")
        g = labels.index(iv.granule)
        vel[g] = iv.v
        om[g] = iv.omega
    return system, initial_state(system, vel, om), media


def safe_time_step(system, excitations, init_speed: float = 0.0) -> float:
    """An upper bound for the RK4 step: 1/20 of the shortest Hertz collision time expected
    (granule pairs of each size and granule-wall impacts at the largest speed an excitation
    can impart, impulse / mass), and 1/10 of the shortest pulse duration."""
    from .materials import effective_modulus

    bounds = []
    speed = init_speed
    for e in excitations:
        m = system.mass[e.granule]
        J = e.history.impulse()
        if math.isfinite(J) and J > 0:
            speed = max(speed, J / m)
        if e.history.kind == "half_sine":
            bounds.append(e.history.params[1] / 10.0)
        elif e.history.kind == "burst":
            bounds.append(1.0 / (e.history.params[1] * 20.0))
    if speed > 0 and system.n:
        kinds = np.column_stack([system.radius, system.E, system.nu, system.mass])
        for g in np.unique(kinds, axis=0, return_index=True)[1]:
            R, m = system.radius[g], system.mass[g]
            E2 = effective_modulus(system.E[g], system.nu[g], system.E[g], system.nu[g])
            Ew = effective_modulus(system.E[g], system.nu[g])
            for (Es, Rs, ms) in ((E2, R / 2, m / 2), (Ew, R, m)):
                A = 4.0 / 3.0 * Es * math.sqrt(Rs)
                dmax = (5.0 * ms * speed**2 / (4.0 * A)) ** 0.4
                bounds.append(HERTZ_DURATION * dmax / speed / 20.0)
    return min(bounds) if bounds else math.inf


def check_scenario(sc: Scenario, base: Path | None = None) -> None:
    """Whole-scenario checks that need the built geometry."""
    system, state, media = build_granular(sc, base)
    # overlapping granules
    from scipy.spatial import cKDTree

    pos, R = system.pos0, system.radius
    if system.n > 1:
        pairs = cKDTree(pos).query_pairs(2 * R.max(), output_type="ndarray")
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            over = R[i] + R[j] - np.hypot(*(pos[j] - pos[i]).T)
            bad = over > 1e-9 * np.minimum(R[i], R[j])
            if bad.any():
                k = int(np.argmax(over))
                raise ScenarioError(
                    f"media: granules {system.labels[i[k]]} and {system.labels[j[k]]} overlap by {over[k]:.3e} m "
                    "(initial states must be free of compression)"
                )
    if sc.solid is not None:
        s = sc.solid
        inside = (pos[:, 0] + R > s.x0 + 1e-12) & (pos[:, 0] - R < s.x0 + s.width - 1e-12) & \
                 (pos[:, 1] > s.y0) & (pos[:, 1] < s.y0 + s.length)
        if inside.any():
            g = int(np.flatnonzero(inside)[0])
            raise ScenarioError(f"media: granule {system.labels[g]} overlaps the solid at x = {pos[g, 0]:.4g} m")
    speed = max((math.hypot(*iv.v) for iv in sc.initial_velocities), default=0.0)
    bound = safe_time_step(system, system.excitations, speed)
    dt = sc.simulation.dt
    if dt > bound:
        raise ScenarioError(
            f"simulation.dt = {dt:.3e} s: larger than the safe bound {bound:.3e} s "
            "(1/20 of the shortest expected Hertz collision, 1/10 of the pulse)"
        )
    if sc.simulation.output_every < dt:
        raise ScenarioError(f"simulation.output_every = {sc.simulation.output_every:.3e} s: shorter than dt = {dt:.3e} s")
