"""Compiled discrete-element kernels: contact forces (eqs. 2-6), RHS of eq. (1), RK4.

State vector layout (n granules), float64:
    y[0:2n]   centre positions, interleaved (x0, y0, x1, y1, ...)
    y[2n:3n]  rotations theta
    y[3n:5n]  velocities, interleaved
    y[5n:6n]  spins omega
    y[6n:6n+3] accumulated viscous dissipation, friction dissipation, input work (all >= 0 for
              the first two), so that RK4 integrates the energy balance (13) at its own order.

Three kinds of contacts:
  pairs    granule-granule candidates from the neighbour list (Hertz + Tsuji damping + friction)
  walls    granule-rigid wall candidates (m* = m: damped)
  solid    granule-solid contact points with a prescribed, quadratic-in-time motion inside a step
           (constant average acceleration, eq. A3); m* = 0 there, so no viscous damping.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

ACC_VISC, ACC_FRIC, ACC_WORK = 0, 1, 2


@njit(cache=True, inline="always")
def pair_overlap(y, i, j, radius):
    """(dx, dy, distance, overlap delta) of granules i and j (positions at the start of y)."""
    dx = y[2 * j] - y[2 * i]
    dyy = y[2 * j + 1] - y[2 * i + 1]
    dist = math.sqrt(dx * dx + dyy * dyy)
    return dx, dyy, dist, radius[i] + radius[j] - dist


@njit(cache=True, inline="always")
def wall_overlap(y, i, w, radius, wall_p0, wall_dir, wall_len, wall_n):
    """Overlap of granule i with wall segment w; -1 when its centre projects outside the segment."""
    rx = y[2 * i] - wall_p0[w, 0]
    ry = y[2 * i + 1] - wall_p0[w, 1]
    along = rx * wall_dir[w, 0] + ry * wall_dir[w, 1]
    if along < 0.0 or along > wall_len[w]:
        return -1.0
    return radius[i] - (rx * wall_n[w, 0] + ry * wall_n[w, 1])


@njit(cache=True, inline="always")
def point_overlap(y, i, c, radius, sp, sn, ux, uy):
    """Overlap of granule i with the flat solid contact point c displaced by (ux, uy)."""
    gap = (sp[c, 0] + ux - y[2 * i]) * sn[c, 0] + (sp[c, 1] + uy - y[2 * i + 1]) * sn[c, 1]
    return radius[i] - gap


@njit(cache=True, inline="always")
def contact_law(A, G, delta, ddelta, vt, mu, k_s):
    """Eqs. (2), (3), (5): normal force magnitude fn (repulsive > 0), tangential force ft along
    t, and the damping coefficient gamma, for overlap delta > 0, overlap rate ddelta and relative
    tangential velocity vt."""
    gam = G * math.sqrt(math.sqrt(delta))
    fn = A * delta * math.sqrt(delta) + gam * ddelta
    ft = -mu * abs(fn) * math.tanh(k_s * vt)
    return fn, ft, gam


@njit(cache=True, inline="always")
def _one_sided(dy, i, V, OM, nx, ny, delta, rvx, rvy, Ri, wi, A, G, mu, k_s):
    """Forces and torque on granule i from a flat partner (wall or solid point) along n_ik =
    (nx, ny), given its velocity relative to the partner; returns (viscous, friction) power lost."""
    tx = -ny
    ty = nx
    ddelta = rvx * nx + rvy * ny
    vt = rvx * tx + rvy * ty + Ri * wi
    fn, ft, gam = contact_law(A, G, delta, ddelta, vt, mu, k_s)
    dy[V + 2 * i] += -fn * nx + ft * tx
    dy[V + 2 * i + 1] += -fn * ny + ft * ty
    dy[OM + i] += Ri * ft
    return gam * ddelta * ddelta, -ft * vt


@njit(cache=True, inline="always")
def _excitation_value(kind, par, tab_t, tab_v, t0, t1, t):
    if kind == 0:  # half-sine: fmax, tau, t0
        s = t - par[2]
        if s < 0.0 or s > par[1]:
            return 0.0
        return par[0] * math.sin(math.pi * s / par[1])
    if kind == 1:  # burst: amp, f, t0, cycles
        s = t - par[2]
        if s < 0.0 or s > par[3] / par[1]:
            return 0.0
        return par[0] * math.sin(2.0 * math.pi * par[1] * s)
    if kind == 2:  # table, linear interpolation
        if t1 - t0 < 1 or t < tab_t[t0] or t > tab_t[t1 - 1]:
            return 0.0
        lo = t0
        hi = t1 - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if tab_t[mid] <= t:
                lo = mid
            else:
                hi = mid
        if hi == lo:
            return tab_v[lo]
        w = (t - tab_t[lo]) / (tab_t[hi] - tab_t[lo])
        return tab_v[lo] * (1.0 - w) + tab_v[hi] * w
    return par[0]  # constant


@njit(cache=True)
def rhs(
    t, y, dy, n,
    radius, mass, inertia, mu, k_s,
    pi_, pj_, pA, pG,
    wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, sG, su0, sv0, sa, tau,
    eg, edir, ekind, epar, eoff, tab_t, tab_v,
):
    """dy/dt of the augmented state at time t; `tau` is the time since the step's start
    (it positions the solid contact points, eq. A3)."""
    P = 0
    TH = 2 * n
    V = 3 * n
    OM = 5 * n
    A = 6 * n
    for k in range(6 * n + 3):
        dy[k] = 0.0
    # kinematics
    for i in range(n):
        dy[P + 2 * i] = y[V + 2 * i]
        dy[P + 2 * i + 1] = y[V + 2 * i + 1]
        dy[TH + i] = y[OM + i]
    p_visc = 0.0
    p_fric = 0.0
    # granule-granule contacts, eqs. (2)-(6)
    for c in range(pi_.shape[0]):
        i = pi_[c]
        j = pj_[c]
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
        fn, ft, gam = contact_law(pA[c], pG[c], delta, ddelta, vt, mu, k_s)
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
    # granule-rigid wall contacts
    for c in range(wg.shape[0]):
        i = wg[c]
        w = ww[c]
        delta = wall_overlap(y, i, w, radius, wall_p0, wall_dir, wall_len, wall_n)
        if delta <= 0.0:
            continue
        pv, pf = _one_sided(dy, i, V, OM, -wall_n[w, 0], -wall_n[w, 1], delta, y[V + 2 * i], y[V + 2 * i + 1],
                            radius[i], y[OM + i], wA[c], wG[c], mu, k_s)
        p_visc += pv
        p_fric += pf
    # granule-solid contact points (moving, fixed normal)
    for c in range(sg.shape[0]):
        i = sg[c]
        ux = su0[c, 0] + sv0[c, 0] * tau + 0.5 * sa[c, 0] * tau * tau
        uy = su0[c, 1] + sv0[c, 1] * tau + 0.5 * sa[c, 1] * tau * tau
        wx = sv0[c, 0] + sa[c, 0] * tau
        wy = sv0[c, 1] + sa[c, 1] * tau
        delta = point_overlap(y, i, c, radius, sp, sn, ux, uy)
        if delta <= 0.0:
            continue
        pv, pf = _one_sided(dy, i, V, OM, sn[c, 0], sn[c, 1], delta, y[V + 2 * i] - wx, y[V + 2 * i + 1] - wy,
                            radius[i], y[OM + i], sA[c], sG[c], mu, k_s)
        p_visc += pv
        p_fric += pf
    # applied forces
    p_in = 0.0
    for e in range(eg.shape[0]):
        i = eg[e]
        f = _excitation_value(ekind[e], epar[e], tab_t, tab_v, eoff[e], eoff[e + 1], t)
        fx = f * edir[e, 0]
        fy = f * edir[e, 1]
        dy[V + 2 * i] += fx
        dy[V + 2 * i + 1] += fy
        p_in += fx * y[V + 2 * i] + fy * y[V + 2 * i + 1]
    # forces -> accelerations
    for i in range(n):
        dy[V + 2 * i] /= mass[i]
        dy[V + 2 * i + 1] /= mass[i]
        dy[OM + i] /= inertia[i]
    dy[A + ACC_VISC] = p_visc
    dy[A + ACC_FRIC] = p_fric
    dy[A + ACC_WORK] = p_in


@njit(cache=True)
def rk4_advance(
    y, t, dt, nsteps, n, ref_pos, max_disp,
    radius, mass, inertia, mu, k_s,
    pi_, pj_, pA, pG,
    wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, sG, su0, sv0, sa,
    eg, edir, ekind, epar, eoff, tab_t, tab_v,
):
    """Advance y in place by up to `nsteps` classical RK4 steps of size dt.

    The solid contact motion (su0, sv0, sa) is taken relative to the start of *each* step, which
    is exact for a rigid solid (all zero) and for a single coupled step (nsteps = 1).
    Stops early (returning the number of steps done) when a granule has moved more than
    `max_disp` from `ref_pos`, so that the caller rebuilds the neighbour list, or when the state
    stops being finite (returned as -(steps done) - 1).
    """
    m = y.shape[0]
    k1 = np.empty(m)
    k2 = np.empty(m)
    k3 = np.empty(m)
    k4 = np.empty(m)
    tmp = np.empty(m)
    h2 = 0.5 * dt
    lim2 = max_disp * max_disp
    for s in range(nsteps):
        rhs(t, y, k1, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
            wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0, sv0, sa, 0.0,
            eg, edir, ekind, epar, eoff, tab_t, tab_v)
        for k in range(m):
            tmp[k] = y[k] + h2 * k1[k]
        rhs(t + h2, tmp, k2, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
            wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0, sv0, sa, h2,
            eg, edir, ekind, epar, eoff, tab_t, tab_v)
        for k in range(m):
            tmp[k] = y[k] + h2 * k2[k]
        rhs(t + h2, tmp, k3, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
            wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0, sv0, sa, h2,
            eg, edir, ekind, epar, eoff, tab_t, tab_v)
        for k in range(m):
            tmp[k] = y[k] + dt * k3[k]
        rhs(t + dt, tmp, k4, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
            wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0, sv0, sa, dt,
            eg, edir, ekind, epar, eoff, tab_t, tab_v)
        finite = True
        for k in range(m):
            y[k] += dt / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])
            if not math.isfinite(y[k]):
                finite = False
        t += dt
        if not finite:
            return -(s + 1) - 1
        far = False
        for i in range(n):
            ddx = y[2 * i] - ref_pos[i, 0]
            ddy = y[2 * i + 1] - ref_pos[i, 1]
            if ddx * ddx + ddy * ddy > lim2:
                far = True
                break
        if far:
            return s + 1
    return nsteps


@njit(cache=True)
def solid_contact_state(y, n, radius, mu, k_s, sg, sp, sn, sA, sG, su, sv):
    """At the solid contact points, given their displacement su and velocity sv:
    returns (force on the solid (nc, 2), normal force magnitude |N| (nc,), relative tangential
    velocity (nc,), overlap (nc,))."""
    nc = sg.shape[0]
    force = np.zeros((nc, 2))
    normal = np.zeros(nc)
    vrel = np.zeros(nc)
    over = np.zeros(nc)
    V = 3 * n
    OM = 5 * n
    for c in range(nc):
        i = sg[c]
        nx = sn[c, 0]
        ny = sn[c, 1]
        tx = -ny
        ty = nx
        delta = point_overlap(y, i, c, radius, sp, sn, su[c, 0], su[c, 1])
        rvx = y[V + 2 * i] - sv[c, 0]
        rvy = y[V + 2 * i + 1] - sv[c, 1]
        vt = rvx * tx + rvy * ty + radius[i] * y[OM + i]
        vrel[c] = vt
        over[c] = delta
        if delta <= 0.0:
            continue
        ddelta = rvx * nx + rvy * ny
        fn, ft, _ = contact_law(sA[c], sG[c], delta, ddelta, vt, mu, k_s)
        force[c, 0] = fn * nx - ft * tx
        force[c, 1] = fn * ny - ft * ty
        normal[c] = abs(fn)
    return force, normal, vrel, over


@njit(cache=True)
def granule_energies(
    y, n, radius, mass, inertia,
    pi_, pj_, pA, wg, ww, wA, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, su,
):
    """Per-granule energy of eq. (11): kinetic, rotational and the contact potential share
    (1/5 A delta^(5/2) per granule-granule contact, 2/5 per wall or solid contact)."""
    V = 3 * n
    OM = 5 * n
    kin = np.empty(n)
    rot = np.empty(n)
    pot = np.zeros(n)
    for i in range(n):
        kin[i] = 0.5 * mass[i] * (y[V + 2 * i] ** 2 + y[V + 2 * i + 1] ** 2)
        rot[i] = 0.5 * inertia[i] * y[OM + i] ** 2
    for c in range(pi_.shape[0]):
        i = pi_[c]
        j = pj_[c]
        delta = pair_overlap(y, i, j, radius)[3]
        if delta > 0.0:
            e = 0.2 * pA[c] * delta * delta * math.sqrt(delta)
            pot[i] += e
            pot[j] += e
    for c in range(wg.shape[0]):
        i = wg[c]
        w = ww[c]
        delta = wall_overlap(y, i, w, radius, wall_p0, wall_dir, wall_len, wall_n)
        if delta > 0.0:
            pot[i] += 0.4 * wA[c] * delta * delta * math.sqrt(delta)
    for c in range(sg.shape[0]):
        i = sg[c]
        delta = point_overlap(y, i, c, radius, sp, sn, su[c, 0], su[c, 1])
        if delta > 0.0:
            pot[i] += 0.4 * sA[c] * delta * delta * math.sqrt(delta)
    return kin, rot, pot


@njit(cache=True)
def friction_rate(y, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
                  wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su):
    """The largest decay rate of relative sliding in the tanh law's viscous regime,
    mu k_s |N| / m_eff with 1/m_eff = sum 1/m + R^2/I over the bodies in contact [1/s].
    RK4 on that mode is stable for rate * dt < 2.78."""
    rate = 0.0
    for c in range(pi_.shape[0]):
        i = pi_[c]
        j = pj_[c]
        delta = pair_overlap(y, i, j, radius)[3]
        if delta > 0.0:
            inv = 1.0 / mass[i] + 1.0 / mass[j] + radius[i] ** 2 / inertia[i] + radius[j] ** 2 / inertia[j]
            r = mu * k_s * pA[c] * delta * math.sqrt(delta) * inv
            if r > rate:
                rate = r
    for c in range(wg.shape[0]):
        i = wg[c]
        w = ww[c]
        delta = wall_overlap(y, i, w, radius, wall_p0, wall_dir, wall_len, wall_n)
        if delta > 0.0:
            r = mu * k_s * wA[c] * delta * math.sqrt(delta) * (1.0 / mass[i] + radius[i] ** 2 / inertia[i])
            if r > rate:
                rate = r
    for c in range(sg.shape[0]):
        i = sg[c]
        delta = point_overlap(y, i, c, radius, sp, sn, su[c, 0], su[c, 1])
        if delta > 0.0:
            r = mu * k_s * sA[c] * delta * math.sqrt(delta) * (1.0 / mass[i] + radius[i] ** 2 / inertia[i])
            if r > rate:
                rate = r
    return rate


@njit(cache=True)
def rk4_substepped(
    y, t, dt, n, ref_pos, radius, mass, inertia, mu, k_s,
    pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, sG, su0, sv0, sa, eg, edir, ekind, epar, eoff, tab_t, tab_v, rate,
):
    """One step of size dt as m RK4 sub-steps, m = ceil(rate dt / 2) (1 unless the friction is
    stiff), with the contact points' quadratic motion carried across the sub-steps. Returns m."""
    m = max(1, int(math.ceil(rate * dt / 2.0)))
    if m == 1:
        r = rk4_advance(y, t, dt, 1, n, ref_pos, 1e300, radius, mass, inertia, mu, k_s,
                        pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
                        sg, sp, sn, sA, sG, su0, sv0, sa, eg, edir, ekind, epar, eoff, tab_t, tab_v)
        return 1 if r >= 0 else -1
    h = dt / m
    nc = sg.shape[0]
    u = np.empty((nc, 2))
    v = np.empty((nc, 2))
    for k in range(m):
        tau = k * h
        for c in range(nc):
            for d in range(2):
                u[c, d] = su0[c, d] + sv0[c, d] * tau + 0.5 * sa[c, d] * tau * tau
                v[c, d] = sv0[c, d] + sa[c, d] * tau
        r = rk4_advance(y, t + tau, h, 1, n, ref_pos, 1e300, radius, mass, inertia, mu, k_s,
                        pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
                        sg, sp, sn, sA, sG, u, v, sa, eg, edir, ekind, epar, eoff, tab_t, tab_v)
        if r < 0:
            return -1
    return m


@njit(cache=True)
def rk4_advance_substepped(
    y, t, dt, nsteps, n, ref_pos, max_disp, radius, mass, inertia, mu, k_s,
    pi_, pj_, pA, pG, wg, ww, wA, wG, wall_p0, wall_dir, wall_len, wall_n,
    sg, sp, sn, sA, sG, su0, sv0, sa, eg, edir, ekind, epar, eoff, tab_t, tab_v,
):
    """`rk4_advance` with each step split into RK4 sub-steps where the friction is stiff
    (see `rk4_substepped`); same return convention."""
    lim2 = max_disp * max_disp
    for s in range(nsteps):
        rate = 1.5 * friction_rate(y, n, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
                                   wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0)
        r = rk4_substepped(y, t, dt, n, ref_pos, radius, mass, inertia, mu, k_s, pi_, pj_, pA, pG, wg, ww, wA, wG,
                           wall_p0, wall_dir, wall_len, wall_n, sg, sp, sn, sA, sG, su0, sv0, sa,
                           eg, edir, ekind, epar, eoff, tab_t, tab_v, rate)
        t += dt
        if r < 0:
            return -(s + 1) - 1
        for i in range(n):
            ddx = y[2 * i] - ref_pos[i, 0]
            ddy = y[2 * i + 1] - ref_pos[i, 1]
            if ddx * ddx + ddy * ddy > lim2:
                return s + 1
    return nsteps
