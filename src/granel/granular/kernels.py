"""Compiled discrete-element kernels: the right-hand side of eq. (1) with the contact law of
`granular.contact` at every pair, wall and solid point and the granules' weights, RK4 (with sub-steps where friction is
stiff), per-granule energies (11), and the interface forces with their Jacobian.

Kernel inputs travel in the bundles of `granular.bundles` (state layout documented there).
Three kinds of contact share one geometry helper each and one force routine:
  pairs   granule-granule candidates from the neighbour list (Hertz + Tsuji damping + friction);
  walls   granule-rigid wall candidates (m* = m: damped; G = 0 at an undamped wall);
  points  granule-solid contact points moving with the solid, u(tau) from `Motion` (eq. A3);
          m* = 0 there, so no viscous damping.
"""

from __future__ import annotations

import math

import numpy as np

from ..guard.jit import njit
from .bundles import ACC_FRIC, ACC_VISC, ACC_WORK, LEDGER_SIZE, ledger_offset, spin_offset, theta_offset, velocity_offset
from .contact import contact_law, contact_law_derivatives, hertz_force, hertz_potential
from .laws import load_force, wall_motion


# ---------------------------------------------------------------- geometry of a contact


@njit(cache=True, inline="always")
def pair_overlap(y, i, j, radius):
    """(dx, dy, distance, overlap delta of eq. (2)) of granules i and j."""
    dx = y[2 * j] - y[2 * i]
    dyy = y[2 * j + 1] - y[2 * i + 1]
    dist = math.sqrt(dx * dx + dyy * dyy)
    return dx, dyy, dist, radius[i] + radius[j] - dist


@njit(cache=True, inline="always")
def wall_overlap(y, i, w, radius, walls):
    """Overlap (eq. 2) of granule i with wall segment w; -1 when its centre projects outside the
    segment."""
    rx = y[2 * i] - walls.p0[w, 0]
    ry = y[2 * i + 1] - walls.p0[w, 1]
    along = rx * walls.tangent[w, 0] + ry * walls.tangent[w, 1]
    if along < 0.0 or along > walls.length[w]:
        return -1.0
    return radius[i] - (rx * walls.normal[w, 0] + ry * walls.normal[w, 1])


@njit(cache=True, inline="always")
def point_overlap(y, i, c, radius, points, ux, uy):
    """Overlap (eq. 2) of granule i with the flat solid contact point c displaced by (ux, uy)."""
    gap = (points.p[c, 0] + ux - y[2 * i]) * points.n[c, 0] + (points.p[c, 1] + uy - y[2 * i + 1]) * points.n[c, 1]
    return radius[i] - gap


@njit(cache=True, inline="always")
def motion_at(motion, c, tau):
    """(ux, uy, wx, wy): displacement and velocity of contact point c at tau into the step (A3,
    or the polynomial of the exact modal integrator), from the Taylor coefficients of `Motion`."""
    t2 = 0.5 * tau * tau
    t3 = t2 * tau / 3.0
    t4 = 0.25 * t3 * tau
    t5 = 0.2 * t4 * tau
    ux = motion.u0[c, 0] + motion.v0[c, 0] * tau + motion.a[c, 0] * t2 + motion.j[c, 0] * t3 + motion.d4[c, 0] * t4 \
        + motion.d5[c, 0] * t5
    uy = motion.u0[c, 1] + motion.v0[c, 1] * tau + motion.a[c, 1] * t2 + motion.j[c, 1] * t3 + motion.d4[c, 1] * t4 \
        + motion.d5[c, 1] * t5
    wx = motion.v0[c, 0] + motion.a[c, 0] * tau + motion.j[c, 0] * t2 + motion.d4[c, 0] * t3 + motion.d5[c, 0] * t4
    wy = motion.v0[c, 1] + motion.a[c, 1] * tau + motion.j[c, 1] * t2 + motion.d4[c, 1] * t3 + motion.d5[c, 1] * t4
    return ux, uy, wx, wy


# ---------------------------------------------------------------- forces


@njit(cache=True, inline="always")
def one_sided_force(y, radius, i, nx, ny, delta, rvx, rvy, A, G, law):
    """The force (fx, fy) and torque on granule i from a flat partner (wall or solid point) along
    n_ik = (nx, ny), given its velocity relative to the partner (rvx, rvy), eqs. (2)-(6), and the
    (viscous, friction) power they dissipate."""
    OM = spin_offset(radius.shape[0])
    tx = -ny
    ty = nx
    Ri = radius[i]
    ddelta = rvx * nx + rvy * ny
    vt = rvx * tx + rvy * ty + Ri * y[OM + i]
    fn, ft, gam = contact_law(A, G, delta, ddelta, vt, law.mu, law.k_s)
    return -fn * nx + ft * tx, -fn * ny + ft * ty, Ri * ft, gam * ddelta * ddelta, -ft * vt


@njit(cache=True, inline="always")
def wall_contact(y, model, c, t):
    """Granule-wall candidate c at time t: (touching, fx, fy, torque on the granule, viscous and
    friction power), by `one_sided_force` against the wall where `laws.wall_motion` puts it (its
    overlap grows by the wall's displacement s, the granule's velocity is taken relative to the
    wall's, s' n). The one law of `rhs` and `wall_forces`."""
    walls, radius = model.walls, model.granules.radius
    V = velocity_offset(radius.shape[0])
    i = walls.g[c]
    w = walls.w[c]
    sw = vw = 0.0
    if walls.drive[w, 1] > 0.0:  # a wall at rest skips its motion (docs/performance.md, "A regression")
        sw, vw = wall_motion(walls.drive[w], t)
    delta = wall_overlap(y, i, w, radius, walls) + sw
    if delta <= 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0
    nx, ny = walls.normal[w, 0], walls.normal[w, 1]
    fx, fy, tq, pv, pf = one_sided_force(y, radius, i, -nx, -ny, delta, y[V + 2 * i] - vw * nx, y[V + 2 * i + 1] - vw * ny,
                                         walls.A[c], walls.G[c], model.law)
    return True, fx, fy, tq, pv, pf


@njit(cache=True, inline="always")
def _one_sided(dy, y, radius, i, nx, ny, delta, rvx, rvy, A, G, law):
    """`one_sided_force` added to granule i's derivative; returns the (viscous, friction) power."""
    V = velocity_offset(radius.shape[0])
    fx, fy, tq, pv, pf = one_sided_force(y, radius, i, nx, ny, delta, rvx, rvy, A, G, law)
    dy[V + 2 * i] += fx
    dy[V + 2 * i + 1] += fy
    dy[spin_offset(radius.shape[0]) + i] += tq
    return pv, pf


@njit(cache=True, inline="always")
def load_value(loads, e, t):
    """F(t) of applied load e (`laws.load_force` with its parameters and table)."""
    lo, hi = loads.offset[e], loads.offset[e + 1]
    return load_force(loads.kind[e], loads.params[e], loads.tab_t[lo:hi], loads.tab_v[lo:hi], t)


@njit(cache=True)
def rhs(t, y, dy, model, motion, tau):
    """dy/dt of the augmented state at time t, eq. (1); `tau` is the time since the step's start
    (it positions the solid contact points, eq. A3)."""
    gr = model.granules
    radius = gr.radius
    n = radius.shape[0]
    TH = theta_offset(n)
    V = velocity_offset(n)
    OM = spin_offset(n)
    for k in range(ledger_offset(n) + LEDGER_SIZE):
        dy[k] = 0.0
    for i in range(n):
        dy[2 * i] = y[V + 2 * i]
        dy[2 * i + 1] = y[V + 2 * i + 1]
        dy[TH + i] = y[OM + i]
    p_visc = 0.0
    p_fric = 0.0
    pairs = model.pairs
    law = model.law
    for c in range(pairs.i.shape[0]):  # granule-granule, eqs. (2)-(6)
        i = pairs.i[c]
        j = pairs.j[c]
        dx, dyy, dist, delta = pair_overlap(y, i, j, radius)
        if delta <= 0.0:
            continue
        nx = dx / dist
        ny = dyy / dist
        tx = -ny
        ty = nx
        rvx = y[V + 2 * i] - y[V + 2 * j]
        rvy = y[V + 2 * i + 1] - y[V + 2 * j + 1]
        ddelta = rvx * nx + rvy * ny
        vt = rvx * tx + rvy * ty + radius[i] * y[OM + i] + radius[j] * y[OM + j]
        fn, ft, gam = contact_law(pairs.A[c], pairs.G[c], delta, ddelta, vt, law.mu, law.k_s)
        fx = -fn * nx + ft * tx
        fy = -fn * ny + ft * ty
        dy[V + 2 * i] += fx
        dy[V + 2 * i + 1] += fy
        dy[V + 2 * j] -= fx
        dy[V + 2 * j + 1] -= fy
        dy[OM + i] += radius[i] * ft
        dy[OM + j] += radius[j] * ft
        p_visc += gam * ddelta * ddelta
        p_fric -= ft * vt
    walls = model.walls
    p_in = 0.0
    for c in range(walls.g.shape[0]):  # granule-rigid wall (at rest, or moving: `wall_contact`)
        touching, fx, fy, tq, pv, pf = wall_contact(y, model, c, t)
        if not touching:
            continue
        i = walls.g[c]
        dy[V + 2 * i] += fx
        dy[V + 2 * i + 1] += fy
        dy[OM + i] += tq
        if walls.drive[walls.w[c], 1] > 0.0:  # a moving wall's contact is a load: its power is input work
            p_in += fx * y[V + 2 * i] + fy * y[V + 2 * i + 1] + tq * y[OM + i]
        else:
            p_visc += pv
            p_fric += pf
    points = model.points
    for c in range(points.g.shape[0]):  # granule-solid contact points (moving, fixed normal)
        i = points.g[c]
        ux, uy, wx, wy = motion_at(motion, c, tau)
        delta = point_overlap(y, i, c, radius, points, ux, uy)
        if delta <= 0.0:
            continue
        pv, pf = _one_sided(dy, y, radius, i, points.n[c, 0], points.n[c, 1], delta, y[V + 2 * i] - wx, y[V + 2 * i + 1] - wy,
                            points.A[c], points.G[c], law)
        p_visc += pv
        p_fric += pf
    loads = model.loads
    for e in range(loads.g.shape[0]):  # applied forces
        i = loads.g[e]
        f = load_value(loads, e, t)
        fx = f * loads.direction[e, 0]
        fy = f * loads.direction[e, 1]
        dy[V + 2 * i] += fx
        dy[V + 2 * i + 1] += fy
        p_in += fx * y[V + 2 * i] + fy * y[V + 2 * i + 1]
    for i in range(n):  # weights (a potential: not input work, `gravity_energy`), then forces -> accelerations
        dy[V + 2 * i] += gr.weight[i, 0]
        dy[V + 2 * i + 1] += gr.weight[i, 1]
        dy[V + 2 * i] /= gr.mass[i]
        dy[V + 2 * i + 1] /= gr.mass[i]
        dy[OM + i] /= gr.inertia[i]
    acc = ledger_offset(n)
    dy[acc + ACC_VISC] = p_visc
    dy[acc + ACC_FRIC] = p_fric
    dy[acc + ACC_WORK] = p_in


# ---------------------------------------------------------------- RK4


@njit(cache=True)
def rk4_step(y, t, h, model, motion, tau0, work, k1_known=False):
    """One classical RK4 step of size h from time t, in place; the contact points sit at tau0 + s
    into the coupled step (A3). `work` is (5, len(y)) scratch; with `k1_known`, work[0] already
    holds the derivative at the start (first same as last). Returns False if y is not finite."""
    m = y.shape[0]
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    h2 = 0.5 * h
    if not k1_known:
        rhs(t, y, k1, model, motion, tau0)
    for k in range(m):
        tmp[k] = y[k] + h2 * k1[k]
    rhs(t + h2, tmp, k2, model, motion, tau0 + h2)
    for k in range(m):
        tmp[k] = y[k] + h2 * k2[k]
    rhs(t + h2, tmp, k3, model, motion, tau0 + h2)
    for k in range(m):
        tmp[k] = y[k] + h * k3[k]
    rhs(t + h, tmp, k4, model, motion, tau0 + h)
    finite = True
    for k in range(m):
        y[k] += h / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])
        if not math.isfinite(y[k]):
            finite = False
    return finite


@njit(cache=True)
def overlaps(y, model, su):
    """Overlaps of every candidate contact (pairs, walls, solid points displaced by su), eq. (2);
    <= 0 where the bodies do not touch."""
    radius = model.granules.radius
    pairs, walls, points = model.pairs, model.walls, model.points
    dp = np.empty(pairs.i.shape[0])
    for c in range(dp.shape[0]):
        dp[c] = pair_overlap(y, pairs.i[c], pairs.j[c], radius)[3]
    dw = np.empty(walls.g.shape[0])
    for c in range(dw.shape[0]):
        dw[c] = wall_overlap(y, walls.g[c], walls.w[c], radius, walls)
    ds = np.empty(points.g.shape[0])
    for c in range(ds.shape[0]):
        ds[c] = point_overlap(y, points.g[c], c, radius, points, su[c, 0], su[c, 1])
    return dp, dw, ds


# classical RK4 is stable for a decay rate r with r h below 2.785 (its real-axis limit)
RK4_REAL_LIMIT = 2.785
# a step's sub-steps keep rate h below this, inside RK4_REAL_LIMIT
SUBSTEP_RATE_STEP = 2.0
# the friction's rate at a step's start, times this margin, stands for its largest within the
# step (the contact forces may grow over it)
FRICTION_MARGIN = 1.5


@njit(cache=True)
def friction_rate(y, model, motion):
    """The largest decay rate of relative sliding in the tanh law's viscous regime,
    mu k_s |N| / m_eff with 1/m_eff = sum 1/m + R^2/I over the bodies in contact [1/s] (eq. 5),
    times FRICTION_MARGIN: the rate the RK4 sub-steps must follow (`friction_substeps`). The
    solid points sit at the step's start."""
    gr = model.granules
    radius, mass, inertia = gr.radius, gr.mass, gr.inertia
    muk = model.law.mu * model.law.k_s
    dp, dw, ds = overlaps(y, model, motion.u0)
    one = 1.0 / mass + radius**2 / inertia  # per granule: 1/m + R^2/I
    rate = 0.0
    for c in range(dp.shape[0]):
        if dp[c] > 0.0:
            inv = one[model.pairs.i[c]] + one[model.pairs.j[c]]
            rate = max(rate, muk * hertz_force(model.pairs.A[c], dp[c]) * inv)
    for c in range(dw.shape[0]):
        if dw[c] > 0.0:
            rate = max(rate, muk * hertz_force(model.walls.A[c], dw[c]) * one[model.walls.g[c]])
    for c in range(ds.shape[0]):
        if ds[c] > 0.0:
            rate = max(rate, muk * hertz_force(model.points.A[c], ds[c]) * one[model.points.g[c]])
    return FRICTION_MARGIN * rate


@njit(cache=True, inline="always")
def friction_substeps(rate, h):
    """The RK4 sub-steps of a step h under the friction's `rate`: ceil(rate h / SUBSTEP_RATE_STEP),
    at least 1."""
    return max(1, int(math.ceil(rate * h / SUBSTEP_RATE_STEP)))


@njit(cache=True)
def rk4_substepped(y, t, h, model, motion, rate, work):
    """One step of size h as m RK4 sub-steps, m = `friction_substeps` (1 unless the friction is
    stiff), with the contact points' motion (A3) carried across the sub-steps. Returns m, or -1
    if the state stopped being finite."""
    m = friction_substeps(rate, h)
    s = h / m
    for k in range(m):
        # a typed flag, not a literal: one compiled signature of rk4_step
        if not rk4_step(y, t + k * s, s, model, motion, k * s, work, np.bool_(False)):
            return -1
    return m


@njit(cache=True)
def rk4_advance(y, t, h, nsteps, model, motion, ref_pos, max_disp, substep):
    """Advance y in place by up to `nsteps` RK4 steps of size h (each split into sub-steps where
    the friction is stiff if `substep`). The contact motion is taken relative to each step's
    start (exact for a rigid solid and for a single coupled step). Stops early, returning the
    steps done, when a granule has moved more than `max_disp` from `ref_pos` (the caller then
    rebuilds the neighbour list); returns -(steps done) - 1 if the state stops being finite."""
    n = model.granules.radius.shape[0]
    work = np.empty((5, y.shape[0]))
    lim2 = max_disp * max_disp
    for s in range(nsteps):
        rate = friction_rate(y, model, motion) if substep else 0.0
        if rk4_substepped(y, t + s * h, h, model, motion, rate, work) < 0:
            return -(s + 1) - 1
        if moved_beyond(y, n, ref_pos, lim2):
            return s + 1
    return nsteps


@njit(cache=True, inline="always")
def moved_beyond(y, n, ref_pos, lim2):
    """True when a granule is farther than sqrt(lim2) from its reference position."""
    for i in range(n):
        ddx = y[2 * i] - ref_pos[i, 0]
        ddy = y[2 * i + 1] - ref_pos[i, 1]
        if ddx * ddx + ddy * ddy > lim2:
            return True
    return False


# ---------------------------------------------------------------- energies and interface forces


@njit(cache=True)
def granule_energies(y, model, su):
    """Per-granule energy of eq. (11): kinetic, rotational and the contact potential share
    (1/5 A delta^(5/2) per granule-granule contact, 2/5 per wall or solid contact); the solid
    contact points displaced by su (nc, 2)."""
    gr = model.granules
    n = gr.radius.shape[0]
    V = velocity_offset(n)
    OM = spin_offset(n)
    kin = np.empty(n)
    rot = np.empty(n)
    pot = np.zeros(n)
    for i in range(n):
        kin[i] = 0.5 * gr.mass[i] * (y[V + 2 * i] ** 2 + y[V + 2 * i + 1] ** 2)
        rot[i] = 0.5 * gr.inertia[i] * y[OM + i] ** 2
    dp, dw, ds = overlaps(y, model, su)
    for c in range(dp.shape[0]):
        if dp[c] > 0.0:
            e = 0.5 * hertz_potential(model.pairs.A[c], dp[c])
            pot[model.pairs.i[c]] += e
            pot[model.pairs.j[c]] += e
    for c in range(dw.shape[0]):  # (a moving wall's contact is a load: its work is input work, `rhs`)
        if dw[c] > 0.0 and model.walls.drive[model.walls.w[c], 1] <= 0.0:
            pot[model.walls.g[c]] += hertz_potential(model.walls.A[c], dw[c])
    for c in range(ds.shape[0]):
        if ds[c] > 0.0:
            pot[model.points.g[c]] += hertz_potential(model.points.A[c], ds[c])
    return kin, rot, pot


@njit(cache=True)
def gravity_energy(y, granules):
    """The granules' gravitational potential energy -sum m g . (x - x_datum) [J], measured from
    their centres as built (zero without gravity)."""
    e = 0.0
    w, d = granules.weight, granules.datum
    for i in range(w.shape[0]):
        e -= w[i, 0] * (y[2 * i] - d[i, 0]) + w[i, 1] * (y[2 * i + 1] - d[i, 1])
    return e


@njit(cache=True)
def wall_forces(y, model, out, t):
    """The force each rigid wall takes from the granules at time t (out (nw, 2), x and y), the
    opposite of the wall contacts' forces on the granules (`wall_contact`, as in `rhs`)."""
    walls = model.walls
    out[:, :] = 0.0
    for c in range(walls.g.shape[0]):
        touching, fx, fy, _, _, _ = wall_contact(y, model, c, t)
        if touching:
            out[walls.w[c], 0] -= fx
            out[walls.w[c], 1] -= fy


@njit(cache=True, inline="always")
def point_kinematics(y, model, c, ux, uy, wx, wy):
    """Contact point c displaced by (ux, uy) and moving at (wx, wy): (granule i, overlap delta,
    n, t = k x n, the granule's velocity relative to the point, v_t of eq. 6)."""
    radius = model.granules.radius
    n = radius.shape[0]
    points = model.points
    i = points.g[c]
    nx, ny = points.n[c, 0], points.n[c, 1]
    tx, ty = -ny, nx
    delta = point_overlap(y, i, c, radius, points, ux, uy)
    rvx = y[velocity_offset(n) + 2 * i] - wx
    rvy = y[velocity_offset(n) + 2 * i + 1] - wy
    return i, delta, nx, ny, tx, ty, rvx, rvy, rvx * tx + rvy * ty + radius[i] * y[spin_offset(n) + i]


@njit(cache=True)
def interface_forces(y, model, u, w, out, derivatives=True):
    """At the solid contact points displaced by u and moving at w (nc, 2): the contact law's forces
    on the solid (eqs. (2), (3), (5); out.F), |N| (out.normal), the relative tangential velocity of
    eq. (6) (out.vrel) and, with `derivatives`, the 2x2 derivatives of each force with respect to
    that point's displacement (out.Du) and velocity (out.Dw), from `contact_law_derivatives` (the
    granules' own sensitivity left out, the paper's Assumption 3)."""
    points = model.points
    mu, k_s = model.law.mu, model.law.k_s
    for c in range(points.g.shape[0]):
        i, delta, nx, ny, tx, ty, rvx, rvy, vt = point_kinematics(y, model, c, u[c, 0], u[c, 1], w[c, 0], w[c, 1])
        out.vrel[c] = vt
        out.F[c, 0] = 0.0
        out.F[c, 1] = 0.0
        out.normal[c] = 0.0
        for a in range(2):
            for b in range(2):
                out.Du[c, a, b] = 0.0
                out.Dw[c, a, b] = 0.0
        if delta <= 0.0:
            continue
        dd = rvx * nx + rvy * ny
        A, G = points.A[c], points.G[c]
        fn, ft, _ = contact_law(A, G, delta, dd, vt, mu, k_s)
        out.F[c, 0] = fn * nx - ft * tx
        out.F[c, 1] = fn * ny - ft * ty
        out.normal[c] = abs(fn)
        if not derivatives:
            continue
        dfn_d, dfn_dd, dft_d, dft_dd, dft_dv = contact_law_derivatives(A, G, delta, dd, vt, mu, k_s)
        # d delta / d u = -n, d ddelta / d w = -n, d vt / d w = -t
        for b in range(2):
            nb = nx if b == 0 else ny
            tb = tx if b == 0 else ty
            fn_u, ft_u = -dfn_d * nb, -dft_d * nb
            fn_w, ft_w = -dfn_dd * nb, -dft_dd * nb - dft_dv * tb
            out.Du[c, 0, b] = nx * fn_u - tx * ft_u
            out.Du[c, 1, b] = ny * fn_u - ty * ft_u
            out.Dw[c, 0, b] = nx * fn_w - tx * ft_w
            out.Dw[c, 1, b] = ny * fn_w - ty * ft_w
