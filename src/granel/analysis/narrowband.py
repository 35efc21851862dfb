"""Measures of a narrowband (harmonic) response: when it is steady, its amplitudes at the drive
frequency, its harmonics and subharmonics, the period it locks to, and transmissibility and
nonreciprocity.

Signals are sampled on the outputs (t, s). Amplitudes come from a least-squares fit of
c0 + sum_k (a_k cos 2 pi f_k t + b_k sin 2 pi f_k t) over a whole number of the longest period
fitted (a lock-in amplifier's measure: exact for a signal made of those frequencies, and blind to
the others when the window holds whole periods of them). A response is steady when successive
drive periods repeat; it locks to m drive periods when s(t + m T) = s(t) there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np
import scipy.linalg

from ..granular.loads import Harmonic, load_history
from ..io.model import read_record
from ..solid.kinds import is_elastic
from .chain import ChainError, LinearChain, band_edges, chain_matrices, linear_chain
from .signals import damped_modes


@dataclass(frozen=True)
class Drive:
    """A harmonic drive of a run: granule label, frequency [Hz], force amplitude [N], start t0,
    and the periods of its ramp."""

    granule: str
    frequency: float
    amplitude: float
    t0: float
    ramp_cycles: float = 0.0


def drive_of(ds) -> Drive:
    """The (first) harmonic load of a result Dataset (`granular.loads.Harmonic`, from its record)."""
    rec = read_record(ds)
    for e in rec.loads:
        h = load_history(e.kind, e.params)
        if isinstance(h, Harmonic):
            return Drive(rec.labels[e.granule], h.frequency, h.amplitude, h.t0, h.ramp_cycles)
    raise ValueError("the run has no harmonic excitation")


def lock_in(t, s, frequencies, window=None) -> np.ndarray:
    """Complex amplitudes A_k (s ~ c0 + sum Re(A_k e^(2 pi i f_k t))) at `frequencies` by least
    squares over `window` = (t0, t1) (all samples by default); |A_k| is the amplitude."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    if window is not None:
        sel = (t >= window[0] - 1e-12 * abs(window[0])) & (t <= window[1] + 1e-12 * abs(window[1]))
        t, s = t[sel], s[sel]
    f = np.atleast_1d(np.asarray(frequencies, float))
    w = 2 * np.pi * f[None, :] * t[:, None]
    M = np.column_stack([np.ones_like(t), np.cos(w), np.sin(w)])
    c, *_ = np.linalg.lstsq(M, s, rcond=None)
    return c[1: 1 + len(f)] - 1j * c[1 + len(f):]


def steady_window(t, s, period: float, rtol: float = 1e-2, periods: int = 3) -> tuple[float, float] | None:
    """The latest stretch of whole periods at the end of the record over which the response is
    steady: from the first time after which each period's waveform differs from the one before
    by less than `rtol` (RMS of the difference over the RMS of the period) for the rest of the
    record. None if the last `periods` periods are not steady or the record is too short."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    n = int(math.floor((t[-1] - t[0]) / period + 1e-9))
    if n < periods + 1:
        return None
    ends = t[-1] - period * np.arange(n + 1)[::-1]  # period boundaries counted back from the end
    grid = np.linspace(0.0, period, 64, endpoint=False)
    waves = np.array([np.interp(a + grid, t, s) for a in ends[:-1]])
    diff = np.sqrt(np.mean(np.diff(waves, axis=0) ** 2, axis=1))
    size = np.sqrt(np.mean(waves[1:] ** 2, axis=1))
    ok = diff <= rtol * np.maximum(size, 1e-300)
    if not ok[-periods:].all():
        return None
    first = len(ok) - int(np.argmin(ok[::-1])) if not ok.all() else 0
    return float(ends[first]), float(t[-1])


def response_period(t, s, period: float, max_multiple: int = 8, rtol: float = 1e-2, window=None) -> int:
    """The smallest m <= max_multiple with s(t + m T) = s(t) within `rtol` (RMS over the RMS of
    s) over `window` (by default the record after its first 2 max_multiple periods): the response
    locks to m drive periods (1: at the drive period; 2: a period-doubled response). 0 when none
    does (quasi-periodic or chaotic)."""
    t = np.asarray(t, float)
    s = np.asarray(s, float)
    lo, hi = window if window is not None else (t[0] + 2 * max_multiple * period, t[-1])
    for m in range(1, max_multiple + 1):
        a = max(lo, t[0])
        b = hi - m * period
        if b - a < m * period:
            break
        grid = np.linspace(a, b, 400)
        x, y = np.interp(grid, t, s), np.interp(grid + m * period, t, s)
        if np.sqrt(np.mean((y - x) ** 2)) <= rtol * max(np.sqrt(np.mean(x * x)), 1e-300):
            return m
    return 0


def harmonic_amplitudes(t, s, frequency: float, orders=(1, 2, 3), subharmonics=(2, 3), window=None) -> dict:
    """Amplitudes of s at k f (k in `orders`) and at f / m (m in `subharmonics`), fitted together
    over a whole number of periods of the slowest of them ending at the window's end (`window`
    defaults to the whole record). Keys: 'f', '2f', ..., 'f/2', ..."""
    t = np.asarray(t, float)
    lo, hi = window if window is not None else (t[0], t[-1])
    ks = [Fraction(k) for k in orders] + [Fraction(1, m) for m in subharmonics]
    longest = max(1 / (float(k) * frequency) for k in ks)
    span = math.floor((hi - lo) / longest + 1e-9) * longest
    if span <= 0:
        raise ValueError(f"the window ({hi - lo:.3e} s) is shorter than the longest period fitted ({longest:.3e} s)")
    A = lock_in(t, s, [float(k) * frequency for k in ks], (hi - span, hi))
    names = [("f" if k == 1 else f"{k}f") if k.denominator == 1 else f"f/{k.denominator}" for k in ks]
    return {n: float(abs(a)) for n, a in zip(names, A)}


def transmissibility(measured_amplitude: float, driven_amplitude: float) -> float:
    """The measured response's amplitude at the drive frequency over the driven one's (e.g. the
    far wall's force over the drive's force, or a far granule's velocity over the driven one's)."""
    return float(measured_amplitude / driven_amplitude) if driven_amplitude else float("nan")


def nonreciprocity_db(forward, backward):
    """20 log10 of forward over backward transmissibility [dB] (0: reciprocal)."""
    return 20.0 * np.log10(np.asarray(forward, float) / np.asarray(backward, float))


# ---------------------------------------------------------------- a chain's cut-off


class CutoffError(ValueError):
    """A run whose chain cut-off cannot be measured; the message says why."""


@dataclass(frozen=True)
class ChainCutoff:
    """A precompressed chain's band edges measured from a run (`cutoff_frequency`): for a
    monatomic chain its cut-off; for a diatomic one (two masses alternating) its acoustic band's
    top, its optical band's bottom and top, the last being `cutoff_hz`."""

    cutoff_hz: float  # the highest frequency that propagates: f_top / factor
    top_mode_hz: float  # the highest mode's undamped frequency, measured
    top_damping_ratio: float  # its damping ratio, measured
    factor: float  # f_top / cutoff of the linearised chain with these ends
    beads: tuple[str, ...]  # the chain's beads, end to end
    end_stiffness: tuple[float, float]  # each end's wall (or solid) stiffness over the pair stiffness (0: free)
    modes_hz: np.ndarray  # each mode's undamped frequency, measured in its modal coordinate (NaN: not excited)
    window: tuple[float, float]  # the free response analysed [s]
    strain: float  # the largest |delta - delta0| / delta0 of a pair over the record
    spread: float  # |f_top from the window's first 3/4 / f_top - 1|: the fit's own check
    leak: float  # the top mode's coordinate: its second strongest oscillation over the mode's
    kind: str = "monatomic"  # or "diatomic"
    band_edges_hz: tuple[float, ...] = ()  # (cut-off,) or (acoustic top, optical bottom, optical top), measured
    end_shift: float = 0.0  # an end on an elastic solid: |factor with that end free / factor - 1|, else 0


def _chain_matrix(n: int, k_first: float, k_last: float) -> np.ndarray:
    """T = tridiag(-1, 2, -1) with corners 1 + k_first and 1 + k_last: M^-1 K of a monatomic
    chain in units of K / m (see `chain_mode_factors`)."""
    d = np.full(n, 2.0)
    d[0], d[-1] = 1.0 + k_first, 1.0 + k_last
    return np.diag(d) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)


def chain_mode_factors(n: int, k_first: float = 0.0, k_last: float = 0.0) -> np.ndarray:
    """The normal-mode frequencies of a linearised monatomic chain of n beads whose end beads
    also press on walls of stiffness k_first K and k_last K (0: a free end), as fractions of the
    infinite chain's cut-off w_c = 2 sqrt(K / m): sqrt(eig(T) / 4), ascending (`_chain_matrix`).
    Closed forms: a free end and a wall of twice the pair stiffness (a Hertz sphere on a rigid
    wall of its own material) give sin((2j - 1) pi / (4n)), j = 1..n; two free ends
    sin((j - 1) pi / (2n)); walls of the pair stiffness at both ends sin(j pi / (2(n + 1)))."""
    n = int(n)
    if n < 1:
        raise ValueError(f"a chain needs at least one bead, got {n}")
    if n == 1:
        return np.array([math.sqrt(max(k_first + k_last, 0.0) / 4.0)])
    return np.sqrt(np.clip(np.linalg.eigvalsh(_chain_matrix(n, k_first, k_last)), 0.0, None) / 4.0)


# The fit of a chain's free response. Outputs are thinned to about SAMPLES_PER_PERIOD samples a
# period of the chain's highest possible frequency (Gershgorin's bound); each modal coordinate
# is fitted with MODE_ORDER exponentials (its mode, and room for the weak oscillations that leak
# into it: the contacts' harmonics and their coupling to the other modes), which needs
# SAMPLES_PER_EXPONENTIAL samples each; the pencil spans PENCIL samples (8-16 periods of that
# bound, or 2/3 of a shorter record). A coordinate's fit costs about samples x PENCIL^2, and the
# chain's n coordinates n times that: the first MAX_SAMPLES samples are fitted (256 periods of the
# bound, far beyond what the checks ask for), or as many as `min_periods` of the top mode need.
# Neither the order nor the sample budget grows with n: the modal filter, not the fit, separates
# the modes.
SAMPLES_PER_PERIOD = 16.0
MODE_ORDER = 8
SAMPLES_PER_EXPONENTIAL = 8
PENCIL = 256
MAX_SAMPLES = 4096
MAX_LEAK = 0.1  # a coordinate whose second oscillation reaches this share of its mode is not one mode
MIN_SHARE = 1e-6  # the top mode's coordinate below this share (RMS) of the strongest one: not excited


def _chain_modes(chain: LinearChain, top_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(each undamped mode's frequency over `top_hz`, the projections from the beads'
    velocities onto the modal velocities as columns), ascending: K phi = w^2 M phi with phi
    M-orthonormal, so q' = phi' M v. (For one mass m these are sqrt(m) times the unit shapes of
    `_chain_matrix`, whose eigenvalues give `chain_mode_factors`.)"""
    K, _, M = chain_matrices(chain)
    lam, phi = scipy.linalg.eigh(K, M)
    f = np.sqrt(np.clip(lam, 0.0, None)) / (2 * math.pi)
    return f / top_hz, chain.mass[:, None] * phi


def _mode_of(t, q) -> tuple[float, float, float] | None:
    """(undamped frequency, damping ratio, leak) of the strongest oscillation in one modal
    coordinate q(t), by `damped_modes` with MODE_ORDER exponentials; the leak is the next
    strongest oscillation's amplitude over it. None when q holds no oscillation."""
    try:
        modes = damped_modes(t, q, MODE_ORDER, pencil=min(PENCIL, (2 * len(t)) // 3))
    except ValueError:
        return None
    if not len(modes.frequency):
        return None
    rank = np.argsort(modes.strength)[::-1]
    k = int(rank[0])
    leak = float(modes.strength[rank[1]] / modes.strength[k]) if len(rank) > 1 else 0.0
    return float(modes.frequency[k]), float(modes.damping_ratio[k]), leak


def _load_fields(system, what: str = "amplitude") -> str:
    """The scenario fields that set the chain ringing: the transient loads' amplitudes (`what` =
    "amplitude") or durations ("duration")."""
    fields = [f"excitations.{k}.{e.history.size_field if what == 'amplitude' else e.history.length_field}"
              for k, e in enumerate(system.excitations) if not e.history.static]
    fields += [f"the motion of wall {w.name or '?'} ({what})" for w in system.walls if w.drive is not None]
    return ", ".join(fields) or "initial_velocities"


def _free_start(system, t_end: float) -> tuple[float, bool]:
    """(When the run's loads and moving walls have all stopped, constant loads aside: the start
    of the free response; whether any of them acts at all). CutoffError when one lasts to the
    end of the run."""
    start, driven = 0.0, False
    for k, e in enumerate(system.excitations):
        if e.history.static:
            continue
        driven = True
        end = e.history.end_time
        if not end < t_end:
            raise CutoffError(f"excitations.{k} ({e.history.kind}) acts until the end of the run: a cut-off is read from "
                              "the free response after a pulse (give the drive a finite duration, or use a half_sine)")
        start = max(start, end)
    for w in system.walls:
        if w.drive is not None:
            driven = True
            end = w.drive.t0 + w.drive.duration
            if not end < t_end:
                raise CutoffError(f"wall {w.name or '?'} moves until the end of the run: a cut-off is read from the free "
                                  "response (give its motion a finite duration)")
            start = max(start, end)
    return start, driven


def _duration_for(t_first: float, span: float, output_every: float) -> float:
    """The shortest simulation.duration (a whole number of outputs) whose record holds `span`
    seconds after t_first."""
    return math.ceil((t_first + span) / output_every * (1 + 1e-12)) * output_every


def cutoff_frequency(ds, system, min_periods: float = 10.0, max_strain: float = 0.1,
                     rtol: float = 1e-3) -> ChainCutoff:
    """The band edges of a precompressed monatomic or diatomic chain, measured from a run in which
    a transient load sets it ringing: its top mode's frequency in the free response over that
    mode's share of the infinite chain's top band edge (f_c = (1/pi) sqrt(K / m) for a monatomic
    chain, sqrt(2 K (1/m1 + 1/m2)) / 2 pi for a diatomic one). `system` is the run's granular
    system (`analysis.result_model.result_system(ds)`); `min_periods`, `max_strain` and `rtol`
    bound the checks, and CutoffError (a ValueError) says why a run gives no cut-off and what to
    change. docs/design.md ("An inverse problem: a chain's cut-off") gives the method, its checks
    and its bias."""
    chain, edges = _periodic_chain(ds, system)
    order, axis = list(chain.index), np.array(chain.axis)
    n = chain.n
    labels = list(system.labels)
    t = np.asarray(ds["time"].values, float)
    output_every = (t[-1] - t[0]) / max(len(t) - 1, 1)
    # sampling: Gershgorin's bound on the linearised chain's frequencies (rows of M^-1 K)
    K, _, _ = chain_matrices(chain)
    f_bound = math.sqrt(float(np.max(np.abs(K).sum(axis=1) / chain.mass))) / (2 * math.pi)
    factors, project = _chain_modes(chain, edges.top_hz)
    f_expected = factors[-1] * edges.top_hz  # the top mode, linearised: sizes the record only
    need = SAMPLES_PER_EXPONENTIAL * MODE_ORDER
    # the samples fitted: MAX_SAMPLES, or more when min_periods of the top mode need more
    def budget(h):
        return max(MAX_SAMPLES, need + math.ceil(1.25 * min_periods / (f_expected * h)))

    t_sel, V, strain, step = _free_response(ds, system, order, axis, f_bound, max_strain, budget)
    first = float(t_sel[0]) if len(t_sel) else float(t[-1])
    enough = _duration_for(first, max((need - 1) * step, min_periods / f_expected), output_every)
    if len(t_sel) < need:
        raise CutoffError(f"the free response after {first:.3g} s holds {len(t_sel)} usable samples (one every "
                          f"{step:.3g} s); {need} are needed, and {min_periods:g} periods of the top mode (about "
                          f"{f_expected:.4g} Hz): raise simulation.duration to at least {enough:.10g} s")
    if not np.any(V):
        raise CutoffError(f"the chain does not move after its loads end: nothing to measure (raise {_load_fields(system)})")
    Q = V @ project  # the modal coordinates' velocities
    rms = np.sqrt(np.mean(Q * Q, axis=0))
    if not rms[-1] > MIN_SHARE * rms.max():
        raise CutoffError(f"the top mode is not excited (its coordinate holds {rms[-1] / rms.max():.2g} of the strongest "
                          f"mode's): shorten {_load_fields(system, 'duration')} to less than half its period "
                          f"({0.5 / f_expected:.3g} s), on an end bead")
    fits = [_mode_of(t_sel, Q[:, j]) if rms[j] > MIN_SHARE * rms.max() else None for j in range(n)]
    if fits[-1] is None:
        raise CutoffError(f"no oscillation found in the top mode's coordinate: raise {_load_fields(system)} above the "
                          "round-off of the chain's motion")
    f_top, zeta_top, leak = fits[-1]
    span = float(t_sel[-1] - t_sel[0])
    decays = zeta_top * 2 * math.pi * f_top * span  # e-folds of the top mode over the window
    capped = t_sel[-1] + step < t[-1] - 0.5 * output_every  # the budget, not the run, ends the window
    if capped or decays > 10.0:
        longer = (f"the record already holds the top mode's ring-down (it decays by e^-{decays:.3g} over the window), so "
                  f"a longer run adds nothing: weaken {_load_fields(system)} (the contacts swing by {strain:.2g} of their "
                  "overlap) or tighten simulation.rtol")
    else:
        longer = (f"raise simulation.duration to at least "
                  f"{_duration_for(first, 10.0 / max(zeta_top * 2 * math.pi * f_top, 1e-300), output_every):.10g} s "
                  "(10 e-folds of the top mode's ring-down)")
    if f_top > f_bound * (1.0 + 1e-3) or leak > MAX_LEAK:
        what = (f"an oscillation at {f_top:.4g} Hz, above any mode of the linearised chain (at most {f_bound:.4g} Hz)"
                if f_top > f_bound * (1.0 + 1e-3) else
                f"a second oscillation of {leak:.2g} of the mode's amplitude beside it (the motion is not the linearised "
                "chain's modes)")
        kind = str(ds.attrs.get("solid_kind", "rigid"))
        if is_elastic(kind) and any(e.on_solid for e in chain.ends):
            longer = (f"the chain presses on the {kind}, whose motion at the contact couples the chain to the solid's "
                      f"modes: end the chain on a wall or on a rigid solid (solid.kind = \"rigid\"); or {longer}")
        raise CutoffError(f"the fit of the top mode's coordinate finds {what}: {longer}")
    if span * f_top < min_periods:
        raise CutoffError(f"the free response ({span:.3g} s) holds {span * f_top:.1f} periods of the top mode "
                          f"({f_top:.4g} Hz); {min_periods:g} are needed: raise simulation.duration to at least "
                          f"{_duration_for(first, min_periods / f_top, output_every):.10g} s")
    # the same fit on the first three quarters of the window: a fit the record supports agrees
    part = (3 * len(t_sel)) // 4
    other = _mode_of(t_sel[:part], Q[:part, -1])
    spread = abs(other[0] / f_top - 1.0) if other is not None else math.inf
    if not spread <= rtol:
        raise CutoffError(f"the top mode ({f_top:.6g} Hz) moves by {spread:.2g} when the last quarter of the free response "
                          f"is left out (limit {rtol:g}): {longer}")
    modes = np.array([f[0] if f is not None else math.nan for f in fits])
    cutoff = f_top / float(factors[-1])
    return ChainCutoff(cutoff_hz=cutoff, top_mode_hz=f_top, top_damping_ratio=zeta_top,
                       factor=float(factors[-1]), beads=tuple(labels[g] for g in order),
                       end_stiffness=tuple(e.stiffness / edges.stiffness for e in chain.ends),
                       modes_hz=modes, window=(float(t_sel[0]), float(t_sel[-1])), strain=strain, spread=spread,
                       leak=leak, kind=edges.kind,
                       band_edges_hz=tuple(e * cutoff / edges.top_hz for e in edges.edges_hz),
                       end_shift=_end_shift(ds, chain, f_expected))


def _periodic_chain(ds, system):
    """(the run's chain linearised, `analysis.chain.linear_chain`; its infinite chain's band
    edges), or CutoffError: no static precompression, not one straight chain, or a chain that
    is neither monatomic nor diatomic."""
    if "equilibrium_contact" not in ds or not ds.sizes.get("equilibrium_contact", 0):
        raise CutoffError("the run has no static precompression (simulation.equilibrate = true with a constant load): "
                          "a cut-off belongs to a precompressed chain")
    try:
        chain = linear_chain(ds, system)
    except ChainError as e:
        raise CutoffError(str(e)) from None
    edges = band_edges(chain)
    if edges is None:
        k, m = chain.stiffness, chain.mass
        raise CutoffError(f"the chain {chain.beads[0]}..{chain.beads[-1]} is not monatomic, nor diatomic (bead "
                          f"masses {m.min():.4g}-{m.max():.4g} kg, pair stiffnesses {k.min():.4g}-{k.max():.4g} N/m; "
                          "one mass, or two alternating, and one pair stiffness have band edges in closed form)")
    return chain, edges


def _end_shift(ds, chain: LinearChain, top_hz: float) -> float:
    """For ends held by an elastic solid: the largest |the linearised top mode with that end free
    / `top_hz` (with it held) - 1|, a scale of how far the solid's own motion, neglected, could
    move the cut-off; 0 when no end presses on an elastic solid."""
    if not is_elastic(str(ds.attrs.get("solid_kind", "rigid"))):
        return 0.0
    shift = 0.0
    for k, end in enumerate(chain.ends):
        if end.on_solid:
            ends = list(chain.ends)
            ends[k] = replace(end, stiffness=0.0, damping=0.0)
            free = replace(chain, ends=tuple(ends))
            shift = max(shift, abs(_chain_modes(free, top_hz)[0][-1] - 1.0))
    return shift


def _free_response(ds, system, order, axis, f_bound: float, max_strain: float, budget):
    """(times, the beads' velocities along the chain (times, beads), the contacts' largest swing
    over their static overlap, the sample spacing) of the chain's free response: after the last
    transient load, thinned to about SAMPLES_PER_PERIOD samples a period of f_bound, its first
    budget(spacing) samples. CutoffError for outputs too sparse for f_bound, nothing that sets the
    chain moving, or a swing beyond max_strain (not the linear regime)."""
    from ..io.results import require_states

    require_states(ds, "the chain's free response", order)
    t = np.asarray(ds["time"].values, float)
    dt = (t[-1] - t[0]) / max(len(t) - 1, 1)
    if len(t) < 2 or 1.0 / dt < 2.5 * f_bound:
        raise CutoffError(f"outputs every {dt:.3g} s sample the chain's modes (up to {f_bound:.4g} Hz) fewer than 2.5 times a "
                          f"period: lower simulation.output_every to at most {1.0 / (2.5 * f_bound):.3g} s")
    start, driven = _free_start(system, t[-1])
    if not driven and not np.any(ds["v_x"].values[0, order]) and not np.any(ds["v_y"].values[0, order]):
        raise CutoffError("nothing sets the chain moving (no transient load, moving wall or initial velocity)")
    i, j = np.array(order[:-1]), np.array(order[1:])
    R = system.radius
    gap = np.hypot(ds["x"].values[:, j] - ds["x"].values[:, i], ds["y"].values[:, j] - ds["y"].values[:, i])
    delta = R[i] + R[j] - gap
    strain = float(np.max(np.abs(delta - delta[0]) / delta[0]))
    if strain > max_strain:
        raise CutoffError(f"a contact's overlap swings by {strain:.3g} of its static value (limit {max_strain:g}): the chain "
                          f"is not in its linear regime; drive it more weakly: scale {_load_fields(system)} down by a "
                          f"factor of at least {strain / max_strain:.3g}")
    sel = np.flatnonzero(t >= start + 0.5 * dt)
    q = max(1, int(1.0 / (dt * SAMPLES_PER_PERIOD * f_bound)))
    sel = sel[::q][:budget(q * dt)]
    V = ds["v_x"].values[sel][:, order] * axis[0] + ds["v_y"].values[sel][:, order] * axis[1]
    return t[sel], V, strain, q * dt
