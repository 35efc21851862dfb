"""The solid's wavefield along its length, in wavenumber and time: pure functions of a result
Dataset and its solid model. The node lines and the transform that fits the ends, the kinetic
energy E(k, t) of each harmonic (and the modes' energy of eq. 15 shared over the harmonics), its
moments and their growth law, band-filtered fields, and the frequency-wavenumber map with its
ridges and the analytic branches (`solid.dispersion`). docs/wavefield.md ("Method") states the
definitions with their equations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..io.results import ResultFileError
from ..solid.base import QUADRATIC_DISPERSION
from ..solid.kinds import kind_of
from .modal import modal_energies

ENDS = {(True, True): "clamped-clamped", (False, False): "free-free", (True, False): "clamped-free",
        (False, True): "free-clamped"}
# the frequency error the wavenumbers called resolved stay below (`resolved_wavenumber`)
FE_ERROR = 0.0025
FE_DISPERSION = QUADRATIC_DISPERSION  # the plate's and beam's law (each kind's: `LineSampling.dispersion`)


# --------------------------------------------------------------------------------------------
# 1.-2. where the field is sampled, and the transform along the length


@dataclass(frozen=True)
class SpatialBasis:
    """The transform along the length [y0, y0 + length] that fits the ends: samples y (N,) [m],
    wavenumbers k (N,) [rad/m], and each harmonic's squared norm, the trapezoid rule's integral
    of phi_n^2 over the length on the samples (N,) [m]; `ends` names the end conditions."""

    ends: str
    y0: float
    length: float
    y: np.ndarray
    k: np.ndarray
    norm: np.ndarray


def spatial_basis(y0: float, length: float, samples: int, clamped: tuple[bool, bool]) -> SpatialBasis:
    """The basis of `ENDS[clamped]` on `samples` uniform points (docs/wavefield.md, "Method"):
    clamped-clamped: the interior points s_j = j L / (N + 1), k_n = n pi / L, n = 1..N;
    free-free: s_j = j L / (N - 1), j = 0..N-1 (both ends), k_n = n pi / L, n = 0..N-1;
    clamped at one end: s_j = j L / N, j = 1..N (the free end included), k_n = (n + 1/2) pi / L."""
    ends = ENDS[tuple(bool(c) for c in clamped)]
    n, L = int(samples), float(length)
    if n < 2 or not L > 0:
        raise ValueError(f"spatial_basis: need 2 or more samples and a positive length (got {samples}, {length})")
    j = np.arange(n)
    if ends == "clamped-clamped":
        s, k, norm = (j + 1) * L / (n + 1), (j + 1) * np.pi / L, np.full(n, L / 2)
    elif ends == "free-free":
        s, k = j * L / (n - 1), j * np.pi / L
        norm = np.where((j == 0) | (j == n - 1), L, L / 2)
    else:
        s, k, norm = (j + 1) * L / n, (j + 0.5) * np.pi / L, np.full(n, L / 2)
        if ends == "free-clamped":
            s = L - s[::-1]  # the mirror image: free at y0, clamped at y0 + L
    return SpatialBasis(ends, float(y0), L, y0 + s, k, norm)


def basis_functions(basis: SpatialBasis) -> np.ndarray:
    """phi_n(y_j), (N samples, N harmonics): sin(k s), cos(k s) or, clamped at the top only,
    sin(k (L - s))."""
    s = basis.y - basis.y0
    if basis.ends == "free-free":
        return np.cos(np.outer(s, basis.k))
    if basis.ends == "free-clamped":
        return np.sin(np.outer(basis.length - s, basis.k))
    return np.sin(np.outer(s, basis.k))


def forward(basis: SpatialBasis, v: np.ndarray) -> np.ndarray:
    """Amplitudes a_n (..., N) of samples v (..., N) along the last axis, v(y_j) = sum_n a_n
    phi_n(y_j): DST-I / (N + 1), DCT-I / (N - 1) (halved at n = 0 and N - 1) or DST-III / N
    (scipy.fft's unnormalised transforms, whose sums are the trapezoid rule's)."""
    from scipy.fft import dct, dst

    n = v.shape[-1]
    if basis.ends == "clamped-clamped":
        return dst(v, type=1, axis=-1) / (n + 1)
    if basis.ends == "free-free":
        a = dct(v, type=1, axis=-1) / (n - 1)
        a[..., [0, -1]] *= 0.5
        return a
    if basis.ends == "free-clamped":
        return dst(v[..., ::-1], type=3, axis=-1) / n
    return dst(v, type=3, axis=-1) / n


def inverse(basis: SpatialBasis, a: np.ndarray) -> np.ndarray:
    """The samples v (..., N) of amplitudes a (..., N): sum_n a_n phi_n(y_j) (`forward`'s inverse)."""
    from scipy.fft import dct, dst

    if basis.ends == "clamped-clamped":
        return dst(a, type=1, axis=-1) / 2
    if basis.ends == "free-free":
        b = np.array(a, float, copy=True)
        b[..., [0, -1]] *= 2
        return dct(b, type=1, axis=-1) / 2
    v = dst(a, type=2, axis=-1) / 2
    return v[..., ::-1] if basis.ends == "free-clamped" else v


@dataclass(frozen=True)
class NodeLines:
    """Lines of a solid's nodes along its length: their positions across the width x (nl,) [m],
    the mass per unit length each stands for (nl,) [kg/m] (rho thickness times the trapezoid
    rule's width share on the plate, rho A on the beam), the velocity components sampled
    ("x", "y" on the plate: across and along the length; "x" on the beam), the basis along the
    length and the sparse map from the reduced DOFs to the sampled velocities, rows ordered
    (line, component, sample). `element` is the longest element along the length [m],
    `dispersion` its kind's frequency error law (`solid.base.LineSampling`)."""

    kind: str
    x: np.ndarray
    mass: np.ndarray
    components: tuple[str, ...]
    basis: SpatialBasis
    sampling: sp.csr_matrix
    element: float
    dispersion: tuple[float, int] = (QUADRATIC_DISPERSION, 4)
    whole: bool = True  # the lines carry the solid's whole motion (`solid.base.LineSampling.whole`)

    @property
    def shape(self) -> tuple[int, int, int]:
        return len(self.x), len(self.components), len(self.basis.y)


def node_lines(model, samples: int | None = None) -> NodeLines:
    """The node lines of a solid built from its recipe (`model.recipe`), as its kind samples them
    (`SolidKind.wave_lines`: a plate's vertex columns, a beam's nodes) on the basis of its ends.
    ValueError for a kind without a wavefield."""
    lines = kind_of(model).wave_lines(model, samples)
    r = model.recipe
    basis = spatial_basis(r.y0, r.length, lines.count, tuple(bool(c) for c in r.clamped))
    return NodeLines(model.kind, lines.x, lines.mass, lines.components, basis, (lines.sampler(basis.y) @ model.T).tocsr(),
                     lines.element, lines.dispersion, lines.whole)


def resolved_wavenumber(lines: NodeLines, error: float = FE_ERROR) -> float:
    """The wavenumber [rad/m] below which the elements' dispersion error stays under `error`:
    C (kl)^p = error with l the longest element along the length and (C, p) its kind's law
    (`lines.dispersion`: quadratic elements' (kl)^4 / 1440 on the plate's sides and, as a bound,
    the beam's Hermite cubics; Morley's 0.15 (kl)^2 on the plate in bending, ...)."""
    constant, power = lines.dispersion
    return (error / constant) ** (1.0 / power) / lines.element


def sampled_shapes(lines: NodeLines, modes) -> np.ndarray:
    """The mode shapes at the lines' samples, (rows, modes) float32 (rows as `lines.sampling`)."""
    return np.asarray(lines.sampling @ np.asarray(modes.shapes), np.float32)


def sampled_velocities(ds, lines: NodeLines, shapes: np.ndarray | None = None, name="result") -> np.ndarray:
    """The velocities at the lines' samples at every stored solid output, (nt, nl, nc, N) [m/s]:
    the stored reduced velocities mapped by `lines.sampling`, or the modal velocities through the
    sampled mode shapes (`sampled_shapes`), q' = Phi eta' (float32 products, as the state is stored)."""
    if "solid_v" in ds:
        v = np.asarray(ds["solid_v"].values, np.float32)
        out = (lines.sampling.astype(np.float32) @ v.T).T
    else:
        if shapes.shape[1] != ds.sizes["mode"]:
            raise ResultFileError(f"{name}: its solid state has {ds.sizes['mode']} modes, its solid "
                                  f"{shapes.shape[1]}", 2)
        out = np.asarray(ds["solid_eta_dot"].values, np.float32) @ shapes.T
    return np.asarray(out, float).reshape(-1, *lines.shape)


# --------------------------------------------------------------------------------------------
# 3.-4. the spectrum in wavenumber and time, and its measures


@dataclass(frozen=True)
class WavenumberSpectrum:
    """The sampled field's harmonics: times t (nt,) [s], wavenumbers k (N,) [rad/m], amplitudes
    (nt, nl, nc, N) [m/s] and the kinetic energy of each harmonic per line (nl, N, nt) [J]."""

    t: np.ndarray
    k: np.ndarray
    amplitude: np.ndarray
    energy_line: np.ndarray

    @property
    def energy(self) -> np.ndarray:
        """E(k, t), (N, nt) [J]: summed over the width."""
        return self.energy_line.sum(axis=0)


def harmonic_energy(amplitude: np.ndarray, lines: NodeLines) -> np.ndarray:
    """The kinetic energy of each harmonic on each line, (nl, N, nt) [J], of amplitudes
    (nt, nl, nc, N): E_in = 1/2 m_i |phi_n|^2 sum_c a_inc^2, m_i the line's mass per length and
    |phi_n|^2 the harmonic's squared norm. Their sum over n is the trapezoid rule's
    1/2 m_i integral of |v|^2 over the length (Parseval, by the basis' orthogonality)."""
    e = 0.5 * lines.mass[None, :, None] * lines.basis.norm[None, None, :] * (amplitude**2).sum(axis=2)
    return np.moveaxis(e, 0, -1)


def wavenumber_spectrum(velocities: np.ndarray, lines: NodeLines, t) -> WavenumberSpectrum:
    """The spectrum of sampled velocities (nt, nl, nc, N) at times t (`forward`, `harmonic_energy`)."""
    a = forward(lines.basis, np.asarray(velocities, float))
    return WavenumberSpectrum(np.asarray(t, float), lines.basis.k, a, harmonic_energy(a, lines))


def band_field(spectrum: WavenumberSpectrum, lines: NodeLines, k_lo: float, k_hi: float) -> np.ndarray:
    """The velocity field of the harmonics with k_lo <= k < k_hi back in space, (nt, nl, nc, N)
    [m/s] at the samples (`inverse` of the band's amplitudes, the others zero)."""
    keep = (spectrum.k >= k_lo) & (spectrum.k < k_hi)
    return inverse(lines.basis, np.where(keep, spectrum.amplitude, 0.0))


def energy_density(field: np.ndarray, lines: NodeLines) -> np.ndarray:
    """The kinetic energy per unit length of a sampled field (nt, nl, nc, N), summed over the
    width: 1/2 sum_i m_i |v_i|^2, (N, nt) [J/m]."""
    return 0.5 * np.einsum("i,tijn->nt", lines.mass, np.asarray(field, float) ** 2)


@dataclass(frozen=True)
class SpectralMoments:
    """Per time (nt,): the energy in the wavenumbers analysed `total` [J], the centroid
    [rad/m], the variance [(rad/m)^2] and the Shannon entropy [nats] of p(k) = E(k, t) / total,
    over the wavenumbers k <= `k_max`; NaN where the total is 0."""

    total: np.ndarray
    centroid: np.ndarray
    variance: np.ndarray
    entropy: np.ndarray
    k_max: float


def spectral_moments(k, energy, k_max: float = np.inf) -> SpectralMoments:
    """The moments of E(k, t) (N, nt) over k <= k_max: mu = sum k p, sigma^2 = sum (k - mu)^2 p,
    H = -sum p ln p (0 ln 0 = 0), with p = E / sum E."""
    k = np.asarray(k, float)
    sel = k <= k_max
    E = np.asarray(energy, float)[sel]
    kk = k[sel][:, None]
    total = E.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = E / total
        mu = (kk * p).sum(axis=0)
        var = ((kk - mu) ** 2 * p).sum(axis=0)
        H = -np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0).sum(axis=0)
    bad = ~(total > 0)
    for a in (mu, var, H):
        a[bad] = np.nan
    return SpectralMoments(total, mu, var, H, float(k_max))


def modal_spectrum(ds, lines: NodeLines, shapes: np.ndarray) -> np.ndarray:
    """The solid's energy over the harmonics, (N, nt) [J]: each mode's energy E_m = 1/2 (eta'^2 +
    w^2 eta^2) (eq. 15) shared over the harmonics as the kinetic energy of its sampled shape
    (`harmonic_energy`, normalised to 1 per mode). It adds up to the solid's energy, less the
    modes' cross terms (docs/wavefield.md, "The modal energy spectrum")."""
    n_modes = shapes.shape[1]
    a = forward(lines.basis, np.asarray(shapes, float).T.reshape(n_modes, *lines.shape))
    share = harmonic_energy(a, lines).sum(axis=0).T  # (modes, N)
    total = share.sum(axis=1, keepdims=True)
    share = np.divide(share, total, out=np.zeros_like(share), where=total > 0)
    eta, etad = np.asarray(ds["solid_eta"].values, float), np.asarray(ds["solid_eta_dot"].values, float)
    energy = modal_energies(eta, etad, np.asarray(ds["mode_omega"].values, float))
    return (energy @ share).T


@dataclass(frozen=True)
class PowerLaw:
    """sigma^2(t) = A (t - t0)^exponent fitted by least squares on the logarithms over
    t0 < t <= t_end: the exponent with the regression's standard error (docs/wavefield.md,
    "Growth law"), A [(rad/m)^2 / s^exponent], t0 and t_end [s] and the number of outputs used."""

    exponent: float
    stderr: float
    prefactor: float
    t0: float
    t_end: float
    points: int


def growth_exponent(t, variance, t0: float, t_end: float) -> PowerLaw:
    """The variance's growth law over (t0, t_end] (`PowerLaw`): the straight line through
    (ln(t - t0), ln sigma^2) by least squares. NaN with fewer than 3 outputs with a finite,
    positive variance."""
    t = np.asarray(t, float)
    var = np.asarray(variance, float)
    sel = (t > t0) & (t <= t_end) & np.isfinite(var) & (var > 0)
    n = int(np.count_nonzero(sel))
    if n < 3:
        return PowerLaw(np.nan, np.nan, np.nan, float(t0), float(t_end), n)
    x, y = np.log(t[sel] - t0), np.log(var[sel])
    X = np.column_stack([np.ones_like(x), x])
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    resid = y - X @ coef
    cov = float(resid @ resid) / (n - 2) * np.linalg.inv(X.T @ X)
    return PowerLaw(float(coef[1]), float(np.sqrt(cov[1, 1])), float(np.exp(coef[0])), float(t0), float(t_end), n)


def arrival_time(t, total, fraction: float = 0.01) -> float:
    """The first time the energy `total` reaches `fraction` of its largest value [s] (NaN if it
    never does)."""
    total = np.asarray(total, float)
    top = np.nanmax(total) if np.any(np.isfinite(total)) else np.nan
    hit = np.flatnonzero(total >= fraction * top) if top > 0 else []
    return float(np.asarray(t, float)[hit[0]]) if len(hit) else float("nan")


# --------------------------------------------------------------------------------------------
# 5. the frequency-wavenumber map and the analytic branches


@dataclass(frozen=True)
class FrequencyWavenumberMap:
    """The record's power over wavenumber k (nk,) [rad/m] and frequency f (nf,) [Hz], (nk, nf)
    [J s, up to the windows' constant]: kinetic-energy weighted, summed over the lines and the
    components; `pad` is the zero-padding factor of both transforms."""

    k: np.ndarray
    f: np.ndarray
    power: np.ndarray
    pad: int


def frequency_wavenumber_map(velocities: np.ndarray, lines: NodeLines, t, pad: int = 4) -> FrequencyWavenumberMap:
    """|V(k, f)|^2 + |V(k, -f)|^2 (waves running either way) of the sampled velocities (nt, nl,
    nc, N) at uniform times t: the mean-free field times a Hann window in time and a Hann window
    along the length, Fourier transformed in both (zero-padded `pad` times), weighted by the
    lines' masses 1/2 m_i dy dt^2 and summed over lines and components. k and f are those of the
    transforms: 2 pi j / (pad N dy), j / (pad nt dt)."""
    v = np.asarray(velocities, float)
    t = np.asarray(t, float)
    nt, n = v.shape[0], v.shape[-1]
    if nt < 4:
        raise ValueError(f"a frequency-wavenumber map needs 4 or more outputs, got {nt}")
    dt = (t[-1] - t[0]) / (nt - 1)
    dy = float(lines.basis.y[1] - lines.basis.y[0])
    v = v - v.mean(axis=0)
    window = np.outer(np.hanning(nt), np.hanning(n))
    nt_p, n_p = pad * nt, pad * n
    power = np.zeros((n_p // 2 + 1, nt_p // 2 + 1))
    for i in range(v.shape[1]):  # a line and a component at a time: the padded transform stays small
        for c in range(v.shape[2]):
            V = np.abs(np.fft.fft(np.fft.rfft(v[:, i, c, :] * window, n=n_p, axis=1), n=nt_p, axis=0)) ** 2
            V[1:(nt_p + 1) // 2] += V[:nt_p // 2:-1]  # either direction of travel: f and -f
            power += 0.5 * lines.mass[i] * dy * dt**2 * V[: nt_p // 2 + 1].T
    k = 2 * np.pi * np.fft.rfftfreq(n_p, dy)
    f = np.fft.rfftfreq(nt_p, dt)
    return FrequencyWavenumberMap(k, f, power, int(pad))


@dataclass(frozen=True)
class Ridges:
    """Points of a map's ridges: wavenumbers k [rad/m], frequencies f [Hz] and powers, each
    a local maximum of the map in both directions, refined by a parabola through the peak and its
    neighbours in each (`parabolic_peak`)."""

    k: np.ndarray
    f: np.ndarray
    power: np.ndarray


def parabolic_peak(left: np.ndarray, centre: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The vertex offset, in samples (within [-1/2, 1/2]), of the parabola through three samples
    around a maximum (of their logarithms: exact for a Gaussian peak, close for a Hann window's)."""
    a, b, c = (np.log(np.maximum(x, 1e-300)) for x in (left, centre, right))
    den = a - 2 * b + c
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den < 0, np.clip(0.5 * (a - c) / den, -0.5, 0.5), 0.0)


def map_ridges(fk: FrequencyWavenumberMap, floor: float = 1e-3, k_max: float = np.inf,
               f_max: float = np.inf, reach: int = 3) -> Ridges:
    """The peaks of the map above `floor` times its largest value over k <= k_max and
    f <= f_max: the points that are the largest within `reach` bins of the unpadded transforms
    each way in k and in f (docs/wavefield.md, "Ridges"), each refined in f and in k by
    `parabolic_peak`. The map's edges are left out."""
    from scipy.ndimage import maximum_filter

    P = fk.power
    half = reach * fk.pad
    top_of = maximum_filter(P, size=2 * half + 1, mode="nearest")
    kk, ff = np.meshgrid(fk.k, fk.f, indexing="ij")
    region = (kk <= k_max) & (ff <= f_max)
    region[[0, -1], :] = False
    region[:, [0, -1]] = False
    top = P[region].max() if np.any(region) else 0.0
    i, j = np.nonzero((P == top_of) & region & (P >= floor * top) & (P > 0))
    dk, df = fk.k[1] - fk.k[0], fk.f[1] - fk.f[0]
    k = fk.k[i] + dk * parabolic_peak(P[i - 1, j], P[i, j], P[i + 1, j])
    f = fk.f[j] + df * parabolic_peak(P[i, j - 1], P[i, j], P[i, j + 1])
    return Ridges(k, f, P[i, j])


@dataclass(frozen=True)
class SolidBranches:
    """The analytic dispersion of a solid over wavenumbers k [rad/m]: each branch's frequencies
    [Hz] by name (a plate's Rayleigh-Lamb S0, S1, ..., A0, ...; a beam's Euler-Bernoulli EB)."""

    k: np.ndarray
    named: dict

    def curves(self) -> dict[str, np.ndarray]:
        """Each branch by name, frequencies [Hz] over k."""
        return dict(self.named)


def solid_branches(model, k, count: int = 3) -> SolidBranches:
    """The analytic branches of a solid as its kind gives them (`SolidKind.branches`, from
    `solid.dispersion`: independent of its finite-element model)."""
    k = np.asarray(k, float)
    return SolidBranches(k, kind_of(model).branches(model, k, count))


# --------------------------------------------------------------------------------------------
# all of it, on a result


@dataclass(frozen=True)
class Measures:
    """An energy spectrum over the harmonics, (N, nt) [J], its moments over k <= k_max and the
    growth law of its variance."""

    energy: np.ndarray
    moments: SpectralMoments
    growth: PowerLaw


@dataclass(frozen=True)
class Wavefield:
    """The wavefield analysis of one result (docs/wavefield.md): its node lines, the spectrum
    (amplitudes and E(k, t)) with the `kinetic` measures (moments over k <= k_max, the variance's
    growth law over the fit window), the same `modal` measures of the modal energy spectrum
    (`modal_spectrum`; None for a result that stores no modal state), the energy's arrival [s],
    the kinetic energy of each band's field per unit length (bands (nb, 2) [rad/m]; density
    (nb, N, nt) [J/m]), the frequency-wavenumber map with its ridges over k_window <= k <= k_max,
    and the analytic branches up to `k_plot`. `kinetic_check`: the largest difference of E(k, t)
    summed over k from the solid's kinetic energy 1/2 v'M v, relative to the latter's largest
    value (the width's trapezoid rule against the consistent mass); NaN where the lines do not
    carry the solid's whole motion (a surface standing across the granular plane)."""

    lines: NodeLines
    spectrum: WavenumberSpectrum
    kinetic: Measures
    modal: Measures | None
    arrival: float
    bands: np.ndarray
    band_density: np.ndarray
    fk: FrequencyWavenumberMap
    ridges: Ridges
    branches: SolidBranches
    k_resolved: float
    k_window: float
    k_plot: float
    kinetic_check: float

    @property
    def moments(self) -> SpectralMoments:
        return self.kinetic.moments

    @property
    def growth(self) -> PowerLaw:
        return self.kinetic.growth


def window_wavenumber(lines: NodeLines) -> float:
    """Twice the main-lobe half-width 4 pi / L_w of the map's Hann window along the length
    (L_w = N dy, the sampled length) [rad/m]: a standing wave's part running the other way then
    lies two half-widths away from the one read, beyond its main lobe; below it a ridge's
    wavenumber is pulled toward 0."""
    dy = float(lines.basis.y[1] - lines.basis.y[0])
    return 2 * 4 * np.pi / (len(lines.basis.y) * dy)


def default_bands(k_max: float, count: int = 4) -> np.ndarray:
    """`count` bands of equal width from 0 to k_max, (count, 2) [rad/m]."""
    edges = np.linspace(0.0, k_max, count + 1)
    return np.column_stack([edges[:-1], edges[1:]])


@dataclass(frozen=True)
class WavefieldSettings:
    """What `analyse_wavefield` computes: the moments over k <= `k_max` [rad/m] (None:
    `resolved_wavenumber`), the `bands` (nb, 2) [rad/m] (None: 4 equal bands to k_max), the growth
    law's window `fit` (t0, t_end) [s] (None: from the arrival, the first output where the energy
    below k_max reaches 1 % of its largest, to the end), the map's zero-padding factor `pad` and
    the analytic branches per family `branch_count`."""

    bands: np.ndarray | None = None
    k_max: float | None = None
    fit: tuple[float, float] | None = None
    pad: int = 4
    branch_count: int = 3


def analyse_wavefield(ds, model, modes=None, settings: WavefieldSettings | None = None, progress=None,
                      name="result") -> Wavefield:
    """The `Wavefield` of result `ds` with solid `model` (its `modes` for a modal state), computed
    as `settings` say (default `WavefieldSettings()`); `progress(what)` is called before each
    stage. ValueError for a solid without a wavefield or fewer than 4 solid outputs."""
    settings, say = settings or WavefieldSettings(), progress or (lambda what: None)
    lines = node_lines(model)
    t = np.asarray(ds["solid_time"].values, float)
    if len(t) < 4:
        raise ValueError(f"{name}: {len(t)} stored solid outputs; a wavefield needs 4 or more")
    say("velocities on the node lines")
    shapes = None if "solid_v" in ds else sampled_shapes(lines, modes)
    v = sampled_velocities(ds, lines, shapes, name)
    say("wavenumber spectrum")
    spectrum = wavenumber_spectrum(v, lines, t)
    k_res = resolved_wavenumber(lines)
    k_max = k_res if settings.k_max is None else float(settings.k_max)
    kinetic = spectral_moments(spectrum.k, spectrum.energy, k_max)
    arrival = arrival_time(t, kinetic.total)
    fit = settings.fit
    t0, t_end = (arrival, float(t[-1])) if fit is None else (float(fit[0]), float(fit[1]))

    def measures(energy, moments):
        return Measures(energy, moments, growth_exponent(t, moments.variance, t0, t_end))

    modal = None
    if shapes is not None:
        energy = modal_spectrum(ds, lines, shapes)
        modal = measures(energy, spectral_moments(spectrum.k, energy, k_max))
    bands = default_bands(k_max) if settings.bands is None else np.asarray(settings.bands, float).reshape(-1, 2)
    say("band-filtered fields")
    density = np.stack([energy_density(band_field(spectrum, lines, lo, hi), lines) for lo, hi in bands])
    say("frequency-wavenumber map")
    fk = frequency_wavenumber_map(v, lines, t, settings.pad)
    k_window = window_wavenumber(lines)
    ridges = map_ridges(fk, 1e-3, k_max)
    ridges = Ridges(ridges.k[ridges.k >= k_window], ridges.f[ridges.k >= k_window], ridges.power[ridges.k >= k_window])
    say("dispersion branches")
    k_plot = float(min(fk.k[-1], 1.5 * k_max))
    branches = solid_branches(model, np.linspace(0.0, k_plot, 241), settings.branch_count)
    check = np.nan
    # the solid's 1/2 v'M v, at the solid outputs; a line that does not carry the whole motion (a
    # surface's z = 0) is not the solid's energy: no check
    if lines.whole and "energy_solid_kinetic" in ds and "time" in ds:
        ke = np.interp(t, np.asarray(ds["time"].values, float), np.asarray(ds["energy_solid_kinetic"].values, float))
        if ke.max() > 0:
            check = float(np.max(np.abs(spectrum.energy.sum(axis=0) - ke)) / ke.max())
    return Wavefield(lines, spectrum, measures(spectrum.energy, kinetic), modal, arrival, bands, density, fk, ridges,
                     branches, k_res, k_window, k_plot, check)
