"""`analysis.wavefield` against answers known without it: Fourier series from the textbook (with
the aliasing of their sampled versions), discrete Parseval, the exactness of the Q8 trace on
quadratic fields, moments of distributions with closed-form moments, power laws, a synthetic
standing wave's place on the frequency-wavenumber map, and the modal energy of a free linear
plate; then `granel wavefield` on short runs: its files, units and exit codes."""

import math
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from granel.analysis import wavefield as W
from granel.cli import app

L = 0.1
ENDS = [(True, True), (False, False), (True, False), (False, True)]
runner = CliRunner()


def harmonic(ends, k, s):
    """The basis functions as docs/wavefield.md states them, written here."""
    if ends == (False, False):
        return np.cos(k * s)
    if ends == (False, True):
        return np.sin(k * (L - s))
    return np.sin(k * s)


@pytest.mark.parametrize("ends", ENDS)
def test_a_sampled_harmonic_has_one_amplitude(ends):
    b = W.spatial_basis(0.0, L, 64, ends)
    s = b.y - b.y0
    index = {(True, True): np.arange(1, 65), (False, False): np.arange(64)}.get(ends, np.arange(64) + 0.5)
    expected_k = index * np.pi / L
    np.testing.assert_allclose(b.k, expected_k, rtol=1e-15)
    for n in (0, 5, 63):
        a = W.forward(b, harmonic(ends, b.k[n], s))
        expected = np.zeros(64)
        expected[n] = 1.0
        np.testing.assert_allclose(a, expected, atol=1e-12)
    v = np.random.default_rng(1).normal(size=(3, 64))
    np.testing.assert_allclose(W.inverse(b, W.forward(b, v)), v, atol=1e-12)


def test_sine_series_of_a_parabola():
    """s (L - s) = sum_n 8 L^2 / (pi^3 n^3) sin(n pi s / L), n odd (a textbook series); the DST of
    N samples folds in the harmonics n + 2p(N+1) and 2p(N+1) - n (with a minus sign): the
    difference from the series is that alias sum, computed here from the series."""
    n_samples = 50
    b = W.spatial_basis(0.0, L, n_samples, (True, True))
    a = W.forward(b, (b.y - b.y0) * (L - (b.y - b.y0)))

    def series(n):
        n = np.asarray(n)
        return np.where(n % 2 == 1, 8 * L**2 / (np.pi**3 * n.astype(float) ** 3), 0.0)

    M = n_samples + 1
    for n in range(1, 12):
        p = np.arange(1, 20000)
        aliased = series(n) + np.sum(series(2 * p * M + n) - series(2 * p * M - n))
        assert a[n - 1] == pytest.approx(aliased, rel=1e-10, abs=1e-16)
        assert abs(a[n - 1] - series(n)) < 1e-3 * abs(series(1))


def test_cosine_series_of_a_square():
    """s^2 = L^2/3 + sum_n 4 L^2 (-1)^n / (pi^2 n^2) cos(n pi s / L) (a textbook series); the
    DCT-I of N samples folds in the harmonics 2p(N-1) +- n."""
    n_samples = 41
    b = W.spatial_basis(0.0, L, n_samples, (False, False))
    a = W.forward(b, (b.y - b.y0) ** 2)

    def series(n):
        n = np.asarray(n, float)
        return np.where(n == 0, L**2 / 3, 4 * L**2 * (-1.0) ** n / (np.pi**2 * np.maximum(n, 1) ** 2))

    M = n_samples - 1
    p = np.arange(1, 200000)
    for n in range(1, 10):
        aliased = series(n) + np.sum(series(2 * p * M + n) + series(2 * p * M - n))
        assert a[n] == pytest.approx(aliased, rel=1e-6)


@pytest.mark.parametrize("ends", ENDS)
def test_parseval(ends):
    """The harmonics' energies add up to the trapezoid rule's 1/2 m integral of v^2 along the
    length (its end samples at half weight where the basis includes an end)."""
    b = W.spatial_basis(0.0, L, 37, ends)
    lines = W.NodeLines("plate", np.array([0.0, 1.0]), np.array([2.0, 3.0]), ("x", "y"), b, None, 1e-3)
    v = np.random.default_rng(2).normal(size=(5, 2, 2, 37))
    weights = np.ones(37)
    dy = b.y[1] - b.y[0]
    if ends == (False, False):
        weights[[0, -1]] = 0.5
    elif ends == (True, False):
        weights[-1] = 0.5
    elif ends == (False, True):
        weights[0] = 0.5
    direct = 0.5 * np.einsum("i,tijn,n->t", lines.mass, v**2, weights) * dy
    spectrum = W.wavenumber_spectrum(v, lines, np.arange(5.0))
    np.testing.assert_allclose(spectrum.energy.sum(axis=0), direct, rtol=1e-12)
    # the bands of a partition give the field back; their energies add up
    edges = [0, 300, 900, np.inf]
    total = sum(W.band_field(spectrum, lines, lo, hi) for lo, hi in zip(edges[:-1], edges[1:]))
    np.testing.assert_allclose(total, v, atol=1e-12)


def test_plate_lines_carry_the_q8_field_exactly():
    """On a plate without contacts or clamps (T = I), a field the Q8 elements hold exactly
    (quadratic in x and y) is sampled on the vertex columns without error, and the lines' masses
    add up to rho t times the width."""
    from granel.solid.plate import PlateMesh
    from granel.solid.recipe import SolidRecipe, build_solid_model

    r = SolidRecipe("plate", (), x0=0.0, y0=0.0, width=0.01, length=0.1, thickness=0.001, E=200e9, nu=0.3, rho=7850.0,
                    mesh=PlateMesh(nx=4, max_size=5e-3), clamped=(False, False))
    model = build_solid_model(r)
    lines = W.node_lines(model)
    assert len(lines.x) == 5 and lines.basis.ends == "free-free"
    assert lines.mass.sum() == pytest.approx(7850.0 * 0.001 * 0.01, rel=1e-12)

    def field(x, y):
        return np.stack([1 + 2 * y - 30 * y**2 + 5 * x - 40 * x * y, 3 * x**2 - 7 * y * x + 0.5])

    nodes = model.nodes
    full = np.zeros(model.T.shape[0])
    u = field(nodes[:, 0], nodes[:, 1])
    full[model.node_dofs[0]], full[model.node_dofs[1]] = u[0], u[1]
    q = model.T.T @ full
    assert np.allclose(model.T @ q, full)
    sampled = (lines.sampling @ q).reshape(lines.shape)
    X, Y = np.meshgrid(lines.x, lines.basis.y, indexing="ij")
    np.testing.assert_allclose(sampled, np.moveaxis(field(X, Y), 0, 1), atol=1e-13)


def test_moments_of_known_distributions():
    k = np.arange(0.0, 2000.0, 10.0)
    gauss = np.exp(-0.5 * ((k - 1000.0) / 50.0) ** 2)  # 20 standard deviations from either end
    flat = np.where(k < 100, 1.0, 0.0)
    m = W.spectral_moments(k, np.column_stack([gauss, flat, np.zeros_like(k)]))
    # a Gaussian sampled 5 per standard deviation: the sums' error is exp(-2 pi^2 25), nil
    assert m.centroid[0] == pytest.approx(1000.0, rel=1e-12)
    assert m.variance[0] == pytest.approx(2500.0, rel=1e-10)
    assert m.entropy[1] == pytest.approx(math.log(10), rel=1e-14)  # uniform over 10 harmonics
    assert np.isnan(m.variance[2]) and m.total[2] == 0
    limited = W.spectral_moments(k, gauss[:, None], k_max=1000.0)
    assert limited.centroid[0] < 1000.0


def test_growth_exponent():
    t = np.linspace(0, 1e-3, 401)
    exact = W.growth_exponent(t, 7e8 * np.maximum(t - 2e-4, 0) ** 1.3, 2e-4, 1e-3)
    assert exact.exponent == pytest.approx(1.3, rel=1e-10) and exact.prefactor == pytest.approx(7e8, rel=1e-8)
    assert exact.points == 320
    noisy = 5e3 * np.maximum(t - 1e-4, 0) ** 0.7 * np.exp(np.random.default_rng(3).normal(0, 0.2, len(t)))
    fit = W.growth_exponent(t, noisy, 1e-4, 1e-3)
    assert abs(fit.exponent - 0.7) < 4 * fit.stderr and fit.stderr < 0.05
    assert np.isnan(W.growth_exponent(t, np.zeros_like(t), 0.0, 1e-3).exponent)


def test_a_standing_wave_sits_on_its_place_on_the_map():
    """sin(beta y + phi) cos(2 pi f t) on a clamped strip's samples: the map's ridge is at (beta,
    f) to within 0.1 of a padded bin in each direction (the log-parabola through a padded Hann
    main lobe), for beta beyond the window's wavenumber (its image at -beta then out of reach)."""
    b = W.spatial_basis(0.0, L, 200, (True, True))
    lines = W.NodeLines("plate", np.array([0.0]), np.array([1.0]), ("x",), b, None, 1e-3)
    t = np.arange(801) * 1e-6
    beta, f = 1.37 * W.window_wavenumber(lines), 47.3e3
    for phase in (0.0, 0.9):
        v = np.sin(beta * b.y[None, :] + phase) * np.cos(2 * np.pi * f * t)[:, None]
        fk = W.frequency_wavenumber_map(v[:, None, None, :], lines, t)
        r = W.map_ridges(fk, 1e-2)
        i = int(np.argmax(r.power))
        assert len(r.k) == 1
        assert abs(r.k[i] - beta) < 0.1 * (fk.k[1] - fk.k[0])
        assert abs(r.f[i] - f) < 0.1 * (fk.f[1] - fk.f[0])


# --------------------------------------------------------------------------------------------
# on runs


def invoke(args):
    res = runner.invoke(app, [str(a) for a in args])
    out = " ".join(res.output.split())
    assert "Traceback" not in res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), repr(res.exception)
    return res.exit_code, out


def _run(path, *args):
    res = subprocess.run([sys.executable, "-m", "granel", "run", *map(str, args), "-o", str(path)], capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Short runs of the paper's set-up: plate, beam (0.05 ms) and rigid solid."""
    d = tmp_path_factory.mktemp("wavefield")
    out = {}
    for solid in ("plate", "beam", "rigid"):
        out[solid] = d / f"{solid}.nc"
        _run(out[solid], "paper", "--solid", solid, "--duration", "0.05ms")
    return out


@pytest.mark.parametrize("solid", ["plate", "beam"])
def test_wavefield_command(runs, solid, tmp_path):
    import xarray as xr

    from granel.guard.owners import is_granel_file

    folder = tmp_path / "wf"
    code, out = invoke(["wavefield", runs[solid], "-o", folder, "--bands", "3"])
    assert code == 0, out
    for name in ("wavefield.nc", "kt.png", "fk.png", "moments.png", "bands.png"):
        assert is_granel_file(folder / name), name
    with xr.open_dataset(folder / "wavefield.nc", engine="h5netcdf") as ds:
        assert ds["k"].attrs["units"] == "rad/m" and ds["t"].attrs["units"] == "s" and ds["f"].attrs["units"] == "Hz"
        assert ds["energy"].dims == ("k", "t") and ds["fk_power"].dims == ("k_map", "f")
        assert ds.sizes["band"] == 3 and ds.attrs["ends"] == "clamped-clamped"
        assert ds.attrs["solid_kind"] == solid
        # E(k, t) adds up to the solid's kinetic energy 1/2 v'M v up to the quadrature of the sampled field (the
        # trapezoid rule, against the consistent mass: second order in the spacing; 1 % bounds it loosely here)
        assert ds.attrs["kinetic_check"] < 0.01, ds.attrs["kinetic_check"]
    code, out = invoke(["wavefield", runs[solid], "-o", folder, "--bands", "3"])  # a rerun replaces its own files
    assert code == 0, out


@pytest.mark.slow  # a movie: ffmpeg and matplotlib, about 5 s
def test_wavefield_movie(runs, tmp_path):
    code, out = invoke(["wavefield", runs["plate"], "-o", tmp_path / "m", "--movie", "--frames", "5"])
    assert code == 0, out
    assert (tmp_path / "m" / "bands.mp4").exists() or (tmp_path / "m" / "bands.gif").exists()


def test_rigid_solid_is_refused(runs, tmp_path):
    code, out = invoke(["wavefield", runs["rigid"], "-o", tmp_path / "wf"])
    assert code == 2 and "rigid" in out and "rigid.nc" in out
    assert not (tmp_path / "wf").exists()


@pytest.mark.parametrize("args,words", [(["--bands", "0"], "--bands"), (["--bands", "5,3"], "ascending"),
                                        (["--fit", "0.5ms"], "START:END"), (["--k-max", "-3"], "--k-max"),
                                        (["--frames", "0"], "frames"), (["--bands", "9000,9100"], "wavenumbers up to")])
def test_bad_options_exit_2_before_anything(runs, tmp_path, args, words):
    code, out = invoke(["wavefield", runs["plate"], "-o", tmp_path / "wf", *args])
    assert code == 2 and words in out, out
    assert not (tmp_path / "wf").exists()


def test_bad_files(runs, tmp_path):
    bad = tmp_path / "notes.nc"
    bad.write_text("not NetCDF\n")
    code, out = invoke(["wavefield", bad, "-o", tmp_path / "wf"])
    assert code == 4 and "notes.nc" in out
    code, out = invoke(["wavefield", tmp_path / "missing.nc", "-o", tmp_path / "wf"])
    assert code == 2 and "missing.nc" in out
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("keep me")
    code, out = invoke(["wavefield", runs["plate"], "-o", mine])
    assert code == 2 and "keep.txt" in out
    assert sorted(p.name for p in mine.iterdir()) == ["keep.txt"]


def test_nodal_and_modal_states_give_one_field(runs):
    """A result that stores the reduced nodal state (solids too large for all modes) gives the
    velocities its modal twin gives: q' = Phi eta' mapped by the same lines."""
    from granel.analysis.result_model import result_modes, result_solid
    from granel.run import load_result

    ds = load_result(runs["plate"])
    model, modes = result_solid(ds), result_modes(ds)
    lines = W.node_lines(model)
    modal = W.sampled_velocities(ds, lines, W.sampled_shapes(lines, modes))
    v = (np.asarray(modes.shapes) @ ds["solid_eta_dot"].values.astype(float).T).T
    nodal = ds.drop_vars(["solid_eta", "solid_eta_dot", "mode_omega"]).assign(
        solid_v=(("solid_time", "dof"), v.astype(np.float32)))
    # both stored and multiplied in float32 (6e-8 a rounding, over sums of 3584 terms)
    np.testing.assert_allclose(W.sampled_velocities(nodal, lines), modal, rtol=1e-4, atol=1e-6 * np.abs(modal).max())


def bloch_error(K, M, kl):
    """The lowest branch's relative frequency error of a 1-D element chain (element matrices K, M
    of unit length, for a wave equation with unit speed), at wavenumber k l: Bloch's condition
    ties the next element's first node(s) to this one's by exp(i k l)."""
    from scipy.linalg import eigh

    n = K.shape[0] // 2 if K.shape[0] == 4 else 1  # Hermite: 2 DOFs a node; quadratic: 1 a node
    z = np.exp(1j * kl)
    if n == 1:  # nodes: end, middle, next end = z * end
        T = np.array([[1, 0], [0, 1], [z, 0]])
    else:  # (w, w') at both ends
        T = np.array([[1, 0], [0, 1], [z, 0], [0, z]])
    w2 = np.sort(np.real(eigh(T.conj().T @ K @ T, T.conj().T @ M @ T, eigvals_only=True)))[0]
    exact = kl if n == 1 else kl**2  # w = k (strings) or k^2 (Euler-Bernoulli, EI = rho A = 1)
    return np.sqrt(w2) / exact - 1


def test_resolution_estimate_is_the_elements_dispersion():
    """FE_DISPERSION (kl)^4 / 1440 is the leading frequency error of quadratic elements with
    consistent mass (their matrices from the textbook, written here) and of the beam's Hermite
    cubics (`solid.beam`'s matrices): at kl = 0.25 both agree with it to 1 % (the next term is
    smaller by a factor of order (kl)^2: 1.3 % at kl = 0.5 for the quadratics), and at the
    resolved wavenumber (0.25 %) the errors stay below it."""
    from granel.solid.beam import hermite_mass, hermite_stiffness

    quad_K = np.array([[7, -8, 1], [-8, 16, -8], [1, -8, 7]]) / 3.0
    quad_M = np.array([[4, 2, -1], [2, 16, 2], [-1, 2, 4]]) / 30.0
    for K, M in ((quad_K, quad_M), (hermite_stiffness(1.0, 1.0), hermite_mass(1.0, 1.0))):
        assert bloch_error(K, M, 0.25) == pytest.approx(W.FE_DISPERSION * 0.25**4, rel=1e-2)
        kl = (W.FE_ERROR / W.FE_DISPERSION) ** 0.25
        assert 0 < bloch_error(K, M, kl) < W.FE_ERROR
