"""The paper's iterative-interpolative coupling algorithm (Sec. II C, Appendices A and B).

Per step tau_s -> tau_s+1 (`paper_step`):
  1. guess the interface forces F = F_s (converged at the previous step; 0 at the start);
  2. Newmark (A2) for the solid under F: the contact points' acceleration a_{s+1};
  3. interpolate the contact motion inside the step with the constant average acceleration (A3);
  4. RK4 for the granules under that prescribed motion;
  5. recompute the interface forces at tau_s+1 from the granular state and the contact motion;
  6. repeat 2-5 until every nonzero force component satisfies (A4):
     |F^(j+1) - F^(j)| <= Abstol + Reltol |F^(j)|;
  7. accept: Newmark with the converged forces, the granules' last RK4 state.
The step size follows (B1): dtau0, halved until max |lambda| <= 1/2 with lambda from (A9)
evaluated at the last converged state; the beam (no tangential DOF) keeps dtau0.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from .. import scenario as S
from ..checkpoint import checkpoint_period, fingerprint, load_checkpoint, save_checkpoint
from ..granular.system import Stepper
from ..results import base_attrs, granular_dataset
from ..solid.build import build_solid
from ..solid.newmark import Newmark, NewmarkState
from .interface import Interface
from .rigid import Recorder


class ConvergenceError(RuntimeError):
    """The interface-force iteration did not converge; the message carries the diagnosis."""


@dataclass
class CoupledState:
    y: np.ndarray  # granular augmented state
    solid: NewmarkState
    F: np.ndarray  # converged interface forces on the solid, (nc, 2)
    normal: np.ndarray  # |N_k| at the last converged state
    vrel: np.ndarray  # relative tangential velocity at the last converged state
    ticks: int = 0  # time in units of dt0 / 2^max_halvings
    level: int = 0  # current halving level n: dt = dt0 / 2^n


@dataclass
class StepReport:
    dt: float
    iterations: int
    lam: np.ndarray  # (nc,) |lambda| used to choose dt


@dataclass
class CoupledProblem:
    stepper: Stepper
    iface: Interface
    newmark: Newmark
    dt0: float
    max_halvings: int
    lambda_max: float
    abstol: float
    reltol: float
    max_iterations: int
    adaptive: bool
    newton: bool = False  # Newton on the interface forces (fast solver, sparse path) instead of fixed point
    forced_level: int = 0  # halvings imposed after a failed Newton step
    diag: dict = field(default_factory=dict)


def contact_motion(iface: Interface, sol: NewmarkState):
    """(u, v, a) of the contact points (nc, 2) from the solid state."""
    nc = iface.nc
    if iface.model.ndof == 0:
        z = np.zeros((nc, 2))
        return z, z, z
    return ((iface.B @ sol.x).reshape(nc, 2), (iface.B @ sol.v).reshape(nc, 2), (iface.B @ sol.a).reshape(nc, 2))


def choose_level(prob: CoupledProblem, st: CoupledState, ticks_to_output: int) -> tuple[int, np.ndarray]:
    """(B1): the smallest halving level n with max |lambda(dt0 / 2^n)| <= lambda_max, restricted so
    that the step lands on the tick grid and does not pass the next output."""
    law = prob.stepper.system.law
    H = prob.max_halvings
    lam = np.zeros(prob.iface.nc)
    n = 0
    if prob.adaptive:
        while True:
            lam = prob.iface.friction_eigenvalues(prob.dt0 / 2**n, law.mu, law.k_s, st.normal, st.vrel)
            if lam.max(initial=0.0) <= prob.lambda_max:
                break
            if n == H:
                raise ConvergenceError(
                    f"t = {st.ticks * prob.dt0 / 2**H:.6e} s: the friction eigenvalue stays at {lam.max():.3f} > "
                    f"{prob.lambda_max} after {H} halvings of {prob.dt0:.3e} s (contact "
                    f"{prob.iface.model.contacts[int(np.argmax(lam))].name}); raise simulation.max_halvings or lower k_s"
                )
            n += 1
    n = max(n, prob.forced_level)
    # a larger step only where the clock is aligned to it, and never past the next output
    while n < H and (st.ticks % 2 ** (H - n) != 0 or 2 ** (H - n) > ticks_to_output):
        n += 1
    if n != 0 and prob.adaptive:
        lam = prob.iface.friction_eigenvalues(prob.dt0 / 2**n, law.mu, law.k_s, st.normal, st.vrel)
    return n, lam


def paper_step(prob: CoupledProblem, st: CoupledState, ticks_to_output: int) -> StepReport:
    """One accepted step of the paper's algorithm; updates `st` in place."""
    stepper, iface, nm = prob.stepper, prob.iface, prob.newmark
    n, lam = choose_level(prob, st, ticks_to_output)
    dt = prob.dt0 / 2**n
    ops = iface.operators(dt)
    nc = iface.nc
    has_solid = iface.model.ndof > 0
    sol = st.solid
    if has_solid:
        a_pred = nm.predictor(sol, dt)
        Ba_pred = (iface.B @ a_pred).reshape(nc, 2)
        u0, v0, a0 = contact_motion(iface, sol)
    else:
        z = np.zeros((nc, 2))
        u0 = v0 = a0 = Ba_pred = z
    F = st.F.copy()
    t0 = st.ticks * prob.dt0 / 2**prob.max_halvings
    gstate = _GState(st.y.copy(), t0)
    for it in range(1, prob.max_iterations + 1):
        # steps 2-3: contact accelerations at s+1 and the average acceleration inside the step
        a1 = Ba_pred + (ops.C @ F.ravel()).reshape(nc, 2) if has_solid else Ba_pred
        abar = 0.5 * (a0 + a1)
        # step 4: granules under the prescribed motion
        gstate.y[:] = st.y
        gstate.t = t0
        stepper.advance(gstate, dt, 1, u0, v0, abar)
        # step 5: interface forces at s+1
        u1 = u0 + v0 * dt + 0.5 * abar * dt * dt
        v1 = v0 + abar * dt
        F_new, normal, vrel, _ = stepper.solid_contact_state(gstate, u1, v1)
        dF = np.abs(F_new - F)
        ok = dF <= prob.abstol + prob.reltol * np.abs(F)
        if ok.all() or not prob.newton:
            F = F_new
            if ok.all():
                break
            continue
        F = F + newton_update(stepper, gstate.y, u1, v1, ops.C, dt, F_new - F)
    else:
        k = int(np.argmax(np.where(ok, 0.0, dF).max(axis=1)))
        raise ConvergenceError(
            f"t = {t0:.6e} s, dt = {dt:.3e} s: interface forces did not converge in {prob.max_iterations} iterations "
            f"(contact {iface.model.contacts[k].name}: change {dF[k].max():.3e} N on {np.abs(F[k]).max():.3e} N, "
            f"|lambda| = {lam[k]:.3f}); raise simulation.max_iterations or loosen abstol/reltol"
        )
    # step 7: accept
    if has_solid:
        a_new = a_pred + ops.Z @ F.ravel()
        st.solid = Newmark.finish(sol, a_new, dt)
    st.y[:] = gstate.y
    st.F = F
    st.normal = normal
    st.vrel = vrel
    st.ticks += 2 ** (prob.max_halvings - n)
    st.level = n
    return StepReport(dt, it, lam)


def newton_update(stepper, y, u1, v1, C, dt, residual):
    """dF solving (I - J) dF = G(F) - F, J = Du (dt^2/4) C + Dw (dt/2) C with the analytic
    contact-law derivatives at the contact points (the granules' sensitivity left out)."""
    from .fast import contact_forces_jacobian

    s = stepper.system
    _, _, _, Du, Dw = contact_forces_jacobian(y, s.n, s.radius, s.law.mu, s.law.k_s, s.sg, s.sp, s.sn, s.sA, s.sG, u1, v1)
    nc = len(Du)
    J = np.zeros((2 * nc, 2 * nc))
    for c in range(nc):
        rows = slice(2 * c, 2 * c + 2)
        J[rows] = Du[c] @ C[rows] * (0.25 * dt * dt) + Dw[c] @ C[rows] * (0.5 * dt)
    return np.linalg.solve(np.eye(2 * nc) - J, residual.ravel()).reshape(nc, 2)


class _GState:
    """A light granular state (y, t) for trial integrations."""

    __slots__ = ("y", "t")

    def __init__(self, y, t):
        self.y = y
        self.t = t

    @property
    def pos(self):
        n = (len(self.y) - 3) // 6
        return self.y[: 2 * n].reshape(-1, 2)


def simulate_coupled(sc: S.Scenario, progress=None, checkpoint=None, resume=None) -> xr.Dataset:
    """Run a scenario with an elastic solid (plate or beam): the fast solver (default) or the
    paper's algorithm."""
    if sc.simulation.solver == "fast":
        from .fast import simulate_fast

        return simulate_fast(sc, progress, checkpoint, resume)
    return simulate_sparse(sc, progress, checkpoint, resume, newton=False)


def simulate_sparse(sc: S.Scenario, progress=None, checkpoint=None, resume=None, newton=False, model=None) -> xr.Dataset:
    """Sparse-direct Newmark coupled to the granules. newton=False: the paper's algorithm (fixed
    point, step halving by (A9)-(B1)); newton=True: the fast solver's Newton iteration at dtau0
    (a step that does not converge is retried at half the step), for solids too large for the
    all-mode path."""
    sim = sc.simulation
    system, gstate0, media = S.build_granular(sc, sc.base)
    stepper = Stepper(system)
    model = build_solid(sc, system) if model is None else model
    nm = Newmark(model.M, model.K)
    tangents = np.array([[-c.normal[1], c.normal[0]] for c in system.solid_contacts]).reshape(-1, 2)
    iface = Interface(model, nm, tangents)
    H = sim.max_halvings
    prob = CoupledProblem(stepper, iface, nm, sim.dt, H, sim.lambda_max, sim.abstol, sim.reltol,
                          sim.max_iterations, adaptive=bool(iface.has_tangent.any()) and not newton, newton=newton)
    nc = iface.nc
    st = CoupledState(gstate0.y.copy(), nm.initial(), np.zeros((nc, 2)), np.zeros(nc), np.zeros(nc))
    per = max(1, int(round(sim.output_every / sim.dt)))
    nout = int(np.ceil(sim.duration / (per * sim.dt) - 1e-9))
    out_ticks = per * 2**H
    solid_per = max(1, int(round(sim.solid_output_every / sim.output_every))) if sim.solid_output_every > 0 else 1
    rec = Recorder()
    steps: dict[str, list] = {"t": [], "dt": [], "iterations": [], "lambda": []}
    solid_rec: dict[str, list] = {"t": [], "x": [], "v": []}
    fp = fingerprint(S.to_toml(sc) + "coupled")

    def snapshot():
        from ..granular.system import GranularState

        g = GranularState(st.y, st.ticks * sim.dt / 2**H)
        u, _, _ = contact_motion(iface, st.solid)
        ek, ep = model.energy(st.solid.x, st.solid.v) if model.ndof else (0.0, 0.0)
        nrm = np.array([c.normal for c in system.solid_contacts]).reshape(-1, 2)
        fn = np.einsum("ij,ij->i", st.F, nrm)
        ft = np.einsum("ij,ij->i", st.F, tangents)
        rec.snapshot(stepper, g, ek + ep, u, energy_solid_kinetic=ek, energy_solid_potential=ep,
                     contact_force_normal=fn, contact_force_tangential=ft)

    def solid_snapshot():
        solid_rec["t"].append(st.ticks * sim.dt / 2**H)
        solid_rec["x"].append(st.solid.x.astype(np.float32))
        solid_rec["v"].append(st.solid.v.astype(np.float32))

    start = 0
    if resume is not None:
        arrays, recorded, times = load_checkpoint(resume, fp)
        st.y[:] = arrays["y"]
        st.solid = NewmarkState(arrays["sx"], arrays["sv"], arrays["sa"], 0.0)
        st.F, st.normal, st.vrel = arrays["F"], arrays["normal"], arrays["vrel"]
        st.ticks, st.level = int(arrays["ticks"]), int(arrays["level"])
        from ..granular.system import build_neighbours

        stepper.nl = build_neighbours(system, arrays["ref_pos"])
        unpack_records(recorded, times, rec, steps, solid_rec)
        start = int(arrays["k"])
    else:
        snapshot()
        solid_snapshot()
    ck_per = checkpoint_period(checkpoint, sim.checkpoint_every, per, sim.dt)
    t_wall = time.perf_counter()
    for k in range(start, nout):
        target = (k + 1) * out_ticks
        while st.ticks < target:
            try:
                rep = paper_step(prob, st, target - st.ticks)
            except ConvergenceError:
                if not newton or prob.forced_level >= H:
                    raise
                prob.forced_level += 1  # retry this step at half the step (state untouched)
                continue
            steps["t"].append(st.ticks * sim.dt / 2**H)
            steps["dt"].append(rep.dt)
            steps["iterations"].append(rep.iterations)
            steps["lambda"].append(rep.lam.copy())
            if not np.isfinite(st.y).all() or not np.isfinite(st.solid.x).all():
                raise RuntimeError(f"state became non-finite at t = {st.ticks * sim.dt / 2**H:.6e} s")
        prob.forced_level = 0  # back to dtau0 after each output interval
        snapshot()
        if (k + 1) % solid_per == 0:
            solid_snapshot()
        if progress is not None:
            progress(st.ticks * sim.dt / 2**H)
        if ck_per and (k + 1) % ck_per == 0 and k + 1 < nout:
            save_checkpoint(checkpoint, fp, {
                "y": st.y, "sx": st.solid.x, "sv": st.solid.v, "sa": st.solid.a, "F": st.F, "normal": st.normal,
                "vrel": st.vrel, "ticks": st.ticks, "level": st.level, "ref_pos": stepper.nl.ref_pos, "k": k + 1,
            }, pack_records(rec, steps, solid_rec), rec.times)
    wall = time.perf_counter() - t_wall
    return _dataset(sc, system, model, rec, steps, solid_rec, wall, prob, solver_name="fast-sparse" if newton else "paper")


def pack_records(rec, steps: dict, solid_rec: dict) -> dict:
    """Everything recorded so far, flattened for a checkpoint."""
    out = dict(rec.rec)
    out.update({f"step:{a}": b for a, b in steps.items()})
    out.update({f"solid:{a}": b for a, b in solid_rec.items()})
    return out


def unpack_records(recorded: dict, times, rec, steps: dict, solid_rec: dict) -> None:
    """Inverse of `pack_records`, into the given containers."""
    for k, v in recorded.items():
        if k.startswith("step:"):
            steps[k[5:]] = list(v)
        elif k.startswith("solid:"):
            solid_rec[k[6:]] = list(v)
        else:
            rec.rec[k] = list(v)
    rec.times = times


def _dataset(sc, system, model, rec, steps, solid_rec, wall, prob, solver_name="paper", modes=None) -> xr.Dataset:
    sim = sc.simulation
    it = np.asarray(steps["iterations"], dtype=np.int64)
    dts = np.asarray(steps["dt"], float)
    solver = {"name": solver_name, "dt0": sim.dt, "steps": int(len(dts)), "mean_iterations": float(it.mean()) if len(it) else 0.0,
              "max_iterations_used": int(it.max()) if len(it) else 0, "min_step": float(dts.min()) if len(dts) else sim.dt,
              "abstol": sim.abstol, "reltol": sim.reltol, "lambda_max": sim.lambda_max, "wall_time_s": wall,
              "neighbour_rebuilds": prob.stepper.rebuilds}
    attrs = base_attrs(S.to_toml(sc), solver)
    attrs["solid_kind"] = model.kind
    attrs["solid_dofs"] = int(model.ndof)
    attrs["solid_elements"] = int(model.nelements)
    names = [c.name for c in model.contacts]
    r = rec.rec
    extras = {
        "energy_solid_kinetic": (("time",), r.pop("energy_solid_kinetic"), {"units": "J"}),
        "energy_solid_potential": (("time",), r.pop("energy_solid_potential"), {"units": "J"}),
        "contact_force_normal": (("time", "contact"), np.array(r.pop("contact_force_normal")).reshape(len(rec.times), -1),
                                 {"units": "N", "long_name": "normal force on the solid (along n_ik)"}),
        "contact_force_tangential": (("time", "contact"), np.array(r.pop("contact_force_tangential")).reshape(len(rec.times), -1),
                                     {"units": "N", "long_name": "tangential force on the solid (along t_ik = k x n_ik)"}),
    }
    # per-output-interval diagnostics
    st_t = np.asarray(steps["t"], float)
    lam = np.array(steps["lambda"], float).reshape(len(st_t), -1)
    times = np.asarray(rec.times)
    idx = np.searchsorted(st_t, times - 1e-15, side="left")
    step_size = np.full(len(times), np.nan)
    iters = np.full(len(times), np.nan)
    lmax = np.zeros((len(times), len(names)))
    lo = 0
    for j, hi in enumerate(idx):
        if j == 0:
            lo = 0
            continue
        seg = slice(lo, hi + 1)
        if hi + 1 > lo:
            step_size[j] = dts[seg].min()
            iters[j] = it[seg].mean()
            lmax[j] = lam[seg].max(axis=0)
        lo = hi + 1
    extras["step_size"] = (("time",), step_size, {"units": "s", "long_name": "smallest step since the previous output"})
    extras["iterations"] = (("time",), iters, {"long_name": "mean fixed-point iterations since the previous output"})
    extras["lambda_max"] = (("time", "contact"), lmax, {"long_name": "max |lambda| (A9) since the previous output"})
    extras["step_time"] = (("step",), st_t, {"units": "s", "long_name": "time at the end of each accepted step"})
    extras["step_dt"] = (("step",), dts, {"units": "s"})
    extras["step_iterations"] = (("step",), it, {})
    extras["step_lambda"] = (("step", "contact"), lam, {"long_name": "|lambda| (A9) of each step at each contact"})
    nst = len(solid_rec["t"])
    extras["solid_time"] = (("solid_time",), np.asarray(solid_rec["t"], float), {"units": "s"})
    if "x" in solid_rec:  # reduced coordinates (paper solver)
        extras["solid_x"] = (("solid_time", "dof"), np.array(solid_rec["x"], dtype=np.float32).reshape(nst, -1),
                             {"long_name": "reduced solid displacements q"})
        extras["solid_v"] = (("solid_time", "dof"), np.array(solid_rec["v"], dtype=np.float32).reshape(nst, -1),
                             {"long_name": "reduced solid velocities"})
    else:  # mass-normalised modal coordinates (fast solver): q = Phi eta
        extras["solid_eta"] = (("solid_time", "mode"), np.array(solid_rec["eta"], dtype=np.float32).reshape(nst, -1),
                               {"long_name": "modal displacements (mass-normalised modes)"})
        extras["solid_eta_dot"] = (("solid_time", "mode"), np.array(solid_rec["eta_dot"], dtype=np.float32).reshape(nst, -1),
                                   {"long_name": "modal velocities"})
        extras["mode_omega"] = (("mode",), modes.omega, {"units": "rad/s"})
    for key, val in extras.items():
        r[f"extra:{key}"] = val
    ds = granular_dataset(rec.times, system.labels, system.media, system.medium_index, r, attrs)
    ds = ds.assign_coords(contact=("contact", np.array(names, dtype=object)))
    return ds
