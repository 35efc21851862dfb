"""The per-step modal operators of the exact integrator: each mode's closed-form response to a
force polynomial over the step (`solid.propagation`), seen at the contacts, cached per step size;
and the products between contacts and modes."""

from __future__ import annotations

import numpy as np

from ...guard.jit import njit
from .. import core
from ...solid.propagation import interpolation_taylor, weights_at


@njit(cache=True)
def ensure_ops(cache, solid, slot, h):
    """Fill `cache` slot `slot` for step size h (once per grid level; always for the off-grid slot):
    per unknown node j at tau_j the modes' free response, the contacts' displacement and velocity
    per unit force datum (P diag(disp_b) P', P diag(vel_b) P'), and the basis's integrals; and the
    modes' end weights."""
    if cache.ready[slot]:
        return
    omega, P = solid.omega, solid.P
    nodes = cache.nodes
    nb = nodes.shape[0]
    nr = omega.shape[0]
    T = cache.T[slot]
    interpolation_taylor(nodes, np.zeros(nb, np.int64), h, T)
    disp, vel = np.empty((nr, nb)), np.empty((nr, nb))
    for j in range(nb - 1):
        tau = nodes[j + 1] * h
        weights_at(omega, tau, T, cache.free[slot, j], disp, vel)
        for b in range(nb):
            core.copy2(cache.Cu[slot, j, b], np.dot(P * disp[:, b].copy(), P.T))
            core.copy2(cache.Cw[slot, j, b], np.dot(P * vel[:, b].copy(), P.T))
            i1 = 0.0
            i2 = 0.0
            fact = 1.0
            for k in range(4):  # int_0^tau H_b = sum_k T[b, k] tau^(k+1) / (k+1)!, and the double integral
                fact *= k + 1
                i1 += T[b, k] * tau ** (k + 1) / fact
                i2 += T[b, k] * tau ** (k + 2) / (fact * (k + 2))
            cache.I1[slot, j, b] = i1
            cache.I2[slot, j, b] = i2
    core.copy2(cache.end_disp[slot], disp)  # the last node is the step's end
    core.copy2(cache.end_vel[slot], vel)
    cache.ready[slot] = slot < cache.ready.shape[0] - 1  # the off-grid slot is recomputed each time


@njit(cache=True, fastmath={"reassoc", "nsz", "contract"})
def contacts_of_modes(P, V, out):
    """out[r, k] = sum_i P[r, i] V[k, i]: modal vectors V (K, nr) seen at the contacts, two rows of
    V at a time with P's row read once per pair (sums reassociated, so vectorised)."""
    m2, nr = P.shape
    K = V.shape[0]
    for r in range(m2):
        k = 0
        while k + 1 < K:
            a0 = 0.0
            a1 = 0.0
            for i in range(nr):
                p = P[r, i]
                a0 += p * V[k, i]
                a1 += p * V[k + 1, i]
            out[r, k] = a0
            out[r, k + 1] = a1
            k += 2
        if k < K:
            a0 = 0.0
            for i in range(nr):
                a0 += P[r, i] * V[k, i]
            out[r, k] = a0


@njit(cache=True)
def modes_of_contacts(X, P, out):
    """out[a, i] = sum_r X[a, r] P[r, i]: contact vectors X (A, 2nc) projected on the modes (P'
    applied to each row), accumulated along P's rows."""
    A, m2 = X.shape
    nr = P.shape[1]
    for a in range(A):
        for i in range(nr):
            out[a, i] = 0.0
        for r in range(m2):
            x = X[a, r]
            if x == 0.0:
                continue
            for i in range(nr):
                out[a, i] += x * P[r, i]


@njit(cache=True)
def free_response(state, solid, cache, slot, nodes):
    """The part of the contacts' displacement and velocity at each unknown node that does not
    depend on the unknowns (nodes.u_free, nodes.w_free): P applied to the modes' free response,
    plus the start force's share."""
    nr = state.eta.shape[0]
    m2 = state.u.shape[0]
    nn = cache.nodes.shape[0] - 1
    if nr == 0:
        nodes.u_free[:, :] = 0.0
        nodes.w_free[:, :] = 0.0
        return
    modal = nodes.modal
    for j in range(nn):
        free = cache.free[slot, j]
        for i in range(nr):
            modal[2 * j, i] = free[i, 0] * state.eta[i] + free[i, 1] * state.etad[i]
            modal[2 * j + 1, i] = free[i, 2] * state.eta[i] + free[i, 0] * state.etad[i]
    out = nodes.at_contacts
    contacts_of_modes(solid.P, modal, out)
    for j in range(nn):
        Cu, Cw = cache.Cu[slot, j, 0], cache.Cw[slot, j, 0]
        for r in range(m2):
            u = out[r, 2 * j]
            v = out[r, 2 * j + 1]
            for q in range(m2):
                f0 = state.F[q // 2, q % 2]
                u += Cu[r, q] * f0
                v += Cw[r, q] * f0
            nodes.u_free[j, r] = u
            nodes.w_free[j, r] = v


@njit(cache=True, inline="always")
def propagate_mode(free, disp, vel, i, eta0, etad0, modal_force):
    """Mode i's displacement and velocity after a step (or at a point inside it) from its start
    state and its modal force data (nb, nr), with the weights of `solid.propagation.weights_at`."""
    eta = free[i, 0] * eta0 + free[i, 1] * etad0
    etad = free[i, 2] * eta0 + free[i, 0] * etad0
    for b in range(disp.shape[1]):
        eta += disp[i, b] * modal_force[b, i]
        etad += vel[i, b] * modal_force[b, i]
    return eta, etad
