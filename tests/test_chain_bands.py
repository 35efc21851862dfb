"""Band edges of precompressed chains and the band measures of `granel spectrum`, against lattice
dynamics no one here wrote:

* the infinite chains' band edges (`analysis.chain.band_edges`) against the eigenvalues of the
  unit cell's Bloch matrix over the Brillouin zone (monatomic: D(q) = 2K/m (1 - cos q); diatomic:
  the 2 x 2 matrix of Kittel's ch. 4), computed here with numpy;
* the linearised chain's harmonic response (`analysis.chain.chain_response`, a dense solve)
  against a transfer (shooting) solution written here, bead by bead;
* the band measures (`analysis.bands`) on curves whose crossings are known in closed form;
* a chain's measured band edges (`analysis.narrowband.cutoff_frequency`) for a diatomic chain
  and a chain pressing on the solid, against the band edges from Hertz's law;
* `granel spectrum`'s band measures on a monatomic and a diatomic chain (slow) against the
  linearised chain.

Chains are steel beads (granel's default: E = 200 GPa, nu = 0.3, rho = 7850 kg/m^3) pressed by
F0 = 10 N; Hertz's contact linearises to K = 3/2 A^(2/3) F0^(1/3) (A = 4/3 E* sqrt(R*))."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from granel import scenario as S
from granel.analysis.bands import DROP, EDGE, pass_band, second_band
from granel.analysis.chain import ChainEnd, LinearChain, band_edges, chain_response, linear_chain
from granel.analysis.narrowband import CutoffError, cutoff_frequency
from granel.analysis.result_model import result_system
from granel.run import run_scenario

from test_chain_cutoff_lengths import bound
from test_narrowband_physics import R_HEAVY, R_LIGHT, chain_scenario, diatomic_bands, hertz_A, sphere_mass

EPS = np.finfo(float).eps
F0 = 10.0
CUTOFF_CHAIN = Path(__file__).resolve().parents[1] / "scenarios" / "designs" / "cutoff-chain.toml"


def monatomic_cutoff(R=0.005, F=F0):
    """f_c = 2 sqrt(K / m) / 2 pi of steel beads of radius R pressed by F."""
    K = 1.5 * hertz_A(R, R) ** (2 / 3) * F ** (1 / 3)
    return math.sqrt(K / sphere_mass(R)) / math.pi


def hand_chain(mass, k, c, ends=(ChainEnd(), ChainEnd())) -> LinearChain:
    n = len(mass)
    return LinearChain(tuple(f"C:{j + 1}" for j in range(n)), tuple(range(n)), np.asarray(mass, float),
                       np.asarray(k, float), np.asarray(c, float), ends, (1.0, 0.0))


# ---------------------------------------------------------------- the infinite chains' band edges

def test_band_edges_are_the_bloch_matrix_extremes():
    """The acoustic band's top, the optical band's bottom and top are the extremes over the zone
    (q in [0, pi], 2001 points: the extremes lie at its ends, so the grid holds them exactly) of
    the eigenvalues of the diatomic cell's Bloch matrix [[2K/m1, -K(1 + e^-iq)/sqrt(m1 m2)], [.,
    2K/m2]] (numpy's eigvalsh), and the monatomic cut-off is the top of 2K/m (1 - cos q), each
    within a few ulps (eigvalsh's backward error). One mass among three, or springs that differ,
    have no closed form: None."""
    K, m1, m2 = 1.1e7, 4.1e-3, 0.89e-3
    q = np.linspace(0.0, math.pi, 2001)
    lam = np.array([np.linalg.eigvalsh(np.array([[2 * K / m1, -K * (1 + np.exp(-1j * x)) / math.sqrt(m1 * m2)],
                                                 [-K * (1 + np.exp(1j * x)) / math.sqrt(m1 * m2), 2 * K / m2]]))
                    for x in q])
    hz = np.sqrt(np.clip([lam[:, 0].max(), lam[:, 1].min(), lam[:, 1].max()], 0, None)) / (2 * math.pi)
    for masses in ([m1, m2] * 4, [m2, m1] * 4, [m1, m2] * 4 + [m1]):
        n = len(masses)
        edges = band_edges(hand_chain(masses, [K] * (n - 1), [0.0] * (n - 1)))
        assert edges.kind == "diatomic"
        assert edges.edges_hz == pytest.approx(tuple(hz), rel=16 * EPS)
    mono = band_edges(hand_chain([m1] * 6, [K] * 5, [0.0] * 5))
    top = math.sqrt((2 * K / m1 * (1 - np.cos(q))).max()) / (2 * math.pi)
    assert mono.kind == "monatomic" and mono.edges_hz == pytest.approx((top,), rel=4 * EPS)
    assert band_edges(hand_chain([m1, m2, 2 * m1] * 2, [K] * 5, [0.0] * 5)) is None
    assert band_edges(hand_chain([m1] * 4, [K, 2 * K, K], [0.0] * 3)) is None


# ---------------------------------------------------------------- the linearised chain's response

def shooting(chain: LinearChain, f: float, driven: int) -> np.ndarray:
    """Each bead's displacement under a unit force on bead `driven`, by marching the link
    tensions along the chain: T_-1 = z_L u_0, T_i = T_(i-1) - w^2 m_i u_i - P_i, u_(i+1) = u_i +
    T_i / z_i (z = k + i w c), from two starts (u_0 = 1 unloaded; u_0 = 0 loaded) combined so
    that the last tension meets the right end, T_(n-1) = -z_R u_(n-1)."""
    w = 2 * math.pi * f
    z = chain.stiffness + 1j * w * chain.damping
    zl, zr = (e.stiffness + 1j * w * e.damping for e in chain.ends)

    def march(u0, load):
        u = [complex(u0)]
        T = zl * u0
        for i in range(chain.n):
            T = T - w * w * chain.mass[i] * u[i] - (load if i == driven else 0.0)
            if i < chain.n - 1:
                u.append(u[i] + T / z[i])
        return np.array(u), T + zr * u[-1]

    (ua, ra), (ub, rb) = march(1.0, 0.0), march(0.0, 1.0)
    # the round-off of the combination: an ulp of the largest terms it adds, per bead marched
    return ub - (rb / ra) * ua, chain.n * EPS * (np.abs(ub).max() + abs(rb / ra) * np.abs(ua).max())


def test_the_linear_response_is_the_transfer_solution():
    """`chain_response` (a dense solve of (K + i w C - w^2 M) u = e_a) against the shooting
    solution, on a chain of unequal beads, springs and dashpots, a damped wall at one end and an
    undamped one at the other, among its modes (3.8 to 31.5 kHz) and above them (45 kHz):
    within the round-off of the march's combination (n ulps of its largest terms, `shooting`),
    eight times over for the dense solve's."""
    rng = np.random.default_rng(3)
    n = 9
    mass = rng.uniform(0.5e-3, 4e-3, n)
    k = rng.uniform(0.5e7, 2e7, n - 1)
    c = rng.uniform(0.0, 5.0, n - 1)
    chain = hand_chain(mass, k, c, (ChainEnd("w0", 2e7, 3.0), ChainEnd("w1", 1.5e7, 0.0)))
    for f in (2e3, 9e3, 17e3, 30e3, 45e3):
        w = 2 * math.pi * f
        for driven in (0, 4, n - 1):
            ref, err = shooting(chain, f, driven)
            got = chain_response(chain, f, chain.beads[driven])
            assert np.all(np.abs(got.velocity - 1j * w * ref) <= 8 * w * err), (f, driven)  # and the solve's own ulps
            assert abs(got.end_force[1] - 1.5e7 * ref[-1]) <= 8 * 1.5e7 * err
            assert abs(got.end_force[0] - (2e7 + 3j * w) * ref[0]) <= 8 * abs(2e7 + 3j * w) * err
            assert err < 1e-6 * np.abs(ref).max()  # a test of the solution, not of round-off alone (measured <= 5e-8)


# ---------------------------------------------------------------- the band measures of a curve

def test_pass_band_and_second_band_by_their_definitions():
    """A curve on the grid 0..12 (in Hz) whose measures follow from the definitions by hand:
    y = 0, 10, -15, 5, 0, -10, -30, -60, -45, -20, -25, -50, -70 dB. The dip to -15 at 2 is not
    below the mean before it less 20 (5 - 20); -30 at 6 is (mean(0..5) = -10/6) and falls on:
    the stop band starts at 6, the level is L = -10/6. The cut-off: the last fall through L - 3
    at or before 6, between 4 (0) and 5 (-10); the 20 dB point through L - 20, between 5 (-10)
    and 6 (-30). The second band: peak -20 at 9 over the floor -60 (40 dB), half-way -40, so the
    run 9..10 (-45 at 8 is below), L2 = -22.5; its bottom through L2 - 3 = -25.5 between 8 and 9,
    its top between 10 (-25) and 11 (-50); the gap: L less the mean over 5..8 (between the
    cut-off, 4.47, and the bottom, 8.78). Linear interpolation, to a few ulps."""
    f = np.arange(13.0)
    y = np.array([0, 10, -15, 5, 0, -10, -30, -60, -45, -20, -25, -50, -70], float)
    pb = pass_band(f, y)
    L = -10 / 6
    assert pb.stop == 6 and pb.level_db == pytest.approx(L, abs=4 * EPS)
    assert pb.edge_hz == pytest.approx(4 + (L - EDGE - 0) / (-10 - 0), abs=8 * EPS)
    assert pb.db20_hz == pytest.approx(5 + (L - DROP + 10) / (-30 + 10), abs=8 * EPS)
    assert pb.edge_interval == (4.0, 5.0) and pb.db20_interval == (5.0, 6.0)
    sb = second_band(f, y, pb)
    L2 = -22.5
    assert sb.level_db == L2
    assert sb.bottom_hz == pytest.approx(8 + (L2 - EDGE + 45) / (-20 + 45), abs=8 * EPS)
    assert sb.top_hz == pytest.approx(10 + (L2 - EDGE + 25) / (-50 + 25), abs=8 * EPS)
    assert sb.gap_attenuation_db == pytest.approx(L - np.mean([-10, -30, -60, -45]), abs=8 * EPS)
    # a dip 20 dB below the mean that rises again is not a stop band; a curve that never falls has none
    assert pass_band(f[:4], [0.0, 0.0, -25.0, 0.0]).stop == 4 and math.isnan(pass_band(f[:4], [0.0] * 4).edge_hz)
    assert math.isnan(second_band(f[:8], y[:8], pass_band(f[:8], y[:8])).bottom_hz)  # no rise out of the gap


def test_crossings_on_a_given_curve_are_its_roots():
    """Given the curve itself, y = 0 up to 5 and -40 (f - 5)^2 above, the edge and the 20 dB
    point are its roots, 5 + sqrt(3/40) and 5 + sqrt(1/2) (L = 0 on the grid 0..9), to Brent's
    tolerance (1e-12 of f); linear interpolation between the grid's 5 and 6 gives 5 + 3/40 and
    5.5 instead."""
    def curve(x):
        return 0.0 if x <= 5 else -40.0 * (x - 5) ** 2

    f = np.arange(10.0)
    y = np.array([curve(x) for x in f])
    pb = pass_band(f, y, curve)
    assert pb.level_db == 0.0
    assert pb.edge_hz == pytest.approx(5 + math.sqrt(EDGE / 40), rel=1e-12)
    assert pb.db20_hz == pytest.approx(5 + math.sqrt(DROP / 40), rel=1e-12)
    lin = pass_band(f, y)
    assert lin.edge_hz == pytest.approx(5 + EDGE / 40, rel=8 * EPS) and lin.db20_hz == pytest.approx(5.5, rel=8 * EPS)


# ---------------------------------------------------------------- measured band edges (cutoff_frequency)

def cutoff_run(radii, extra=()):
    """scenarios/designs/cutoff-chain.toml with these radii (from the wall out), over 1.5 ms (20
    periods of the lowest top mode here, 17 kHz)."""
    sc = S.load(str(CUTOFF_CHAIN), [f"media.0.radii={list(radii)}", 'simulation.duration="1.5ms"', *extra])
    ds = run_scenario(sc)
    return ds, S.build_granular(sc, sc.base)[0]


ON_THE_SOLID = ['media.0.side="left"', 'media.0.grow="left"', "media.0.walls=[]",
                "excitations.0.direction=[1.0, 0.0]", "excitations.1.direction=[1.0, 0.0]"]


def test_a_diatomic_chains_band_edges_are_measured():
    """Eight beads alternating R = 5 and 3 mm (from the wall), pressed by 10 N on a rigid wall,
    undamped (alpha_n = 0: the modes are the undamped ones), rung by the pulse: the measured
    acoustic top, optical bottom and optical top are Brillouin's sqrt(2K/m1), sqrt(2K/m2),
    sqrt(2K(1/m1 + 1/m2)) / 2 pi within the bound of a measured mode (test_chain_cutoff_lengths'
    `bound`: nonlinearity s/4, the fit's resolution, RK4's phase error; measured 1.5e-6 below)."""
    radii = [R_HEAVY if k % 2 == 0 else R_LIGHT for k in range(8)]
    ds, system = cutoff_run(radii, ["contact.alpha_n=0.0"])
    c = cutoff_frequency(ds, system)
    want = diatomic_bands(F0)
    print("measured / analytic - 1:", [e / a - 1 for e, a in zip(c.band_edges_hz, want)])
    assert c.kind == "diatomic" and c.cutoff_hz == pytest.approx(c.band_edges_hz[-1], rel=4 * EPS)
    tol = bound(c, ds, c.top_mode_hz)
    assert tol < 1e-3
    for got, ref in zip(c.band_edges_hz, want):
        assert abs(got / ref - 1) <= tol + 1e-9  # 1e-9: the equilibrium's K (its residual, 1e-10 of the load)


def test_a_chain_pressing_on_a_rigid_solid_has_a_cutoff():
    """Eight 5 mm beads pressed by 10 N on a rigid solid instead of a wall (no longer refused):
    the solid's contact is an end spring of its Hertz stiffness (a sphere on a rigid flat, as a
    wall: twice the pair's), its point immovable, so end_shift is 0 and the cut-off is (1/pi)
    sqrt(K/m) within the measured mode's bound. On a beam (alpha_n = 0.05) the beam's motion at
    the contact couples the monatomic chain's top mode to the beam's modes: refused, saying so;
    the diatomic chain's top mode (27.7 kHz) is measured (4.8e-4 above Brillouin's edges), with
    end_shift, the top mode's change were that end free (1.2e-3), as a scale of the neglect (not
    a bound)."""
    ds, system = cutoff_run([0.005] * 8, ['solid={kind="rigid"}', "contact.alpha_n=0.0", *ON_THE_SOLID])
    c = cutoff_frequency(ds, system)
    print(f"rigid solid: cut-off {c.cutoff_hz / monatomic_cutoff() - 1:.1e} off")
    assert c.kind == "monatomic" and c.end_shift == 0.0
    assert c.end_stiffness[1] == pytest.approx(2.0, rel=1e-9)  # the equilibrium's forces, to 1e-10 of the load
    assert abs(c.cutoff_hz / monatomic_cutoff() - 1) <= bound(c, ds, c.top_mode_hz) + 1e-9
    ds, system = cutoff_run([0.005] * 8, ['solid={kind="beam"}', *ON_THE_SOLID])
    with pytest.raises(CutoffError, match="the chain presses on the beam, whose motion at the contact couples"):
        cutoff_frequency(ds, system)
    radii = [R_HEAVY if k % 2 == 0 else R_LIGHT for k in range(8)]
    ds, system = cutoff_run(radii, ['solid={kind="beam"}', *ON_THE_SOLID])
    beam = cutoff_frequency(ds, system)
    print(f"beam: edges {[e / a - 1 for e, a in zip(beam.band_edges_hz, diatomic_bands(F0))]} off, "
          f"end_shift {beam.end_shift:.1e}")
    assert beam.end_shift > 0 and linear_chain(ds, system).ends[1].holder == "solid"


def test_an_undamped_wall_is_a_spring_without_dashpot_in_the_linear_chain():
    """The chain's far wall undamped: its end is a spring alone (c = 0), the pairs keep their
    dashpots G delta0^(1/4) (eq. 3: alpha_n sqrt(m A / 2) for two equal beads)."""
    ds, system = cutoff_run([0.005] * 4, ['media.0.undamped_walls=["face"]', 'simulation.duration="0.05ms"'])
    chain = linear_chain(ds, result_system(ds))
    assert chain.ends[1].holder == "C:face" and chain.ends[1].damping == 0.0 and chain.ends[1].stiffness > 0
    A = hertz_A(0.005, 0.005)
    delta0 = (F0 / A) ** (2 / 3)
    want = 0.05 * math.sqrt(sphere_mass(0.005) / 2 * A) * delta0**0.25
    assert chain.damping == pytest.approx([want] * 3, rel=1e-9)  # delta0 from the equilibrium, to 1e-10 of F0


# ---------------------------------------------------------------- granel spectrum's band measures

def test_the_spectrum_dataset_carries_the_band_measures_with_units():
    """A spectrum's summary whose measured curves are a hand-made chain's exact response (six
    beads, the last on a wall): its band measures equal the linearised chain's levels exactly
    (the same values on the same frequencies), and each measured edge, interpolated, lies in the
    same grid step as the linearised chain's exact one; units on every band variable, the
    infinite chain's cut-off, and a report with the table. Without a chain the measured figures
    stand alone and the report says why."""
    from granel.studies.spectrum import BAND_MEASURES, case_metric_units, spectrum_dataset
    from granel.studies.spectrum_report import spectrum_report
    from granel.studies.spectrum_study import spectrum_sweep
    from granel.studies.sweep import cases, summary_dataset

    K, m = 1.2e7, 4.1e-3
    chain = hand_chain([m] * 6, [K] * 5, [2.0] * 5, (ChainEnd(), ChainEnd("far", 2 * K, 4.0)))
    f = np.linspace(3e3, 24e3, 15)
    spec = spectrum_sweep("paper", [], list(f), [0.1], drive="C:1", measure="C:6", both_directions=False)
    results = []
    for case in cases(spec):
        r = chain_response(chain, f[case["index"][0]], "C:1")
        metrics = dict.fromkeys(case_metric_units(spec.spectrum), 0.0)
        metrics.update(transmissibility_fwd=abs(r.velocity[-1] / r.velocity[0]), mobility_fwd=abs(r.velocity[-1]),
                       wall_force_fwd=abs(r.end_force[1]))
        results.append({"index": case["index"], "status": "ok", "metrics": metrics})
    summary = summary_dataset(spec, results)
    ds = spectrum_dataset(summary, spec.spectrum, chain)
    one = ds.sel(direction="fwd", amplitude=0.1)
    for name in ("passband_db", "wall_force_db"):
        assert float(one[name]) == float(one[f"{name}_linear"]), name
    for name in ("cutoff_hz", "db20_hz"):
        got, ref = float(one[name]), float(one[f"{name}_linear"])
        assert np.searchsorted(f, got) == np.searchsorted(f, ref) and got != ref, name
    assert float(ds["band_edge_hz"].sel(band_edge="cut-off")) == pytest.approx(math.sqrt(K / m) / math.pi, rel=4 * EPS)
    assert all(ds[name].attrs["units"] == unit for name, unit in BAND_MEASURES.items())
    assert ds["mobility_linear"].attrs["units"] == "m/(N s)" and ds["frequency"].attrs["units"] == "Hz"
    report = spectrum_report(ds)
    assert "## Band measures" in report and "| cut-off, 3 dB below it [kHz] | fwd |" in report
    bare = spectrum_dataset(summary, spec.spectrum, None, "no chain here")
    assert "cutoff_hz_linear" not in bare and "transmissibility_linear" not in bare
    assert bare.attrs["chain_note"] == "no chain here" and "band_edge_hz" not in bare
    assert float(bare["cutoff_hz"].sel(direction="fwd", amplitude=0.1)) == float(one["cutoff_hz"])
    assert "No linearised chain: no chain here." in spectrum_report(bare)


# ---------------------------------------------------------------- granel spectrum's band measures (slow)

def spectrum_of(tmp_path, radii, alpha, frequencies, cycles):
    """`granel spectrum`'s study (forward only: drive C:1, measure the last bead, which presses
    on the wall "far"), 0.1 N against 10 N, from the Python API; returns the spectrum Dataset and
    its report."""
    from granel.studies.spectrum_study import run_spectrum, spectrum_sweep

    loads = f"""[[excitations]]
granule = "C:1"
kind = "harmonic"
amplitude = 0.1
frequency = 1e4
ramp_cycles = 5
direction = [1.0, 0.0]
[[excitations]]
granule = "C:1"
kind = "constant"
value = {F0!r}
direction = [1.0, 0.0]
"""
    chain_scenario(tmp_path, radii, loads, "1ms", alpha)
    spec = spectrum_sweep(str(tmp_path / "chain.toml"), [], list(frequencies), [0.1], drive="C:1",
                          measure=f"C:{len(radii)}", both_directions=False, cycles=cycles)
    ds = run_spectrum(spec, tmp_path / "spec.nc", workers=2)
    return ds, (tmp_path / "spec.md").read_text()


def grid_step(f, x):
    """The width of the grid interval holding x: the resolution of an edge measured on f."""
    k = int(np.searchsorted(f, x))
    return float(f[k] - f[k - 1])


def check_against_the_linear_chain(ds, names):
    """Each measured edge in `names` within the grid step at the linearised chain's (which is
    exact); the transmissibility at every frequency the chain passes within 40 dB of its level
    within twice the largest drift there (the runs' residual transient, if it halves from window
    to window at least); the levels within the same, in dB."""
    f = ds["frequency"].values
    one = ds.sel(direction="fwd", amplitude=0.1)
    level = float(one["passband_db_linear"])
    lin = one["transmissibility_linear"].values
    near = 20 * np.log10(lin) > level - 40
    tol = 2 * np.nanmax(one["drift"].values[near])
    got = one["transmissibility"].values
    print("transmissibility / linear - 1:", np.round(got / lin - 1, 5), "tolerance", tol)
    assert np.all(np.abs(got[near] / lin[near] - 1) <= tol)
    for name in names:
        m, ref = float(one[name]), float(one[f"{name}_linear"])
        print(f"{name}: measured {m:.1f}, linearised {ref:.1f}, grid step {grid_step(f, ref):.0f}")
        assert abs(m - ref) <= grid_step(f, ref), name
    return 20 * math.log10(1 + tol)


@pytest.mark.slow  # 15 runs, about 15 s on 2 workers
def test_spectrum_band_measures_of_a_monatomic_chain(tmp_path):
    """Eight 5 mm beads, alpha_n = 0.2, 15 frequencies from 3 to 24 kHz (steps of 1.5 kHz), 40
    cycles: the infinite chain's cut-off is (1/pi) sqrt(K/m) (to the equilibrium's 1e-9); the
    measured cut-off (3 dB below the pass band's level) and 20 dB point lie within the grid step
    of the linearised chain's; the transmissibility, the pass band's level and the wall force's
    level agree with the linearised chain's within twice the runs' drift (measured: 14.24 and
    16.85 kHz against 14.28 and 16.89; the level -9.74 dB both; transmissibility within 5e-4)."""
    f = np.linspace(3e3, 24e3, 15)
    ds, report = spectrum_of(tmp_path, [0.005] * 8, 0.2, f, 40)
    assert float(ds["band_edge_hz"].sel(band_edge="cut-off")) == pytest.approx(monatomic_cutoff(), rel=1e-9)
    db = check_against_the_linear_chain(ds, ["cutoff_hz", "db20_hz"])
    one = ds.sel(direction="fwd", amplitude=0.1)
    for name in ("passband_db", "wall_force_db"):
        assert abs(float(one[name]) - float(one[f"{name}_linear"])) <= db, name
    assert "| cut-off, 3 dB below it [kHz] | fwd |" in report and "monatomic" in report


@pytest.mark.slow  # 17 runs of 100 cycles, about 15 s on 2 workers
def test_spectrum_band_measures_of_a_diatomic_chain(tmp_path):
    """Eight beads alternating R = 5 and 3 mm, alpha_n = 0.05 (light enough for the optical band
    to rise 20 dB out of the gap over four cells), 17 frequencies from 3 to 35 kHz (steps of
    2 kHz), 100 cycles: the infinite chain's edges are Brillouin's (to the equilibrium's 1e-9);
    the measured acoustic top and its 20 dB point, the optical band's bottom and top lie within
    the grid step of the linearised chain's; the transmissibility and the gap's mean attenuation
    within twice the drift (measured: 11.58 / 12.90 / 24.79 / 27.38 kHz against 11.28 / 12.81 /
    24.84 / 27.44; gap 30.61 dB against 30.62)."""
    f = np.linspace(3e3, 35e3, 17)
    radii = [R_HEAVY if k % 2 == 0 else R_LIGHT for k in range(8)]
    ds, report = spectrum_of(tmp_path, radii, 0.05, f, 100)
    assert tuple(ds["band_edge_hz"].values) == pytest.approx(diatomic_bands(F0), rel=1e-9)
    db = check_against_the_linear_chain(ds, ["cutoff_hz", "db20_hz", "optical_bottom_hz", "optical_top_hz"])
    one = ds.sel(direction="fwd", amplitude=0.1)
    assert abs(float(one["gap_attenuation_db"]) - float(one["gap_attenuation_db_linear"])) <= 2 * db
    assert "| optical band top [kHz] | fwd |" in report and "diatomic" in report


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
