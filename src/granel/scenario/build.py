"""Scenario -> built objects: the granular media and system, the solid model, the solver settings
and the output schedule (`build_problem`), with the whole-scenario checks that need the built
geometry (`check_scenario`). Nothing below this layer sees the scenario."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..coupling.driver import Guards, Schedule
from ..io.trajectory import Stored
from ..coupling.settings import LARGE_SOLID_MODES, SolverSettings
from ..granular.packing import Placement, Wall, chain, hexagonal_columns, medium_from_table
from ..guard.reading import InputFileError
from ..granular.scales import auto_mode_cutoff, load_kinks, load_scales, safe_time_step
from ..granular.system import MEDIUM_TOWARD_SOLID, ContactLaw, Excitation, SolidContact, build_system, initial_state
from ..granular.contact import hertz_force, hertz_overlap, impact_overlap, tsuji_damping
from ..granular.kernels import FRICTION_MARGIN, RK4_REAL_LIMIT, SUBSTEP_RATE_STEP
from ..granular.materials import damping_coefficient, pair_coefficients, wall_coefficients
from ..problem import Problem
from ..solid.base import SolidModel
from ..solid.kinds import kind_of
from ..solid.recipe import RecipeContact, SolidRecipe, build_solid_model
from .files import to_toml
from .tables import read_granules_table
from .schema import ExcitationSpec, Scenario, ScenarioError, present_solid



def elastic_solid(sc: Scenario):
    """The scenario's [solid] table if its kind moves (`SolidKind.elastic`), else None."""
    s = present_solid(sc)
    return s if s is not None and kind_of(s.kind).elastic else None


def build_media(sc: Scenario, base: Path | None = None):
    solid = present_solid(sc)
    media = []
    for k, m in enumerate(sc.media):
        mat = sc.materials[m.material].material()
        if m.granules_file:
            path = Path(m.granules_file)
            if base is not None and not path.is_absolute():
                path = base / path
            try:
                rows = read_granules_table(path)
            except InputFileError as e:
                raise ScenarioError(f"media.{k}.granules_file: {e}", e.code) from None
            try:
                med = medium_from_table(m.name, rows, mat, m.side, {k: v.material() for k, v in sc.materials.items()})
            except (ValueError, KeyError) as e:
                raise ScenarioError(f"media.{k}.granules_file = {m.granules_file!r}: {e}") from None
            if np.any(med.radius <= 0):
                raise ScenarioError(f"media.{k}.granules_file = {m.granules_file!r}: radius must be positive")
        elif m.radii is not None:
            mats = [sc.materials[name].material() for name in (m.materials or [m.material] * len(m.radii))]
            try:
                med = chain(m.name, list(m.radii), mats, _placement(m, solid), tuple(m.walls or ()))
            except ValueError as e:
                raise ScenarioError(f"media.{k}: {e}") from None
        else:
            try:
                med = hexagonal_columns(m.name, m.columns, m.radius, mat, _placement(m, solid), m.labels, m.wall_names())
            except ValueError as e:
                raise ScenarioError(f"media.{k}: {e}") from None
        if m.undamped_walls:
            med.walls = [replace(w, damped=False) if w.name.split(":", 1)[1] in m.undamped_walls else w
                         for w in med.walls]
        media.append(med)
    return media


def _placement(m, solid) -> Placement:
    """Where a built medium starts (`granular.packing.Placement`): its face line (x, or y growing up
    or down) and the centre of its first column along it (the solid's face and mid-length beside a
    solid, else 0), its gap and growth."""
    face, center = _face_and_centre(m, solid)
    return Placement(m.side, face, center, m.gap, m.grow)


def _face_and_centre(m, solid) -> tuple[float, float]:
    if m.grow in ("up", "down"):
        return m.face_y or 0.0, m.center_x or 0.0
    if solid is not None and m.side != "none":
        face = solid.x0 if m.side == "left" else solid.x0 + solid.width
        center = m.center_y if m.center_y is not None else solid.y0 + 0.5 * solid.length
    else:
        face, center = 0.0, m.center_y if m.center_y is not None else 0.0
    return (m.face_x if m.face_x is not None else face), center


def solid_contacts_for(sc: Scenario, media) -> list:
    """Contact points of the solid: the granules of column 0 of each medium beside the solid
    (within its radius and the medium's gap of the face: those across a gap strike the solid once
    they cross it), at the face point nearest to the centre. ScenarioError naming the medium for a
    granule of column 0 level with the solid's ends or beyond them (it would face no surface: it
    would pass the solid by, or strike its corner)."""
    s = present_solid(sc)
    if s is None:
        return []
    out, offset = [], 0
    for k, med in enumerate(media):
        if med.side in ("left", "right"):
            face = s.x0 if med.side == "left" else s.x0 + s.width
            nrm = (1.0, 0.0) if med.side == "left" else (-1.0, 0.0)
            for g in range(med.n):
                x, y = med.pos[g]
                R = med.radius[g]
                dist = (face - x) * nrm[0]
                if not 0 < dist < R * (1 + 1e-9) + 1e-12 + sc.media[k].gap:
                    continue
                if not s.y0 < y < s.y0 + s.length:
                    raise ScenarioError(
                        f"media.{k}: granule {med.name}:{med.labels[g]} faces the solid at y = {y:.6g} m, level with "
                        f"its ends or beyond them (solid.y0 = {s.y0:g}, solid.y0 + length = {s.y0 + s.length:g}): "
                        f"place the medium on the solid's face (media.{k}.center_y) or lengthen it (solid.length)")
                # touching, or across the medium's gap: its Hertz force stays zero until the gap closes
                out.append(SolidContact(offset + g, (face, float(y)), nrm, f"{med.name}:{med.labels[g]}"))
        offset += med.n
    return out


def excitation_direction(spec: ExcitationSpec, side: str) -> tuple[tuple[float, float], int]:
    """(The load's direction vector, how it was given: +1 toward the solid, -1 away, 0 a vector)."""
    if isinstance(spec.direction, tuple):
        return spec.direction, 0
    if side not in MEDIUM_TOWARD_SOLID:
        raise ScenarioError(f"excitation on {spec.granule}: direction 'toward_solid' needs a medium beside the solid; give a vector")
    toward = MEDIUM_TOWARD_SOLID[side]
    return (toward, 1) if spec.direction == "toward_solid" else ((-toward[0], -toward[1]), -1)


def build_granular(sc: Scenario, base: Path | None = None):
    """Scenario -> (GranularSystem with its solid contact points at rest, initial state, media)."""
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
        except InputFileError as err:
            raise ScenarioError(f"excitations.{k}.file: {err}", err.code) from None
        except (OSError, ValueError) as err:
            raise ScenarioError(f"excitations.{k}.file = {e.file!r}: {err}") from None
        direction, toward = excitation_direction(e, side_of[e.granule])
        exc.append(Excitation(labels.index(e.granule), direction, hist, toward))
    walls = [Wall(p0=w.p0, p1=w.p1, normal=w.normal, medium=w.medium, name=w.name,
                  drive=w.motion.drive() if w.motion is not None else None, damped=w.damped)
             for w in sc.walls]
    system = build_system(media, law, solid_contacts_for(sc, media), exc, walls)
    vel = np.zeros((system.n, 2))
    om = np.zeros(system.n)
    for k, iv in enumerate(sc.initial_velocities):
        if iv.granule not in labels:
            raise ScenarioError(f"initial_velocities.{k}.granule = {iv.granule!r}: no such granule")
        g = labels.index(iv.granule)
        vel[g] = iv.v
        om[g] = iv.omega
    system.strikers = tuple(labels.index(iv.granule) for iv in sc.initial_velocities)
    system.gravity = (float(sc.gravity[0]), float(sc.gravity[1]))
    return system, initial_state(system, vel, om), media


def check_scenario(sc: Scenario, base: Path | None = None) -> None:
    """Whole-scenario checks that need the built geometry, on a granular system built for them
    and then dropped (`build_problem` builds its own). The run's needs are estimated first
    (`estimate.check_needs`), and again with the built granule count and the contacts' heights
    (a granules file, a solid's mesh graded toward its contacts)."""
    from .estimate import check_needs

    check_needs(sc)
    system, _, _ = build_granular(sc, base)
    s = present_solid(sc)
    if any(m.granules_file for m in sc.media) or (s is not None and s.contact_refinement):
        check_needs(sc, system.n, [float(c.point[1]) for c in system.solid_contacts])
    check_geometry(sc, system)
    check_load_overlaps(sc, system)
    check_contact_rates(sc, system)
    speed = max((math.hypot(*iv.v) for iv in sc.initial_velocities), default=0.0)
    bound = safe_time_step(system, system.excitations, speed)
    dt = sc.simulation.dt
    if dt > bound:
        raise ScenarioError(
            f"simulation.dt = {dt:.3e} s: larger than the safe bound {bound:.3e} s "
            "(1/20 of the shortest expected Hertz collision, 1/10 of the pulse)"
        )
    check_times(sc.simulation)


def check_geometry(sc: Scenario, system) -> None:
    """No granule starts pressed into another, a wall or the solid (faces and ends), however its
    medium was built (`granular.geometry.initial_overlaps`)."""
    from ..granular.geometry import initial_overlaps

    s = present_solid(sc)
    box = None if s is None else (s.x0, s.y0, s.x0 + s.width, s.y0 + s.length)
    limit = sc.simulation.overlap_limit
    for o in initial_overlaps(system, box, limit):
        R = float(system.radius[list(system.labels).index(o.granule)])
        what = {"granules": f"granules {o.granule} and {o.other} overlap",
                "wall": f"granule {o.granule} overlaps the wall {o.other!r}",
                "solid": f"granule {o.granule} overlaps the solid"}[o.kind]
        why = {"granules": "granules must start free of compression (simulation.equilibrate finds a precompressed "
                           "start)",
               "wall": f"beyond the contact law's range (simulation.overlap_limit = {limit:g} of the radius)",
               "solid": "where no contact with the solid acts (its ends or inside), or beyond the face contact's range "
                        f"(simulation.overlap_limit = {limit:g})"}[o.kind]
        raise ScenarioError(f"media: {what} by {o.depth:.3e} m ({o.depth / R:.2%} of its radius): {why}")


def _wall_hertz(system, g) -> float:
    """A of granule g against a rigid wall, eq. (3)."""
    return float(wall_coefficients(system.bodies(g), 0.0)[0])


def check_load_overlaps(sc: Scenario, system) -> None:
    """Refuse loads and initial velocities that would drive a contact beyond
    simulation.overlap_limit of the radius, where Hertz contact (eq. 2) no longer holds: a force
    F pressing its granule on a wall even statically, delta = (F / A)^(2/3), or the speed it
    imparts (impulse / mass), or an initial speed v, in a head-on impact on a wall, delta =
    (5 m v^2 / (4 A))^(2/5) (the wall is the stiffer contact: R* = R, m* = m)."""
    limit = sc.simulation.overlap_limit

    def refuse(where, what, g, delta):
        raise ScenarioError(f"{where}: {what} would press granule {system.labels[g]} {delta / system.radius[g]:.1%} of its "
                            f"radius into a contact (limit simulation.overlap_limit = {limit:g}); Hertz contact (eq. 2) "
                            "does not hold there")

    for k, e in enumerate(system.excitations):
        g, F, J = e.granule, e.history.peak(), e.history.peak_impulse()
        delta = hertz_overlap(F, _wall_hertz(system, g)) if math.isfinite(F) and F > 0 else 0.0
        if delta > limit * system.radius[g]:
            refuse(f"excitations.{k}", f"a peak force of {F:.3e} N", g, delta)
        if math.isfinite(J) and J > 0:
            v = J / system.mass[g]
            delta = impact_overlap(system.mass[g], v, _wall_hertz(system, g))
            if delta > limit * system.radius[g]:
                refuse(f"excitations.{k}", f"an impulse of {J:.3e} N s (speed {v:.3e} m/s)", g, delta)
    labels = list(system.labels)
    for k, iv in enumerate(sc.initial_velocities):
        g, v = labels.index(iv.granule), math.hypot(*iv.v)
        delta = impact_overlap(system.mass[g], v, _wall_hertz(system, g))
        if delta > limit * system.radius[g]:
            refuse(f"initial_velocities.{k}", f"an initial speed of {v:.3e} m/s", g, delta)


# the compiled RK4 follows stiff sliding by sub-steps; beyond this many per step a run would crawl
MAX_SUBSTEPS = 1000


def check_contact_rates(sc: Scenario, system) -> None:
    """Refuse contact laws too stiff for the step at the loads' peak force F (or the force of an
    impact at the initial speeds): the tanh friction (eq. 5) relaxes sliding at mu k_s F / m_eff
    (1/m_eff = 1/m + R^2/I = 3/m for a disc on a wall), which the granules' RK4 follows with sub-steps
    of at most 2/rate, up to MAX_SUBSTEPS per step; the Tsuji damping (eq. 3) decays an overlap's
    rate at gamma / m* = alpha_n sqrt(A / m*) delta^(1/4), which RK4 must follow within its stability
    limit (rate dt < 2.785)."""
    c, dt = sc.contact, sc.simulation.dt
    labels = list(system.labels)
    pushed = [(e.granule, e.history.peak(), f"the peak force of excitations.{k}") for k, e in enumerate(system.excitations)]
    for k, iv in enumerate(sc.initial_velocities):
        g, v = labels.index(iv.granule), math.hypot(*iv.v)
        if v > 0:  # the peak force of a Hertz impact on a wall: A delta_max^(3/2)
            A = _wall_hertz(system, g)
            delta = impact_overlap(system.mass[g], v, A)
            pushed.append((g, hertz_force.py_func(A, delta), f"the impact at initial_velocities.{k}"))
    for g, F, what in pushed:
        if not (math.isfinite(F) and F > 0):
            continue
        m = system.mass[g]
        rate = c.mu * c.k_s * F / (m / 3.0)
        substeps = FRICTION_MARGIN * rate * dt / SUBSTEP_RATE_STEP  # `kernels.friction_substeps`
        if substeps > MAX_SUBSTEPS:
            raise ScenarioError(f"contact.k_s = {c.k_s:g} s/m: at {what} ({F:.3e} N) the tanh friction (eq. 5) relaxes "
                                f"sliding at {rate:.2e} 1/s, which needs about {substeps:.1e} RK4 sub-steps "
                                f"per step dt = {dt:.3e} s (limit {MAX_SUBSTEPS}); lower contact.k_s (the paper: 100 s/m) "
                                "or simulation.dt")
        A = float(pair_coefficients(system.bodies(g), system.bodies(g), c.alpha_n)[0])
        delta = hertz_overlap(F, A)
        decay = tsuji_damping.py_func(damping_coefficient(c.alpha_n, m / 2.0, A), delta) / (m / 2.0)  # gamma / m*
        if decay * dt > RK4_REAL_LIMIT:
            raise ScenarioError(f"contact.alpha_n = {c.alpha_n:g}: at {what} ({F:.3e} N) the contact damping (eq. 3) decays "
                                f"relative motion at {decay:.2e} 1/s, too fast for RK4 at dt = {dt:.3e} s (rate dt = "
                                f"{decay * dt:.2f} > {RK4_REAL_LIMIT}); lower contact.alpha_n or simulation.dt")


def check_times(sim) -> None:
    """Outputs fall on multiples of output_every and the last one exactly at duration: output_every
    must be a whole number of steps dt (for the adaptive exact integrator, dt is only the first
    step and any output_every >= dt will do) and duration a whole number of output intervals."""
    dt, every, duration = sim.dt, sim.output_every, sim.duration
    if duration < dt:
        raise ScenarioError(f"simulation.duration = {duration:.3e} s: shorter than the step simulation.dt = {dt:.3e} s")
    if every > duration * (1 + 1e-9):
        raise ScenarioError(f"simulation.output_every = {every:.3e} s: longer than simulation.duration = {duration:.3e} s "
                            "(set output_every to the duration or less)")
    if every < dt * (1 - 1e-9):
        raise ScenarioError(f"simulation.output_every = {every:.3e} s: shorter than the step simulation.dt = {dt:.3e} s")
    fixed = not (sim.solver == "fast" and sim.integrator == "exact" and sim.adaptive)
    per = every / dt
    if fixed and abs(per - round(per)) > 1e-6 * per:
        raise ScenarioError(f"simulation.output_every = {every:.3e} s is {per:.4g} steps of simulation.dt = {dt:.3e} s: "
                            f"outputs must fall on steps (e.g. dt = {every / max(1, math.ceil(per)):.4e} s)")
    n = duration / every
    if abs(n - round(n)) > 1e-6 * max(n, 1.0):
        raise ScenarioError(f"simulation.duration = {duration:.4e} s is {n:.4g} output intervals of {every:.3e} s: the last "
                            f"output must fall at the duration (e.g. duration = {math.ceil(n) * every:.4e} s)")


def build_solid(sc: Scenario, system) -> SolidModel:
    """The scenario's solid; one contact point per granule-solid contact of `system`, in the
    same order (names are the granule labels). ScenarioError "solid: ..." for a solid that
    cannot be built (a contact on a clamped node, layers that overlap, ...)."""
    try:
        return build_solid_model(solid_recipe(sc, system))
    except ValueError as e:
        raise ScenarioError(f"solid: {e}") from None


def solid_recipe(sc: Scenario, system) -> SolidRecipe:
    """What the scenario's solid is built from (`solid.recipe`): a rigid solid for none; only the
    fields its kind uses (a design's probe tells a field that matters by them)."""
    s = present_solid(sc)
    if s is None:
        return SolidRecipe("rigid", tuple(RecipeContact(c.name, c.point, c.normal) for c in system.solid_contacts))
    kind = kind_of(s.kind)
    contacts = tuple(RecipeContact(c.name, c.point, c.normal, kind.layer(s) * float(system.radius[c.granule]))
                     for c in system.solid_contacts)
    material = sc.materials.get(s.material) if "material" in kind.fields else None
    return SolidRecipe(kind.name, contacts, **kind.recipe_fields(s, material))


def solver_settings(sc: Scenario) -> SolverSettings:
    sim = sc.simulation
    return SolverSettings(method=sim.solver, dt=sim.dt, halvings=sim.max_halvings, lambda_max=sim.lambda_max,
                          abstol=sim.abstol, reltol=sim.reltol, max_iterations=sim.max_iterations, integrator=sim.integrator,
                          force_model=sim.force_model, adaptive=sim.adaptive, rtol=sim.rtol, atol=sim.atol,
                          max_step=sim.max_step, mode_cutoff=sim.mode_cutoff, ledger_tol=sim.ledger_tol, modes=sim.modes)


def stored(sc: Scenario, system) -> Stored:
    """What the run keeps and stores (simulation.outputs), the traced granules by label; an
    unknown label is a ScenarioError naming it."""
    out = sc.simulation.outputs
    traced = None
    if out.granules == "none":
        traced = ()
    elif out.granules != "all":
        index = {label: k for k, label in enumerate(system.labels)}
        unknown = [g for g in out.granules if g not in index]
        if unknown:
            shown = ", ".join(system.labels[:3]) + (", ..." if len(system.labels) > 3 else "")
            raise ScenarioError(f"simulation.outputs.granules: no granule {unknown[0]!r} in this scenario (its labels: {shown})")
        traced = tuple(sorted(index[g] for g in out.granules))
    return Stored(traced=traced, contacts=out.contacts, walls=out.walls, steps=out.steps, solid=out.solid,
                  compression=out.compression)


def schedule(sc: Scenario) -> Schedule:
    sim = sc.simulation
    return Schedule(sim.duration, sim.dt, sim.output_every, sim.solid_output_every, sim.checkpoint_every)


# the balance guard measures errors against at least this share of the loads' energy scale, so
# that the round-off of a run's first, nearly unloaded outputs does not stop it
GUARD_ENERGY_FLOOR = 1e-3


def build_problem(sc: Scenario) -> Problem:
    """Everything a solver needs, built from the validated scenario."""
    text = to_toml(sc)
    system, state, _ = build_granular(sc, sc.base)
    keep = stored(sc, system)  # checked before any computation
    solid = build_solid(sc, system)
    system.with_solid_contacts_moved(solid_sag(solid, system.gravity))
    force0, report, table = None, None, None
    if sc.simulation.equilibrate:
        force0, report, table = equilibrate(system, state, solid)
    scales = load_scales(system, state, sc.simulation.duration)
    guards = Guards(sc.simulation.balance_limit, sc.simulation.overlap_limit, GUARD_ENERGY_FLOOR * scales[1])
    settings, max_modes = solver_settings(sc), None
    if settings.mode_cutoff == "auto":  # the exact integrator's cut-off from its tolerance
        settings = replace(settings, mode_cutoff=auto_mode_cutoff(system, scales[0], settings.rtol))
        max_modes = LARGE_SOLID_MODES
    from .files import input_digests, input_texts

    return Problem(system=system, state=state, solid=solid, settings=settings, schedule=schedule(sc), source=text,
                   guards=guards, solid_force0=force0, equilibrium=report, equilibrium_contacts=table,
                   inputs=input_digests(sc), input_texts=input_texts(sc), scales=scales,
                   kinks=tuple(load_kinks(system)), max_modes=max_modes, stored=keep)


def solid_sag(solid: SolidModel, gravity) -> np.ndarray:
    """(nc, 2) how far the solid's own weight moves its contact points [m] (`SolidModel.sag`); a
    ScenarioError naming `gravity` if the solid's supports do not hold its weight."""
    try:
        return solid.sag(gravity)
    except ValueError as e:
        raise ScenarioError(f"gravity = [{gravity[0]:g}, {gravity[1]:g}]: {e}") from None


def equilibrate(system, state, solid):
    """Move the granules of `state` (in place) to the static equilibrium of the constant loads
    (`granular.static`) with the solid's static compliance at its contacts; returns the forces on
    the solid there (nc, 2), the equilibrium's numbers and its loaded contacts
    (`Equilibrium.contacts`). A load that nothing holds is a ScenarioError naming the granules and
    their free direction (exit 2); a Newton that fails on a held medium one with exit 3."""
    from ..granular.static import NoEquilibrium, NotConverged, equilibrium
    from ..guard.exits import STOPPED
    from ..granular.system import Stepper

    C = None
    if solid.ndof:
        from scipy.sparse.linalg import splu

        B = solid.contact_map()
        C = B @ splu(solid.K.tocsc()).solve(B.T.toarray())
        C = 0.5 * (C + C.T)
    try:
        eq = equilibrium(system, Stepper(system).model, C)
    except NoEquilibrium as err:
        raise ScenarioError(f"simulation.equilibrate: {err}") from None
    except NotConverged as err:  # a numerical stop, not bad input
        raise ScenarioError(f"simulation.equilibrate: {err}", code=STOPPED) from None
    state.pos[:] = eq.pos
    from ..io.results import wall_names

    return eq.solid_forces, eq.summary(), eq.contacts(system.labels, wall_names(system))


def built_models(sc: Scenario):
    """(GranularSystem, SolidModel) of a scenario, for drawings of the scenario (not of a result:
    a result carries its model, `io.model`)."""
    problem = build_problem(sc)
    return problem.system, problem.solid
