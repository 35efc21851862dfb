"""The model a result carries (`ResultModel`): what figures, movies, exports and analysis need of
the granular system and the solid, written beside the trajectory by `io.run_result.trajectory_spec`,
so that nothing downstream runs the scenario builder again.

Granules, walls and solid contacts are variables on the result's own `granule`, `wall` and
`contact` dimensions; the solid is its recipe (JSON of `solid.recipe.SolidRecipe`, from which
`solid.recipe.build_solid_model` builds it again), its mesh, and the SHA-256 of its M and K (the
mode cache names its entries by the first 20 characters). docs/architecture.md, "What a result
carries", lists the names. `read_record` is the one reader; a result of an earlier granel has no
record, and `run.load_result` adds one from its scenario."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from ..guard.fingerprints import sparse_digest
from .results import RECORD_DIMS, ResultFileError, wall_names

RECORD_VERSION = 2  # the `model_record` attribute: raise when the record's layout changes (2: directions, strikers)
DRIVE_PARAMS = 6  # `granular.loads.WallDrive.params`: amplitude, frequency, t0, duration, phase, ramp cycles
LOAD_PARAMS = 8  # `granular.loads.LOAD_PARAMS`: a load history's parameters, zero-padded
# record variables a result of an earlier granel may lack, read with their default (walls damped)
OPTIONAL = ("wall_damped",)


@dataclass(frozen=True)
class WallRecord:
    """A rigid wall: its label in the result, ends p0 -> p1, unit normal into the granules, the
    medium it holds ("" for every medium), for a shaker `WallDrive.params` (zeros at rest), and
    whether its contacts are damped (a result without `wall_damped` predates undamped walls)."""

    name: str
    p0: tuple[float, float]
    p1: tuple[float, float]
    normal: tuple[float, float]
    medium: str
    drive: tuple[float, ...]
    damped: bool = True


@dataclass(frozen=True)
class ContactRecord:
    """A granule-solid contact: its name, granule index, rest position, unit normal n_ik (granule
    -> solid) and the solid's reduced DOFs of its x, y and rotation (-1: none)."""

    name: str
    granule: int
    position: tuple[float, float]
    normal: tuple[float, float]
    dofs: tuple[int, int, int]


@dataclass(frozen=True)
class LoadRecord:
    """An applied load: its granule index, unit direction, history kind (`granular.loads`) with
    its parameters (zero-padded to LOAD_PARAMS), for a table its times and values, and how its
    direction was given (+1 toward the solid, -1 away from it, 0 a vector)."""

    granule: int
    direction: tuple[float, float]
    kind: str
    params: tuple[float, ...]
    times: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    toward: int = 0


@dataclass(frozen=True)
class ResultModel:
    """The granules (labels, media, built centres, radius, mass, moment of inertia, E, nu), the
    contact law of eqs. (2)-(5) and the neighbour skin, the walls, the solid contacts, and the
    solid: kind, reduced DOFs, recipe (JSON), digest of M and K, mesh nodes and elements (None for
    a rigid solid), the natural frequencies of the modal coordinates (the result's `mode_omega`;
    None without), the loads, each granule's unit vector toward the solid (NaN for a medium away
    from it), the granules given an initial motion (in the scenario's order) and the acceleration of
    gravity [m/s^2] (a result without `gravity` predates it: none)."""

    labels: tuple[str, ...]
    media: tuple[str, ...]
    medium_index: np.ndarray
    position0: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    E: np.ndarray
    nu: np.ndarray
    mu: float
    alpha_n: float
    k_s: float
    skin: float
    walls: tuple[WallRecord, ...]
    contacts: tuple[ContactRecord, ...]
    solid_kind: str
    solid_dofs: int
    solid_recipe: str
    solid_digest: str
    nodes: np.ndarray | None = None
    elements: np.ndarray | None = None
    mode_omega: np.ndarray | None = None
    loads: tuple[LoadRecord, ...] = ()
    toward_solid: np.ndarray | None = None
    strikers: tuple[int, ...] = ()
    gravity: tuple[float, float] = (0.0, 0.0)

    @property
    def n(self) -> int:
        return len(self.labels)


def model_record(system, solid) -> ResultModel:
    """The record of a run's `granular.system.GranularSystem` and `solid.base.SolidModel`."""
    if [c.name for c in system.solid_contacts] != [c.name for c in solid.contacts]:
        raise ValueError("the granular system's solid contacts and the solid's contact points differ")
    walls = tuple(WallRecord(name=label, p0=_pair(w.p0), p1=_pair(w.p1), normal=_pair(w.normal), medium=w.medium,
                             drive=tuple(float(x) for x in w.drive.params()) if w.drive is not None
                             else (0.0,) * DRIVE_PARAMS, damped=bool(w.damped))
                  for label, w in zip(wall_names(system), system.walls))
    contacts = tuple(ContactRecord(p.name, int(c.granule), _pair(c.point), _pair(c.normal), (p.dof_x, p.dof_y, p.dof_rotation))
                     for c, p in zip(system.solid_contacts, solid.contacts))
    recipe = solid.recipe.to_json() if getattr(solid, "recipe", None) is not None else ""
    loads = tuple(LoadRecord(granule=int(e.granule),
                             direction=_pair(np.asarray(e.direction, float) / np.hypot(*e.direction)),
                             kind=e.history.kind,
                             params=tuple(float(x) for x in e.history.params) + (0.0,) * (LOAD_PARAMS - len(e.history.params)),
                             times=tuple(float(x) for x in e.history.times),
                             values=tuple(float(x) for x in e.history.values), toward=int(e.toward))
                  for e in system.excitations)
    law = system.law
    return ResultModel(
        labels=tuple(system.labels), media=tuple(system.media), medium_index=np.asarray(system.medium_index, np.int64),
        position0=np.asarray(system.pos0, float).reshape(-1, 2), radius=np.asarray(system.radius, float),
        mass=np.asarray(system.mass, float), inertia=np.asarray(system.inertia, float), E=np.asarray(system.E, float),
        nu=np.asarray(system.nu, float), mu=float(law.mu), alpha_n=float(law.alpha_n), k_s=float(law.k_s),
        skin=float(system.skin), walls=walls, contacts=contacts, solid_kind=solid.kind, solid_dofs=int(solid.ndof),
        solid_recipe=recipe, solid_digest=sparse_digest((solid.M, solid.K)),
        nodes=None if solid.nodes is None else np.asarray(solid.nodes, float),
        elements=None if solid.elements is None else np.asarray(solid.elements, np.int64), loads=loads,
        toward_solid=np.asarray(system.toward_solid, float).reshape(-1, 2), strikers=tuple(int(g) for g in system.strikers),
        gravity=_pair(system.gravity))


def _pair(p) -> tuple[float, float]:
    return float(p[0]), float(p[1])


def record_entries(rec: ResultModel) -> tuple[dict, dict]:
    """(variables as `io.results.ResultSpec` holds them, attributes) of a record; the variables'
    dimensions are `io.results.RECORD_DIMS`."""
    nw, nc = len(rec.walls), len(rec.contacts)
    values = {
        "granule_radius": (rec.radius, {"units": "m"}),
        "granule_mass": (rec.mass, {"units": "kg"}),
        "granule_inertia": (rec.inertia, {"units": "kg m2", "long_name": "moment of inertia"}),
        "granule_modulus": (rec.E, {"units": "Pa", "long_name": "Young's modulus"}),
        "granule_poisson": (rec.nu, {"long_name": "Poisson's ratio"}),
        "granule_position0": (rec.position0, {"units": "m", "long_name": "centre as built (before any static equilibrium)"}),
        "wall_p0": (np.array([w.p0 for w in rec.walls], float).reshape(nw, 2), {"units": "m"}),
        "wall_p1": (np.array([w.p1 for w in rec.walls], float).reshape(nw, 2), {"units": "m"}),
        "wall_normal": (np.array([w.normal for w in rec.walls], float).reshape(nw, 2),
                        {"long_name": "unit normal into the granules"}),
        "wall_medium": (np.array([w.medium for w in rec.walls], dtype=object),
                        {"long_name": "the medium it holds (empty: every medium)"}),
        "wall_drive": (np.array([w.drive for w in rec.walls], float).reshape(nw, DRIVE_PARAMS),
                       {"long_name": "shaker motion: amplitude, frequency, t0, duration, phase, ramp cycles (zeros: at rest)"}),
        "wall_damped": (np.array([w.damped for w in rec.walls], np.int8),
                        {"long_name": "1: its contacts have the dashpot of eq. (3) (m* = m); 0: Hertz alone"}),
        "contact_granule": (np.array([c.granule for c in rec.contacts], np.int64), {}),
        "contact_position": (np.array([c.position for c in rec.contacts], float).reshape(nc, 2),
                             {"units": "m", "long_name": "rest position on the solid"}),
        "contact_normal": (np.array([c.normal for c in rec.contacts], float).reshape(nc, 2),
                           {"long_name": "unit normal n_ik, granule -> solid"}),
        "contact_dofs": (np.array([c.dofs for c in rec.contacts], np.int64).reshape(nc, 3),
                         {"long_name": "the solid's reduced DOFs of its x, y and rotation (-1: none)"}),
    }
    nl = len(rec.loads)
    values.update({
        "load_granule": (np.array([e.granule for e in rec.loads], np.int64), {}),
        "load_direction": (np.array([e.direction for e in rec.loads], float).reshape(nl, 2), {"long_name": "unit direction"}),
        "load_kind": (np.array([e.kind for e in rec.loads], dtype=object), {"long_name": "history kind (granular.loads)"}),
        "load_params": (np.array([e.params for e in rec.loads], float).reshape(nl, LOAD_PARAMS),
                        {"long_name": "history parameters (granular.loads), zero-padded"}),
        "load_table_size": (np.array([len(e.times) for e in rec.loads], np.int64), {"long_name": "points of its table"}),
        "load_table_time": (np.array([t for e in rec.loads for t in e.times], float), {"units": "s"}),
        "load_table_value": (np.array([v for e in rec.loads for v in e.values], float), {"units": "N"}),
        "load_toward": (np.array([e.toward for e in rec.loads], np.int8),
                        {"long_name": "the direction as given: 1 toward the solid, -1 away from it, 0 a vector"}),
        "granule_toward_solid": (np.asarray(rec.toward_solid, float).reshape(rec.n, 2),
                                 {"long_name": "unit vector toward the solid (NaN: a medium away from it)"}),
        "striker_granule": (np.array(rec.strikers, np.int64), {"long_name": "granules given an initial motion"}),
    })
    if rec.nodes is not None:
        values["solid_node_position"] = (rec.nodes, {"units": "m"})
        values["solid_element_nodes"] = (rec.elements, {"long_name": "node indices (Q8: corners, then mid-sides)"})
    data = {name: (RECORD_DIMS[name], v, a) for name, (v, a) in values.items()}
    attrs = {"model_record": RECORD_VERSION, "model_media": json.dumps(list(rec.media)), "model_granules": rec.n,
             "model_walls": nw, "model_contacts": nc, "model_loads": nl, "contact_mu": rec.mu, "contact_alpha_n": rec.alpha_n,
             "contact_k_s": rec.k_s, "granular_skin": rec.skin, "solid_kind": rec.solid_kind,
             "solid_dofs": rec.solid_dofs, "solid_elements": 0 if rec.elements is None else len(rec.elements),
             "solid_recipe": rec.solid_recipe, "solid_matrices_sha256": rec.solid_digest,
             "gravity": [float(g) for g in rec.gravity]}
    return data, attrs


def has_record(ds) -> bool:
    """Whether `ds` carries a model record of this granel's layout (an older one is rebuilt from
    its scenario by `run.with_model_record`, like a result without one)."""
    return "model_record" in ds.attrs and str(ds.attrs["model_record"]) not in OLDER_RECORDS


OLDER_RECORDS = ("1",)  # record versions of earlier granels, which lack fields this one reads


def with_record(ds, rec: ResultModel):
    """The xarray Dataset `ds` with the record's variables and attributes added."""
    data, attrs = record_entries(rec)
    out = ds.assign({name: (dims, values, a) for name, (dims, values, a) in data.items()})
    out.attrs.update(attrs)
    return out


def read_record(ds, name="result") -> ResultModel:
    """The model record of a result Dataset. ResultFileError (code 2) naming `name` for a result
    without one (a result of an earlier granel: `run.load_result` adds it) or with a damaged one."""
    def bad(why):
        return ResultFileError(f"{name}: damaged result (its model record: {why})", 2)

    if "model_record" not in ds.attrs or str(ds.attrs["model_record"]) in OLDER_RECORDS:
        raise ResultFileError(f"{name}: no model record (a result of granel before it stored its model); read it with "
                              "granel.run.load_result, which builds the record from its scenario", 2)
    attrs = ds.attrs
    if str(attrs["model_record"]) != str(RECORD_VERSION):
        raise bad(f"version {attrs['model_record']}, this granel reads {RECORD_VERSION}")
    mesh = ("solid_node_position", "solid_element_nodes")  # a rigid solid has none
    missing = [v for v in RECORD_DIMS if v not in ds.variables and v not in OPTIONAL
               and (v not in mesh or any(m in ds.variables for m in mesh))]
    if missing:
        raise bad(f"no {', '.join(missing)}")
    for v in RECORD_DIMS:
        if v not in ds.variables or ds[v].dtype.kind != "f" or v == "granule_toward_solid":  # NaN: away from the solid
            continue
        values = ds[v].values
        if np.isnan(values).any() or (v not in ("wall_drive", "load_params") and not np.isfinite(values).all()):  # a drive may run forever
            raise bad(f"{v} is not finite")
    try:
        media = tuple(str(m) for m in json.loads(attrs["model_media"]))
        counts = {d: int(attrs[f"model_{d}s"]) for d in ("granule", "wall", "contact", "load")}
        law = [float(attrs[k]) for k in ("contact_mu", "contact_alpha_n", "contact_k_s", "granular_skin")]
        kind, dofs = str(attrs["solid_kind"]), int(attrs["solid_dofs"])
        recipe, digest = str(attrs["solid_recipe"]), str(attrs["solid_matrices_sha256"])
    except (KeyError, TypeError, ValueError) as e:
        raise bad(f"attribute {e}") from None
    for d, count in counts.items():
        if ds.sizes.get(d, 0) != count:
            raise bad(f"{ds.sizes.get(d, 0)} {d}s stored, its model has {count}")
    for v in ("granule_radius", "granule_mass", "granule_inertia", "granule_modulus"):
        if not np.all(np.asarray(ds[v].values, float) > 0):
            raise bad(f"{v} is not positive")
    labels = tuple(str(g) for g in ds["granule"].values)
    names = [str(m) for m in ds["medium"].values]
    if any(m not in media for m in names):
        raise bad(f"a granule's medium is not one of {list(media)}")
    n = counts["granule"]
    granule = np.asarray(ds["contact_granule"].values, np.int64)
    cdofs = np.asarray(ds["contact_dofs"].values, np.int64).reshape(-1, 3)
    if np.any((granule < 0) | (granule >= n)) or np.any((cdofs < -1) | (cdofs >= dofs)):
        raise bad("a contact's granule or DOF is out of range")
    f = lambda v: np.asarray(ds[v].values, float)  # noqa: E731
    damped = np.asarray(ds["wall_damped"].values) if "wall_damped" in ds.variables else np.ones(counts["wall"], np.int8)
    if not np.isin(damped, (0, 1)).all():
        raise bad("wall_damped is neither 0 nor 1")
    walls = tuple(WallRecord(name=str(lab), p0=tuple(p0), p1=tuple(p1), normal=tuple(nrm), medium=str(m),
                             drive=tuple(float(x) for x in d), damped=bool(dmp))
                  for lab, p0, p1, nrm, m, d, dmp in zip(ds["wall"].values, f("wall_p0"), f("wall_p1"),
                                                         f("wall_normal"), ds["wall_medium"].values, f("wall_drive"),
                                                         damped))
    contacts = tuple(ContactRecord(str(lab), int(g), tuple(p), tuple(nrm), tuple(int(x) for x in d))
                     for lab, g, p, nrm, d in zip(ds["contact"].values, granule, f("contact_position"), f("contact_normal"),
                                                  cdofs))
    nodes = elements = None
    if mesh[0] in ds.variables:
        nodes, elements = f("solid_node_position"), np.asarray(ds["solid_element_nodes"].values, np.int64)
        if elements.size and (elements.min() < 0 or elements.max() >= len(nodes)):
            raise bad("an element's node is out of range")
    omega = f("mode_omega") if "mode_omega" in ds.variables else None
    loads = _read_loads(ds, n, bad)
    toward = f("granule_toward_solid")
    unit = np.isnan(toward).all(axis=1) | (np.abs(np.hypot(toward[:, 0], toward[:, 1]) - 1.0) < 1e-12)
    if not unit.all():
        raise bad("granule_toward_solid holds a vector that is neither a unit vector nor NaN")
    strikers = np.asarray(ds["striker_granule"].values, np.int64)
    if np.any((strikers < 0) | (strikers >= n)):
        raise bad("a striker's granule is out of range")
    mu, alpha_n, k_s, skin = law
    gravity = _gravity_of(attrs, bad)
    return ResultModel(labels=labels, media=media, medium_index=np.array([media.index(m) for m in names], np.int64),
                       position0=f("granule_position0"), radius=f("granule_radius"), mass=f("granule_mass"),
                       inertia=f("granule_inertia"), E=f("granule_modulus"), nu=f("granule_poisson"), mu=mu,
                       alpha_n=alpha_n, k_s=k_s, skin=skin, walls=walls, contacts=contacts, solid_kind=kind,
                       solid_dofs=dofs, solid_recipe=recipe, solid_digest=digest, nodes=nodes, elements=elements,
                       mode_omega=omega, loads=loads, toward_solid=toward, strikers=tuple(int(g) for g in strikers),
                       gravity=gravity)


def _gravity_of(attrs, bad) -> tuple[float, float]:
    """The recorded acceleration of gravity ((0, 0) for a result that predates it)."""
    if "gravity" not in attrs:
        return 0.0, 0.0
    try:
        g = np.asarray(attrs["gravity"], float).reshape(2)
    except (TypeError, ValueError):
        raise bad("attribute gravity is not two numbers") from None
    if not np.isfinite(g).all():
        raise bad("attribute gravity is not finite")
    return float(g[0]), float(g[1])


def _read_loads(ds, n: int, bad) -> tuple[LoadRecord, ...]:
    """The record's loads, checked: granules in range, tables that add up."""
    granule = np.asarray(ds["load_granule"].values, np.int64)
    sizes = np.asarray(ds["load_table_size"].values, np.int64)
    times, values = np.asarray(ds["load_table_time"].values, float), np.asarray(ds["load_table_value"].values, float)
    kinds = [str(k) for k in ds["load_kind"].values]
    toward = np.asarray(ds["load_toward"].values, np.int64)
    if np.any((granule < 0) | (granule >= n)):
        raise bad("a load's granule is out of range")
    if not np.isin(toward, (-1, 0, 1)).all():
        raise bad("load_toward is not -1, 0 or 1")
    if np.any(sizes < 0) or sizes.sum() != len(times) or len(times) != len(values):
        raise bad("the load tables' sizes do not add up")
    ends = np.cumsum(sizes)
    return tuple(LoadRecord(granule=int(g), direction=tuple(d), kind=k, params=tuple(float(x) for x in par),
                            times=tuple(times[e - s:e]), values=tuple(values[e - s:e]), toward=int(w))
                 for g, d, k, par, s, e, w in zip(granule, np.asarray(ds["load_direction"].values, float), kinds,
                                                  np.asarray(ds["load_params"].values, float), sizes, ends, toward))


def check_result_model(ds, rec: ResultModel, name) -> None:
    """ResultFileError (code 2) naming `name` unless the result's variables fit its model: the
    same granules, solid contacts and walls, and, for an elastic solid, a modal or reduced state
    of the solid's size with finite values."""
    def bad(why):
        return ResultFileError(f"{name}: damaged result ({why})", 2)

    labels = [str(g) for g in ds["granule"].values]
    if labels != list(rec.labels):
        raise bad(f"{len(labels)} granules stored, its model has {rec.n}")
    if "contact" in ds.dims and [str(c) for c in ds["contact"].values] != [c.name for c in rec.contacts]:
        raise bad(f"{ds.sizes['contact']} solid contacts stored, its model has {len(rec.contacts)}")
    if "wall" in ds.dims and ds.sizes["wall"] != len(rec.walls):
        raise bad(f"{ds.sizes['wall']} walls stored, its model has {len(rec.walls)}")
    if rec.solid_dofs and "solid_time" in ds.dims:
        if "mode" in ds.dims and ds.sizes["mode"] != rec.solid_dofs:  # all modes: q = Phi eta
            raise bad(f"{ds.sizes['mode']} modes stored for a solid of {rec.solid_dofs} degrees of freedom")
        if "dof" in ds.dims and ds.sizes["dof"] != rec.solid_dofs:
            raise bad(f"a reduced state of {ds.sizes['dof']} degrees of freedom for a solid of {rec.solid_dofs}")
        for v in ("solid_eta", "solid_eta_dot", "solid_x", "solid_v", "mode_omega"):
            if v in ds.variables and not np.all(np.isfinite(ds[v].values)):
                raise bad(f"{v} is not finite")


def read_result(path, what: str = "result file"):
    """A result file of this granel, read and checked: its structure (`results.check_result_schema`),
    its model record, and their agreement (`check_result_model`). ResultFileError naming the file
    (code 4: not readable as NetCDF; 2: not a result, damaged, or of an earlier granel, which
    `run.load_result` reads)."""
    from pathlib import Path

    from .results import check_result_schema, read_netcdf_or, with_every_granule

    path = Path(path)
    ds = read_netcdf_or(path, ResultFileError, what)
    check_result_schema(ds, path)
    check_result_model(ds, read_record(ds, path), path)
    return with_every_granule(ds)
