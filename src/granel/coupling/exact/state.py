"""The exact integrator's records: its configuration, the solid as it propagates it, the state that
evolves (with a clock record of named scalars), the per-step operator cache and the scratch of one
step, each built by keyword."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...granular.bundles import InterfaceForces, Motion, interface_buffers, motion_buffers
from ...guard.jit import njit
from .. import core

GRID_PER_OCTAVE = 4  # the step grid h_k = h_max 2^(-k / GRID_PER_OCTAVE)
FORCE_NODES = {"quadratic": (0.0, 0.5, 1.0), "linear": (0.0, 1.0)}

# the scalars that evolve with the state (one record: st.clock[0].t, ...)
CLOCK = np.dtype([
    ("t", np.float64),  # the current time
    ("t_start", np.float64),  # the start of the last accepted step
    ("ledger_ms", np.float64),  # the controller's running mean square of the ledger part (`ledger.control_error`)
    ("friction_rate", np.float64),  # of the last step's RK4 sub-steps
    ("ledger", np.float64),  # the energy ledger (13) now ...
    ("ledger_start", np.float64),  # ... and at t = 0
    ("level", np.float64),  # the controller's continuous level (the step h_max 2^(-level/4))
    ("work_max", np.float64),  # the largest |input work| so far (`ledger.ledger_bound`)
    ("grid_level", np.int64),  # the grid level of the next step
    ("rejected", np.int64),  # steps rejected so far
])

# the scalars of one step's trial (one record: work.trial[0].rate, ...)
TRIAL = np.dtype([
    ("rate", np.float64),  # the friction rate of the step's RK4 sub-steps
    ("velocity_error", np.float64),  # the scaled error parts of `ledger.step_error`: velocities ...
    ("ledger_part", np.float64),  # ... the step's defect of the ledger against its share ...
    ("drift_part", np.float64),  # ... and the drift after the step against the bound
    ("iteration_noise", np.float64),  # the converged forces' work uncertainty (`interface.iteration_noise`)
    ("roundoff", np.float64),  # the ledger's round-off (`ledger.trial_ledger`, `ledger.contact_roundoff`)
    ("touching", np.int64),  # unknowns of the touching contacts in Newton's system
    ("matrix_level", np.int64),  # the step level Newton's matrix was built at (-1: none)
    ("iterations", np.int64),  # of the last converged step
    ("matrix_iteration", np.int64),  # the iteration of this step it was built at (0: an earlier step's)
])


class ExactSolid(NamedTuple):
    """The solid's modes as the integrator propagates them (retained eigenmodes, then residual
    modes): omega (nr,), the contacts' modal matrix P = B Phi (2nc, nr), and the contacts' frame."""

    omega: np.ndarray
    P: np.ndarray
    frame: core.ContactFrame


class ExactConfig(NamedTuple):
    h_max: float
    levels: int  # L: the smallest grid step is h_max 2^(-L/4)
    adaptive: bool  # False: every step is h_max (a fixed step), but for retries of a failed one
    rtol: float
    atol: float  # [m/s]
    v_ref: float  # velocity scale of the error norm [m/s]
    e_ref: float  # energy scale of the error norm [J]
    ledger_tol: float  # the energy ledger (13) stays within ledger_tol e_ref
    ledger_limit: float  # [J] a drift beyond this stops the run (the control has failed)
    duration: float
    newton: bool
    abstol: float
    reltol: float
    max_iterations: int
    max_disp: float


class OpsCache(NamedTuple):
    """The force model's nodes (nb,: 0, then the nn = nb - 1 unknown nodes, the last at 1) and, per
    step size (grid level k; the last slot for an off-grid step cut at a load's kink), computed on
    first use (`operators.ensure_ops`)."""

    nodes: np.ndarray  # (nb,)
    ready: np.ndarray  # (L+1,) bool
    T: np.ndarray  # (L+1, nb, 4) the Lagrange basis's Taylor rows
    free: np.ndarray  # (L+1, nn, nr, 3) the modes' free-response weights at each unknown node
    end_disp: np.ndarray  # (L+1, nr, nb) the modes' end displacement ...
    end_vel: np.ndarray  # ... and velocity per unit modal force datum
    Cu: np.ndarray  # (L+1, nn, nb, 2nc, 2nc) contacts' displacement at unknown node j per unit force datum b
    Cw: np.ndarray  # ... and their velocity
    I1: np.ndarray  # (L+1, nn, nb) the basis's first ...
    I2: np.ndarray  # ... and second integral from the start to each unknown node


def ops_cache(model: str, levels: int, nr: int, nc: int) -> OpsCache:
    """An empty operator cache of a force model for `levels` grid levels plus the off-grid slot."""
    nodes = np.asarray(FORCE_NODES[model], float)
    nb, L, m2 = len(nodes), levels + 2, 2 * nc
    nn = nb - 1
    return OpsCache(nodes=nodes, ready=np.zeros(L, bool), T=np.zeros((L, nb, 4)), free=np.zeros((L, nn, nr, 3)),
                    end_disp=np.zeros((L, nr, nb)), end_vel=np.zeros((L, nr, nb)), Cu=np.zeros((L, nn, nb, m2, m2)),
                    Cw=np.zeros((L, nn, nb, m2, m2)), I1=np.zeros((L, nn, nb)), I2=np.zeros((L, nn, nb)))


class LastStep(NamedTuple):
    """The last accepted step, for dense output and the next step's predictor: its start (granules,
    modes), its force data Fs (nb, nc, 2) at the nodes with their modal projections qs (nb, nr)
    and basis Ts (nb, 4), and the contacts' motion over it."""

    y0: np.ndarray
    eta0: np.ndarray
    etad0: np.ndarray
    Fs: np.ndarray
    qs: np.ndarray
    Ts: np.ndarray
    motion: Motion


class ExactState(NamedTuple):
    """The state at the current time: the granules y and their derivative dy (the next step's
    first RK4 stage), the modes (eta, eta'), the interface force F on the solid (nc, 2) and its
    modal projection q = P'F, the contacts' displacement u and velocity w (2nc,), |N| and v_t at
    the contacts, the last step, and the clock (a CLOCK record)."""

    y: np.ndarray
    dy: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    F: np.ndarray
    q: np.ndarray
    u: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    vrel: np.ndarray
    last: LastStep
    clock: np.ndarray


def new_clock(ledger: float, level: int) -> np.ndarray:
    clock = np.zeros(1, CLOCK)
    c = clock[0]
    c["ledger"] = c["ledger_start"] = ledger
    c["level"] = float(level)
    c["grid_level"] = level
    return clock


def initial_state(y, dy, nr: int, nc: int, nb: int, ledger: float, level: int) -> ExactState:
    """The state at t = 0: the solid at rest, no interface force."""
    zc = lambda: np.zeros((nc, 2))  # noqa: E731
    last = LastStep(y0=y.copy(), eta0=np.zeros(nr), etad0=np.zeros(nr), Fs=np.zeros((nb, nc, 2)), qs=np.zeros((nb, nr)),
                    Ts=np.zeros((nb, 4)), motion=Motion(zc(), zc(), zc(), zc(), zc(), zc()))
    return ExactState(y=y, dy=dy, eta=np.zeros(nr), etad=np.zeros(nr), F=zc(), q=np.zeros(nr), u=np.zeros(2 * nc),
                      w=np.zeros(2 * nc), normal=np.zeros(nc), vrel=np.zeros(nc), last=last, clock=new_clock(ledger, level))


# ---------------------------------------------------------------- the scratch of one step


class Granular(NamedTuple):
    """The granules over the trial step: the end state, RK4's stages, the end derivative, the
    embedded error, and the state at an interior node."""

    y: np.ndarray
    stages: np.ndarray  # (5, len(y))
    dy_end: np.ndarray
    err: np.ndarray
    y_node: np.ndarray


class Nodes(NamedTuple):
    """The contacts at the unknown nodes: their displacement and velocity (nn, 2nc), the part of
    those that does not depend on the unknowns, the motion the granules see, modal scratch."""

    u: np.ndarray
    w: np.ndarray
    u_free: np.ndarray
    w_free: np.ndarray
    motion: Motion
    modal: np.ndarray  # (2 nn, nr)
    at_contacts: np.ndarray  # (2nc, 2 nn)


class Unknowns(NamedTuple):
    """The forces at the unknown nodes X (nn 2nc,: node-major), X before the last Newton step, the
    map's values G(X), the contact law's output at each unknown node, and the trial's modal data:
    the force data projected on the modes (nb, nr) and the modes at the step's end."""

    X: np.ndarray
    X_prev: np.ndarray
    G: np.ndarray
    iface0: InterfaceForces  # at the first unknown node ...
    iface1: InterfaceForces  # ... and at the second (quadratic model)
    modal_force: np.ndarray
    eta_end: np.ndarray
    etad_end: np.ndarray


class Newton(NamedTuple):
    """Newton's system: the rows of -dG/dX (J), the update, the touching contacts and their
    unknowns, the factorised system on those, one contact's granule response, the granules'
    inverse mass and spin factor R^2/I per contact."""

    J: np.ndarray  # (nn 2nc, nn 2nc)
    dX: np.ndarray
    touching: np.ndarray  # (nc,) bool
    index: np.ndarray  # (nn 2nc,) the touching unknowns
    pivots: np.ndarray
    pivots_touching: np.ndarray
    matrix: np.ndarray  # the touching unknowns' system, factorised
    rhs: np.ndarray
    response: np.ndarray  # (2nn, 2nn) one contact's I - Dg ...
    response_inv: np.ndarray  # ... and its inverse
    rows: np.ndarray  # (2nn, nn 2nc)
    column: np.ndarray
    inv_mass: np.ndarray  # (nc,)
    spin: np.ndarray


class LocalFriction(NamedTuple):
    """One contact's local friction problem over its unknown nodes (`newton.local_friction_solve`)."""

    s: np.ndarray  # the tangential forces
    s0: np.ndarray
    vt0: np.ndarray
    normal: np.ndarray
    B: np.ndarray  # (nn, nn)
    residual: np.ndarray
    jacobian: np.ndarray


class Work(NamedTuple):
    """Scratch of one step."""

    granular: Granular
    nodes: Nodes
    unknowns: Unknowns
    newton: Newton
    friction: LocalFriction
    trial: np.ndarray  # a TRIAL record


@njit(cache=True)
def work_for(y, nc, nr, nb):
    m2 = 2 * nc
    nn = nb - 1
    n = nn * m2
    trial = np.zeros(1, dtype=TRIAL)
    trial[0]["matrix_level"] = -1  # by key: the same in Python (`loop.compile_plan`)
    trial[0]["iterations"] = 99
    granular = Granular(y=np.empty_like(y), stages=np.empty((5, y.shape[0])), dy_end=np.empty_like(y), err=np.zeros_like(y),
                        y_node=np.empty_like(y))
    nodes = Nodes(u=np.zeros((nn, m2)), w=np.zeros((nn, m2)), u_free=np.zeros((nn, m2)), w_free=np.zeros((nn, m2)),
                  motion=motion_buffers(nc), modal=np.zeros((2 * nn, nr)), at_contacts=np.zeros((m2, 2 * nn)))
    unknowns = Unknowns(X=np.zeros(n), X_prev=np.zeros(n), G=np.zeros(n), iface0=interface_buffers(nc),
                        iface1=interface_buffers(nc), modal_force=np.zeros((nb, nr)), eta_end=np.zeros(nr),
                        etad_end=np.zeros(nr))
    newton = Newton(J=np.zeros((n, n)), dX=np.zeros(n), touching=np.zeros(nc, np.bool_), index=np.zeros(n, np.int64),
                    pivots=np.zeros(n, np.int64), pivots_touching=np.zeros(n, np.int64), matrix=np.zeros((n, n)),
                    rhs=np.zeros(n), response=np.zeros((2 * nn, 2 * nn)), response_inv=np.zeros((2 * nn, 2 * nn)),
                    rows=np.zeros((2 * nn, n)), column=np.zeros(2 * nn), inv_mass=np.zeros(nc), spin=np.zeros(nc))
    friction = LocalFriction(s=np.zeros(nn), s0=np.zeros(nn), vt0=np.zeros(nn), normal=np.zeros(nn), B=np.zeros((nn, nn)),
                             residual=np.zeros(2), jacobian=np.zeros((2, 2)))
    return Work(granular=granular, nodes=nodes, unknowns=unknowns, newton=newton, friction=friction, trial=trial)


@njit(cache=True, inline="always")
def node_iface(unknowns, j):
    """The contact law's output at unknown node j."""
    return unknowns.iface0 if j == 0 else unknowns.iface1


class StepData(NamedTuple):
    """A step as dense output reads it: its start (granules y0, modes eta0, eta0', time t0), its
    force data Fs (nb, nc, 2) with their modal projections qs (nb, nr) and basis Ts (nb, 4), the
    contacts' motion over it and the friction rate of its RK4 sub-steps."""

    y0: np.ndarray
    eta0: np.ndarray
    etad0: np.ndarray
    t0: float
    Fs: np.ndarray
    qs: np.ndarray
    Ts: np.ndarray
    motion: Motion
    rate: float


class DenseOut(NamedTuple):
    """One output's state, filled by `dense.dense`: granules, modes, interface force (nc, 2)."""

    y: np.ndarray
    eta: np.ndarray
    etad: np.ndarray
    F: np.ndarray
