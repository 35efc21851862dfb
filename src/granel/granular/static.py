"""Static equilibrium of granules pressed by constant loads against each other, rigid walls and a
solid (`simulation.equilibrate`): the state a precompressed medium starts its dynamics from.

At rest the Tsuji damping (eq. 3) and the tanh friction (eq. 5) exert nothing, so equilibrium is
the balance of the Hertz forces (eq. 2) with the constant loads, the solid's contact points
displaced by its static compliance, u = C F_s (C = B K^-1 B'): a stationary point of the
potential energy. A secant predictor, then Newton on the granules' positions and the solid's
displacements, to each granule's round-off bound; docs/narrowband.md has the method and its
measurements. A load that nothing holds has no equilibrium: an error naming the free motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .contact import hertz_force, hertz_overlap, hertz_potential, hertz_stiffness


class NoEquilibrium(ValueError):
    """The loads cannot be balanced (a granule pushed but not held)."""


@dataclass
class Equilibrium:
    pos: np.ndarray  # (n, 2) granule centres at equilibrium
    u: np.ndarray  # (nc, 2) the solid contact points' static displacement
    solid_forces: np.ndarray  # (nc, 2) force on the solid at each contact
    pair_forces: np.ndarray  # (m,) normal force of each loaded granule pair
    pair_overlaps: np.ndarray  # (m,) their overlaps [m]
    pairs: np.ndarray  # (m, 2) the loaded pairs
    wall_forces: np.ndarray  # (k,) normal force of each loaded granule-wall contact
    wall_overlaps: np.ndarray
    walls: np.ndarray  # (k, 2): granule, wall
    iterations: int
    residual: float  # the largest force imbalance on a granule [N]
    tolerance: float = 0.0  # the largest granule's round-off bound it was held to [N]

    @property
    def max_overlap(self) -> float:
        return float(max(self.pair_overlaps.max(initial=0.0), self.wall_overlaps.max(initial=0.0)))

    def contacts(self, labels: list[str], wall_names: list[str]) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Every loaded contact: its name ('C:1-C:2', a granule and a wall 'C:20|far', a solid
        contact 'C:3|solid'), its normal force [N] and its overlap [m] (the solid's: its force only,
        overlap NaN)."""
        names = [f"{labels[i]}-{labels[j]}" for i, j in self.pairs] + \
            [f"{labels[g]}|{wall_names[w]}" for g, w in self.walls]
        force = np.concatenate([self.pair_forces, self.wall_forces])
        overlap = np.concatenate([self.pair_overlaps, self.wall_overlaps])
        return names, force, overlap

    def summary(self) -> dict:
        """Numbers for the run's attributes and summary."""
        fs = np.hypot(*self.solid_forces.T) if len(self.solid_forces) else np.zeros(0)
        return {"equilibrium_iterations": int(self.iterations), "equilibrium_residual_N": float(self.residual),
                "equilibrium_tolerance_N": float(self.tolerance),
                "equilibrium_loaded_pairs": int(len(self.pairs)), "equilibrium_loaded_walls": int(len(self.walls)),
                "equilibrium_max_overlap_m": self.max_overlap,
                "equilibrium_max_pair_force_N": float(self.pair_forces.max(initial=0.0)),
                "equilibrium_max_wall_force_N": float(self.wall_forces.max(initial=0.0)),
                "equilibrium_max_solid_force_N": float(fs.max(initial=0.0))}


def constant_loads(system) -> np.ndarray:
    """(n, 2): the constant excitations (preloads) and the weight on each granule."""
    F = system.weights.copy()
    for e in system.excitations:
        if e.history.static:
            d = np.asarray(e.direction, float)
            F[e.granule] += e.history.preload * d / np.hypot(*d)
    return F


def hertz_force_stiffness(A, delta):
    """Force and stiffness (`contact.hertz_force`, `hertz_stiffness`, eq. 2) of contacts at
    overlaps delta (arrays; none where delta <= 0)."""
    d = np.maximum(delta, 0.0)
    return hertz_force.py_func(A, d), hertz_stiffness.py_func(A, d)


def _outer(n):
    """n n' for rows of unit vectors n (m, 2): (m, 2, 2)."""
    return n[:, :, None] * n[:, None, :]


def _blocks(rows, cols, blocks, shape):
    """A sparse matrix from 2x2 blocks at block rows / columns (granule or contact indices)."""
    r = (2 * rows[:, None, None] + np.arange(2)[None, :, None]).repeat(2, axis=2)
    c = (2 * cols[:, None, None] + np.arange(2)[None, None, :]).repeat(2, axis=1)
    return sp.coo_matrix((blocks.ravel(), (r.ravel(), c.ravel())), shape=shape)


# Round-offs a contact's overlap accumulates at the magnitude of its coordinates: the difference of
# two positions and R_i + R_j - |d| (or the wall's, or the solid point's, projections), each one
# ulp of the largest operand; the force's share is k times that, plus an ulp of the force itself.
OVERLAP_ROUNDINGS = 2.0
# the largest move of a granule in one Newton step, as a share of its radius: the overlap limit
# of a run (simulation.overlap_limit's default). A longer step, on the tangent stiffness of contacts
# that barely touch, can carry a granule through its neighbours to where their contacts push it on,
# which lowers the energy without end
STEP_LIMIT = 0.1
# halvings of a Newton step tried before the shift grows (measured: a 9,950-granule packing under
# gravity took 25 factorisations without them; a step that fails as a whole usually succeeds at
# half or a quarter of its length, where a contact it would open or close is not yet crossed)
BACKTRACKS = 3
# a contact whose gap is below this share of its radius is touching: the predictor gives it the
# secant stiffness of the load (a packing written to a few digits touches only to those digits)
TOUCHING = 1e-6
EPS = float(np.finfo(float).eps)


@dataclass
class Forces:
    """The balance at one configuration: the net force on each granule F (n, 2) and on the solid's
    contact points Fs (nc, 2), the stiffness blocks K = (-dF/dx, -dF/du, dFs/dx, dFs/du), the
    loaded pairs and walls (indices, forces, overlaps), each granule's round-off bound (n,): how
    far its computed F may be from the exact one [N] (and each contact point's), and the potential energy of the contacts and
    the loads (from the initial positions) with its own round-off bound [J]."""

    F: np.ndarray
    Fs: np.ndarray
    K: tuple
    pairs: tuple
    walls: tuple
    roundoff: np.ndarray
    roundoff_s: np.ndarray  # (nc,): the same bound for the force on each solid contact point
    energy: float = 0.0
    energy_roundoff: float = 0.0


class _Balance:
    """The net forces on the granules and on the solid's contact points, and their derivatives, at
    positions x (n, 2) and contact displacements u (nc, 2). With `secant` (a force [N]) every
    touching contact gets, in place of its tangent stiffness, the secant stiffness a Hertz contact
    has under that force, A^(2/3) F^(1/3), and no turn of its normal: the linear predictor."""

    def __init__(self, system, model, loads):
        self.system, self.model, self.loads = system, model, loads
        self.n, self.nc = system.n, len(system.solid_contacts)

    def __call__(self, x, u, secant: float | None = None) -> Forces:
        n, nc, m = self.n, self.nc, self.model
        R = self.system.radius
        F = self.loads.copy()
        Fs = np.zeros((nc, 2))
        err = np.zeros(n)  # each granule's sum of k |coordinates| + |f| over its contacts
        work = self.loads * (x - self.system.pos0)
        energy = [-work.sum()]
        size = [np.abs(work).sum()]  # the terms' magnitudes, for the energy's round-off
        Kxx, Kxu, Ksx, Ksu = [], [], [], []  # -dF/dx, -dF/du, dFs/dx, dFs/du as 2x2 blocks

        def stiffness(A, delta, k, size):
            if secant is None:
                return k
            return np.where(delta > -TOUCHING * size, A ** (2 / 3) * secant ** (1 / 3), 0.0)

        # granule pairs: the force on j is +f n, n from i to j
        i, j, A = m.pairs.i, m.pairs.j, m.pairs.A
        d = x[j] - x[i]
        dist = np.hypot(*d.T)
        R_contact = np.minimum(R[i], R[j])
        on = R[i] + R[j] - dist > (-TOUCHING * R_contact if secant is not None else 0.0)
        i, j, A, d, dist, R_contact = i[on], j[on], A[on], d[on], dist[on], R_contact[on]
        nrm = d / dist[:, None]
        delta = R[i] + R[j] - dist
        f, k = hertz_force_stiffness(A, delta)
        k = stiffness(A, delta, k, R_contact)
        self._energy(A, delta, f, x[i], energy, size)
        np.add.at(F, j, f[:, None] * nrm)
        np.add.at(F, i, -f[:, None] * nrm)
        e = k * (np.abs(x[i]).max(axis=1) + np.abs(x[j]).max(axis=1) + R[i] + R[j]) + f
        np.add.at(err, i, e)
        np.add.at(err, j, e)
        eye = np.eye(2)[None]
        turn = 0.0 if secant is not None else (f / dist)[:, None, None]
        S = k[:, None, None] * _outer(nrm) - turn * (eye - _outer(nrm))  # -dF_j/dx_j
        Kxx += [(j, j, S), (i, i, S), (j, i, -S), (i, j, -S)]
        loaded = f > 0
        pair_data = (np.stack([i, j], axis=1)[loaded], f[loaded], delta[loaded])
        # walls: the force on the granule is +f n_w
        g, w, A = m.walls.g, m.walls.w, m.walls.A
        rel = x[g] - m.walls.p0[w]
        along = np.einsum("ki,ki->k", rel, m.walls.tangent[w])
        delta = R[g] - np.einsum("ki,ki->k", rel, m.walls.normal[w])
        R_contact = R[g]
        on = (delta > (-TOUCHING * R_contact if secant is not None else 0.0)) & (along >= 0) & (along <= m.walls.length[w])
        g, w, A, delta, R_contact = g[on], w[on], A[on], delta[on], R_contact[on]
        nw = m.walls.normal[w]
        f, k = hertz_force_stiffness(A, delta)
        k = stiffness(A, delta, k, R_contact)
        self._energy(A, delta, f, x[g], energy, size)
        np.add.at(F, g, f[:, None] * nw)
        np.add.at(err, g, k * (np.abs(x[g]).max(axis=1) + np.abs(m.walls.p0[w]).max(axis=1) + R[g]) + f)
        Kxx.append((g, g, k[:, None, None] * _outer(nw)))
        loaded = f > 0
        wall_data = (np.stack([g, w], axis=1)[loaded], f[loaded], delta[loaded])
        # solid points: the force on the granule is -f n_c, on the solid +f n_c
        g, A = m.points.g, m.points.A
        nc_ = m.points.n
        gap = np.einsum("ki,ki->k", m.points.p + u - x[g], nc_)
        delta = R[g] - gap
        R_contact = R[g]
        f, k = hertz_force_stiffness(A, np.where(delta > 0, delta, 0.0))
        k = stiffness(A, delta, k, R_contact)
        self._energy(A, delta, f, x[g], energy, size)
        np.add.at(F, g, -f[:, None] * nc_)
        e_point = k * (np.abs(m.points.p).max(axis=1, initial=0.0) + np.abs(u).max(axis=1, initial=0.0)
                       + np.abs(x[g]).max(axis=1, initial=0.0) + R[g]) + f
        np.add.at(err, g, e_point)
        Fs[:] = f[:, None] * nc_
        kk = k[:, None, None] * _outer(nc_)
        idx = np.arange(len(g))
        Kxx.append((g, g, kk))
        Kxu.append((g, idx, -kk))
        Ksx.append((idx, g, kk))
        Ksu.append((idx, idx, -kk))

        def assemble(parts, shape):
            if not parts:
                return sp.csr_matrix(shape)
            rows = np.concatenate([p[0] for p in parts])
            cols = np.concatenate([p[1] for p in parts])
            return _blocks(rows, cols, np.concatenate([p[2] for p in parts]), shape).tocsr()

        K = (assemble(Kxx, (2 * n, 2 * n)), assemble(Kxu, (2 * n, 2 * nc)), assemble(Ksx, (2 * nc, 2 * n)),
             assemble(Ksu, (2 * nc, 2 * nc)))
        roundoff = EPS * (OVERLAP_ROUNDINGS * err + np.abs(self.loads).max(axis=1, initial=0.0))
        return Forces(F=F, Fs=Fs, K=K, pairs=pair_data, walls=wall_data, roundoff=roundoff,
                      roundoff_s=EPS * OVERLAP_ROUNDINGS * e_point,
                      energy=float(sum(e.sum() for e in energy)),
                      energy_roundoff=EPS * float(sum(np.sum(e) for e in size)))

    @staticmethod
    def _energy(A, delta, f, x, energy, size):
        """Append the Hertz potential of contacts at overlaps delta (forces f, at coordinates x) and
        its round-off scale: an ulp of the energy and the force times the overlap's round-off."""
        e = hertz_potential.py_func(A, np.maximum(delta, 0.0))
        energy.append(e)
        size.append(e + OVERLAP_ROUNDINGS * f * np.abs(x).max(axis=1, initial=0.0))


@dataclass
class _Trial:
    """A configuration Newton may move to: its balance, the net forces on the solid's contact
    points G, the imbalance beyond round-off (`merit`, zero at equilibrium), and the potential
    energy with its round-off."""

    balance: Forces
    G: np.ndarray
    merit: float
    energy: float
    noise: float

    def improves(self, now: "_Trial") -> bool:
        """Lower energy beyond both round-offs (the potential is smooth, and along a step shifted
        enough it falls); within them, where the energy no longer tells, a smaller imbalance."""
        gap = self.noise + now.noise
        if self.energy < now.energy - gap:
            return True
        return self.energy <= now.energy + gap and self.merit < now.merit


class NotConverged(ValueError):
    """Newton found no equilibrium although nothing in the medium is free to move."""


def equilibrium(system, model, compliance=None, max_iterations: int = 200) -> Equilibrium:
    """The positions where the constant loads balance the contacts (and the solid's static
    compliance `compliance` (2nc, 2nc) at its contact points, None for a rigid solid), from the
    system's initial positions; `model` is the kernels' bundle of candidate contacts there.

    A linear predictor (each touching contact a spring of the secant stiffness of the largest load)
    puts every contact on the load's paths near its overlap at once; Newton with the tangent
    stiffness, shifted as little as needed (Levenberg-Marquardt) and accepting only steps that
    lower the imbalance, then converges. It stops when every granule's imbalance is within its
    round-off bound (`Forces.roundoff`). NoEquilibrium names the granules and the direction of a
    free motion the loads push along; NotConverged says Newton failed on a medium that is held."""
    n, nc = system.n, len(system.solid_contacts)
    loads = constant_loads(system)
    balance = _Balance(system, model, loads)
    elastic = compliance is not None and nc > 0 and np.any(compliance)
    # The solid in the eigenbasis of its compliance: u = V w, with C = V diag(c) V' over the
    # directions it yields in (an eigenvalue above the rank tolerance of a symmetric eigensolve,
    # 2 nc ulps of the largest); along the others (a beam's axis) it holds rigidly. The contact
    # points then carry the net force G = V' Fs - w / c, and Newton's matrix is the symmetric
    # Hessian of the potential energy, along whose shifted steps the energy falls.
    if elastic:
        c, V = np.linalg.eigh(0.5 * (compliance + compliance.T))
        keep = c > 2 * nc * EPS * c.max()
        c, V = c[keep], V[:, keep]
    else:
        c, V = np.ones(0), np.zeros((2 * nc, 0))
    x, w = system.pos0.astype(float).copy(), np.zeros(len(c))
    # the largest force a contact may carry: the largest load, or all of them together (a column's
    # weight rests on its lowest contact)
    scale = max(np.hypot(*loads.T).max(initial=0.0), float(np.hypot(*loads.sum(axis=0))), 1e-300)
    # the stiffness of a contact under the largest load: the scale of the Levenberg-Marquardt shift
    A_ref = np.concatenate([model.pairs.A, model.walls.A, model.points.A]).max(initial=1.0)
    k_ref = hertz_stiffness.py_func(A_ref, hertz_overlap(scale, A_ref))

    def displacement(w):
        return (V @ w).reshape(nc, 2)

    def residual(x, w) -> _Trial:
        """The balance, the net force along each of the solid's directions (V' Fs - w / c), the
        imbalance beyond round-off (per granule and per direction, so that noise within one
        granule's bound never hides a real imbalance on another), and the potential energy."""
        b = balance(x, displacement(w))
        excess = np.maximum(np.abs(b.F).max(axis=1, initial=0.0) - b.roundoff, 0.0)
        if not elastic:
            return _Trial(b, np.zeros(0), float(np.sqrt(np.sum(excess * excess))), b.energy, b.energy_roundoff)
        G = V.T @ b.Fs.ravel() - w / c
        # a dot product of 2 nc terms is good to 2 nc ulps of the sum of its terms' magnitudes
        bound = np.abs(V.T) @ (np.repeat(b.roundoff_s, 2) + 2 * nc * EPS * np.abs(b.Fs).ravel()) + EPS * np.abs(w / c)
        excess = np.concatenate([excess, np.maximum(np.abs(G) - bound, 0.0)])
        solid = 0.5 * np.sum(w * w / c)
        return _Trial(b, G, float(np.sqrt(np.sum(excess * excess))), b.energy + solid,
                      b.energy_roundoff + OVERLAP_ROUNDINGS * EPS * solid)

    def newton_step(K, F, G, lam):
        Kxx, Kxu, Ksx, Ksu = K
        # Newton on [x, w], shifted by lam: K_xx dx + K_xu V dw = F, (1/c - V' dFs/du V) dw - V' dFs/dx dx = G
        if elastic:
            Vs = sp.csr_matrix(V)
            J = sp.bmat([[Kxx + lam * sp.eye(2 * n), Kxu @ Vs],
                         [-Vs.T @ Ksx, sp.diags(1.0 / c + lam) - Vs.T @ Ksu @ Vs]])
            rhs = np.concatenate([F.ravel(), G])
        else:
            J, rhs = Kxx + lam * sp.eye(2 * n), F.ravel()
        step = splu(sp.csc_matrix(J)).solve(rhs)
        return step[: 2 * n].reshape(n, 2), step[2 * n:]

    now = residual(x, w)
    it = 0
    if now.merit > 0.0:
        # the predictor: one linear solve, every touching contact a spring at the load's secant stiffness
        pred = balance(x, displacement(w), secant=scale)
        dx, dw = newton_step(pred.K, now.balance.F, now.G, 1e-12 * k_ref)
        moved = np.hypot(*dx.T)
        runaway = moved > system.radius  # pushed by a load, held by nothing it touches
        if np.any(runaway):
            raise NoEquilibrium(_free_motion_message(system, np.flatnonzero(runaway), dx))
        # taken whatever it does to the energy: it engages the contacts on the load's paths, whose
        # tangent stiffness (zero while untouched) Newton needs
        x, w = x + dx, w + dw
        now = residual(x, w)
        it = 1
    lam = 1e-9 * k_ref
    while now.merit > 0.0:
        if it >= max_iterations or lam > 1e6 * k_ref:  # out of iterations, or no step lowers anything
            _stalled(system, now.balance, it, k_ref)
        it += 1
        try:
            dx, dw = newton_step(now.balance.K, now.balance.F, now.G, lam)
        except RuntimeError:  # singular even with the shift
            lam = max(100.0 * lam, 1e-6 * k_ref)
            continue
        alpha, trial = _line_search(residual, now, x, w, dx, dw, system.radius)
        if trial is None:
            lam *= 10.0  # no fraction of this step lowers anything: shift further
            continue
        x, w, now = x + alpha * dx, w + alpha * dw, trial
        if alpha == 1.0:
            lam = max(lam / 100.0, 1e-12 * k_ref)
    b = now.balance
    pairs, walls = b.pairs, b.walls
    return Equilibrium(pos=x, u=displacement(w), solid_forces=b.Fs, pair_forces=pairs[1], pair_overlaps=pairs[2], pairs=pairs[0],
                       wall_forces=walls[1], wall_overlaps=walls[2], walls=walls[0], iterations=it,
                       residual=float(np.abs(b.F).max(initial=0.0)),
                       tolerance=float(b.roundoff.max(initial=0.0)))


def _line_search(residual, now, x, w, dx, dw, radius):
    """(alpha, the trial there) of the first step alpha (dx, dw) that lowers the energy
    (`_Trial.improves`): alpha shortened to the trust region (no granule moves more than
    STEP_LIMIT of its radius, so none passes through its neighbours), then halved up to BACKTRACKS
    times, residuals only (each far cheaper than a factorisation); (0, None) when none does."""
    longest = np.max(np.hypot(*dx.T) / radius, initial=0.0)
    alpha = min(1.0, STEP_LIMIT / longest) if longest > 0 else 1.0
    for _ in range(BACKTRACKS + 1):
        trial = residual(x + alpha * dx, w + alpha * dw)
        if trial.improves(now):
            return alpha, trial
        alpha *= 0.5
    return 0.0, None


def _free_motion_message(system, granules, motion) -> str:
    """What a free motion is: the granules it moves (at most six named) and its direction."""
    names = [system.labels[g] for g in granules]
    shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
    d = motion[granules].sum(axis=0)
    d = d / max(np.hypot(*d), 1e-300)
    return (f"no equilibrium: the loads push {shown} along ({d[0]:.3g}, {d[1]:.3g}), and nothing holds "
            f"{'it' if len(names) == 1 else 'them'} that way (a wall, a neighbour or the solid must stop a load; "
            "a frictionless medium slides along a wall)")


def _stalled(system, b: Forces, iterations: int, k_ref: float):
    """Raise the error of a Newton that ran out of iterations: NoEquilibrium with the free motion
    when the stiffness has one that the imbalance pushes along (an eigenvector of a near-zero
    eigenvalue carrying a share of the imbalance), else NotConverged."""
    n = system.n
    K = b.K[0]
    K = 0.5 * (K + K.T)
    F = b.F.ravel()
    try:
        if 2 * n <= 400:
            w, V = np.linalg.eigh(K.toarray())
        else:
            from scipy.sparse.linalg import eigsh

            w, V = eigsh(K.tocsc(), k=min(12, 2 * n - 2), sigma=-1e-6 * k_ref, which="LM")
        soft = np.abs(w) <= 1e-6 * k_ref
        push = np.abs(V.T @ F)
        share = push / max(np.linalg.norm(F), 1e-300)
        free = np.flatnonzero(soft & (share > 0.1))
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        free = np.zeros(0, int)
    if len(free):
        v = V[:, free[np.argmax(share[free])]].reshape(n, 2)
        v = v * np.sign(v.ravel() @ F)
        size = np.hypot(*v.T)
        moving = np.flatnonzero(size >= 0.5 * size.max())
        raise NoEquilibrium(_free_motion_message(system, moving, v))
    worst = int(np.argmax(np.abs(b.F).max(axis=1) / np.maximum(b.roundoff, 1e-300)))
    raise NotConverged(f"the static equilibrium did not converge in {iterations} Newton iterations: granule "
                       f"{system.labels[worst]} is still off balance by {np.abs(b.F[worst]).max():.3e} N, above its "
                       f"round-off bound {b.roundoff[worst]:.3e} N; nothing in the medium is free to move")
