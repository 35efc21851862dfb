"""A precompressed chain of a run, linearised about its static state: springs and dashpots from
the contact law of eqs. (2)-(3) differentiated (`linear_chain`), its exact harmonic response
(K + i w C - w^2 M) u = F e_a (`chain_response`), and the band edges of the infinite monatomic or
diatomic chain with its masses and springs (`band_edges`). docs/narrowband.md ("Band measures")
gives the definitions and the band edges' formulas."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..granular.contact import contact_law_derivatives
from ..granular.contact import hertz_overlap
from ..granular.materials import pair_coefficients, point_coefficient, wall_coefficients
from ..io.results import require, require_states

# beads of one mass within this share; springs of one stiffness within this share (the
# equilibrium's residual, 1e-10 of the load, spreads the contacts' forces far less)
SAME_MASS = 1e-9
SAME_STIFFNESS = 1e-6
# a chain bead lies off the line through its ends by at most this share of the smallest radius
STRAIGHT = 1e-3


class ChainError(ValueError):
    """A run without one straight precompressed chain; the message says why."""


@dataclass(frozen=True)
class ChainEnd:
    """What holds one end bead: a wall (its name), the solid ("solid") or nothing (""), with the
    linearised contact's spring [N/m] and dashpot [N s/m] (0 and 0 for a free end)."""

    holder: str = ""
    stiffness: float = 0.0
    damping: float = 0.0

    @property
    def on_solid(self) -> bool:
        return "solid" in self.holder.split(" + ")


@dataclass(frozen=True)
class LinearChain:
    """A precompressed chain linearised about its static state (docs/narrowband.md, "Band
    measures"): its beads end to end (labels and indices in the run), masses, the springs and
    dashpots between neighbours, both ends, and its unit axis (first bead to last)."""

    beads: tuple[str, ...]
    index: tuple[int, ...]
    mass: np.ndarray  # (n,) [kg]
    stiffness: np.ndarray  # (n - 1,) [N/m]
    damping: np.ndarray  # (n - 1,) [N s/m]
    ends: tuple[ChainEnd, ChainEnd]
    axis: tuple[float, float]

    @property
    def n(self) -> int:
        return len(self.beads)

    def position(self, label: str) -> int:
        """The place of bead `label` along the chain; ChainError when it is not a bead."""
        if label not in self.beads:
            raise ChainError(f"granule {label} is not in the chain {self.beads[0]}..{self.beads[-1]}")
        return self.beads.index(label)


@dataclass(frozen=True)
class BandEdges:
    """The band edges of the infinite chain with a chain's masses and springs [Hz]: "monatomic"
    (cut-off,) or "diatomic" (acoustic top, optical bottom, optical top)."""

    kind: str
    edges_hz: tuple[float, ...]
    stiffness: float  # the springs' K [N/m]

    @property
    def top_hz(self) -> float:
        """The highest frequency that propagates: the cut-off, or the optical band's top."""
        return self.edges_hz[-1]


def linear_contact(A: float, G: float, overlap: float) -> tuple[float, float]:
    """(k, c) of a contact at rest at `overlap`: the derivatives of eqs. (2)-(3) in delta and
    d(delta)/dt (`granular.contact.contact_law_derivatives`), k = 3/2 A delta^(1/2), c = G
    delta^(1/4)."""
    k, c, *_ = contact_law_derivatives(float(A), float(G), float(overlap), 0.0, 0.0, 0.0, 0.0)
    return float(k), float(c)


def _split(name: str, left: set, right: set, sep: str):
    """(a, b) with name = a + sep + b, a in left and b in right (labels may hold sep), or None."""
    for p, ch in enumerate(name):
        if ch == sep and name[:p] in left and name[p + 1:] in right:
            return name[:p], name[p + 1:]
    return None


def chain_contacts(ds, system):
    """The precompressed chain of a run from its equilibrium contacts, the solid's contacts at
    the first output included: (beads in order, {(i, j): overlap} of its pairs, {bead: [(holder,
    wall index or -1 for the solid, overlap)]} of its ends). ChainError when the loaded contacts
    are not one chain, or hold a bead away from its ends."""
    labels = [str(g) for g in ds["granule"].values]
    if labels != list(system.labels):
        raise ChainError("the granular system given is not the run's (its granules differ)")
    if "equilibrium_contact" not in ds or not ds.sizes.get("equilibrium_contact", 0):
        raise ChainError("the run has no static precompression (simulation.equilibrate = true with a constant load): "
                         "a chain's bands belong to a precompressed chain")
    index = {lab: k for k, lab in enumerate(labels)}
    walls = [w.name or f"wall {k}" for k, w in enumerate(system.walls)]
    pairs: dict[tuple[int, int], float] = {}
    held: dict[int, list] = {}
    for name, F, d in zip([str(c) for c in ds["equilibrium_contact"].values],
                          np.asarray(ds["equilibrium_force"].values, float),
                          np.asarray(ds["equilibrium_overlap"].values, float)):
        if not (F > 0 and d > 0):
            continue
        on_wall = _split(name, set(index), set(walls), "|")
        if on_wall:
            held.setdefault(index[on_wall[0]], []).append((on_wall[1], walls.index(on_wall[1]), float(d)))
            continue
        pair = _split(name, set(index), set(index), "-")
        if not pair:
            raise ChainError(f"equilibrium contact {name!r} is neither a pair nor a wall contact")
        i, j = index[pair[0]], index[pair[1]]
        pairs[(min(i, j), max(i, j))] = float(d)
    require(ds, ["contact_force_normal"] * bool(ds.sizes.get("contact", 0)), "the chain's analysis")
    if ds.sizes.get("contact", 0):
        for c, F in enumerate(np.asarray(ds["contact_force_normal"].values[0], float)):
            if F > 0:  # pressed on the solid at rest: its overlap from Hertz's law, eq. (2)
                g = int(system.points.g[c])
                held.setdefault(g, []).append(("solid", -1, float(hertz_overlap(F, system.points.A[c]))))
    if not pairs:
        raise ChainError("no pair of granules is pressed at equilibrium: there is no precompressed chain")
    nbrs: dict[int, list[int]] = {}
    for i, j in pairs:
        nbrs.setdefault(i, []).append(j)
        nbrs.setdefault(j, []).append(i)
    crowded = [g for g, ns in nbrs.items() if len(ns) > 2]
    if crowded:
        raise ChainError(f"granule {labels[crowded[0]]} is pressed by {len(nbrs[crowded[0]])} neighbours: the loaded "
                         "contacts form a packing, not a chain")
    ends = [g for g, ns in nbrs.items() if len(ns) == 1]
    if len(ends) != 2:
        raise ChainError("the loaded contacts close a loop: not a chain")
    order = [min(ends, key=lambda g: labels[g])]
    while len(order) < len(nbrs):
        nxt = [g for g in nbrs[order[-1]] if g not in order[-2:]]
        if not nxt:
            break
        order.append(nxt[0])
    if len(order) != len(nbrs) or len(pairs) != len(order) - 1:
        raise ChainError("the loaded contacts form several chains; the bands need one")
    stray = [g for g in held if g not in (order[0], order[-1])]
    if stray:
        raise ChainError(f"granule {labels[stray[0]]} presses on a {held[stray[0]][0][0]} away from the chain's ends")
    return order, pairs, held


def chain_axis(ds, system, order) -> np.ndarray:
    """The unit vector from the chain's first bead to its last at the first output; ChainError
    when a bead lies off that line (by more than STRAIGHT of the smallest radius)."""
    labels = list(system.labels)
    require_states(ds, "the chain's analysis", order)
    x0 = np.column_stack([ds["x"].values[0, order], ds["y"].values[0, order]])
    axis = x0[-1] - x0[0]
    axis /= np.hypot(*axis)
    off = np.abs((x0 - x0[0]) @ np.array([-axis[1], axis[0]]))
    if off.max() > STRAIGHT * system.radius[order].min():
        raise ChainError(f"the chain is not straight ({labels[order[int(np.argmax(off))]]} lies {off.max():.3g} m off "
                         "the line through its ends): the one-dimensional band does not apply")
    return axis


def linear_chain(ds, system) -> LinearChain:
    """The run's precompressed chain linearised about its static state (docs/narrowband.md):
    springs and dashpots of its pairs (eq. 4's E*, R*, m* of the two beads), of its walls
    (`materials.wall_coefficients`: no dashpot at an undamped wall) and of the solid (its
    massless layer: m* = 0, no dashpot; its contact point taken as immovable). ChainError when
    the run has no such chain."""
    order, pairs, held = chain_contacts(ds, system)
    axis = chain_axis(ds, system, order)
    alpha = system.law.alpha_n
    k, c = [], []
    for a, b in zip(order[:-1], order[1:]):
        A, G = pair_coefficients(system.bodies(a), system.bodies(b), alpha)
        kk, cc = linear_contact(A, G, pairs[(min(a, b), max(a, b))])
        k.append(kk)
        c.append(cc)
    ends = []
    for g in (order[0], order[-1]):
        if g not in held:
            ends.append(ChainEnd())
            continue
        kk = cc = 0.0
        for holder, w, d in held[g]:
            if w >= 0:
                A, G = wall_coefficients(system.bodies(g), alpha, system.walls[w].damped)
            else:
                A, G = point_coefficient(system.bodies(g)), 0.0
            dk, dc = linear_contact(A, G, d)
            kk, cc = kk + dk, cc + dc
        ends.append(ChainEnd(" + ".join(h for h, _, _ in held[g]), kk, cc))
    return LinearChain(beads=tuple(system.labels[g] for g in order), index=tuple(int(g) for g in order),
                       mass=np.asarray(system.mass[order], float), stiffness=np.array(k), damping=np.array(c),
                       ends=(ends[0], ends[1]), axis=(float(axis[0]), float(axis[1])))


def chain_matrices(chain: LinearChain) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K, C, M) of the linearised chain (n x n): each link's spring (dashpot) between its two
    beads, each end's on its bead alone, and the beads' masses on the diagonal."""
    n = chain.n
    idx = np.arange(n - 1)

    def assemble(links, ends):
        A = np.zeros((n, n))
        np.add.at(A, (idx, idx), links)
        np.add.at(A, (idx + 1, idx + 1), links)
        A[idx, idx + 1] -= links
        A[idx + 1, idx] -= links
        A[0, 0] += ends[0]
        A[-1, -1] += ends[1]
        return A

    return (assemble(chain.stiffness, [e.stiffness for e in chain.ends]),
            assemble(chain.damping, [e.damping for e in chain.ends]), np.diag(chain.mass))


def dynamic_stiffness(chain: LinearChain, omega: float) -> np.ndarray:
    """D(w) = K + i w C - w^2 M of the linearised chain (`chain_matrices`)."""
    K, C, M = chain_matrices(chain)
    return K + 1j * omega * C - omega * omega * M


@dataclass(frozen=True)
class ChainResponse:
    """The linearised chain's steady response to a unit harmonic force on one bead at one
    frequency: each bead's complex velocity along the axis [m/(N s)] and the force each end's
    holder takes [N/N] (0 at a free end)."""

    frequency: float
    velocity: np.ndarray
    end_force: tuple[complex, complex]


def chain_response(chain: LinearChain, frequency: float, driven: str) -> ChainResponse:
    """The steady response to a unit force at `frequency` [Hz] on bead `driven`, along the axis:
    u = D(w)^-1 e_a (`dynamic_stiffness`), v = i w u; an end's holder takes (k + i w c) u_end."""
    w = 2 * math.pi * frequency
    u = np.linalg.solve(dynamic_stiffness(chain, w), np.eye(chain.n)[chain.position(driven)].astype(complex))
    ends = tuple(complex((e.stiffness + 1j * w * e.damping) * u[g]) for e, g in zip(chain.ends, (0, chain.n - 1)))
    return ChainResponse(frequency, 1j * w * u, ends)


def band_edges(chain: LinearChain) -> BandEdges | None:
    """The infinite chain's band edges with this chain's masses and springs (docs/narrowband.md),
    for a monatomic chain (one mass, one K) or a diatomic one (two masses alternating, one K);
    None for any other."""
    m, k = chain.mass, chain.stiffness
    if chain.n < 2 or np.ptp(k) > SAME_STIFFNESS * k.max():
        return None
    K = float(k.mean())
    if np.ptp(m) <= SAME_MASS * m.max():
        return BandEdges("monatomic", (2 * math.sqrt(K / m.mean()) / (2 * math.pi),), K)
    a, b = m[0::2], m[1::2]
    if chain.n >= 3 and np.ptp(a) <= SAME_MASS * a.max() and np.ptp(b) <= SAME_MASS * b.max():
        heavy, light = max(a.mean(), b.mean()), min(a.mean(), b.mean())
        hz = lambda w2: math.sqrt(w2) / (2 * math.pi)  # noqa: E731
        return BandEdges("diatomic", (hz(2 * K / heavy), hz(2 * K / light), hz(2 * K * (1 / heavy + 1 / light))), K)
    return None
