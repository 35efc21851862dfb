"""Analysis functions against hand-built signals with known answers, and the figures,
animations and report produced from short runs."""

import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from granel import scenario as S
from granel.analysis import (
    accumulated_modal_energy,
    amplitude_spectrum,
    dominant_frequency,
    peak_time,
    peak_width,
    zero_crossing_frequency,
    arrival_time,
    modal_coordinates,
    modal_energies,
    modes_for_fraction,
    nonreciprocity_index,
    solid_energy_density,
    time_averaged_accumulation,
)
from granel.cli import app
from granel.solid.base import Material, Slab
from granel.solid.beam import build_beam, energy_density_strips
from granel.scenario import build_solid
from granel.solid.modal import modal_analysis


def test_arrival_time_of_a_delayed_pulse():
    t = np.linspace(0, 1e-3, 20001)
    t0, sig = 4e-4, 2e-5
    s = np.exp(-0.5 * ((t - t0) / sig) ** 2)
    # |s| reaches half its peak at t0 - sig sqrt(2 ln 2)
    assert arrival_time(t, s, 0.5) == pytest.approx(t0 - sig * math.sqrt(2 * math.log(2)), abs=2e-8)
    assert arrival_time(t, -3 * s, 0.5) == pytest.approx(t0 - sig * math.sqrt(2 * math.log(2)), abs=2e-8)
    assert math.isnan(arrival_time(t, 0 * s))


def test_peak_time_and_width_of_a_sampled_pulse():
    """A Gaussian pulse sampled coarsely: the parabola through the top three samples finds its
    centre to a small fraction of a sample, and the half-maximum width is 2 sqrt(2 ln 2) sigma."""
    t0, sig = 2.37e-4, 3e-5
    t = np.arange(0, 8e-4, 1e-6)
    s = 5 * np.exp(-0.5 * ((t - t0) / sig) ** 2)
    tp, sp = peak_time(t, s)
    assert tp == pytest.approx(t0, abs=2e-9)  # 1/500 of a sample
    assert sp == pytest.approx(5, rel=1e-4)
    assert peak_width(t, s) == pytest.approx(2 * math.sqrt(2 * math.log(2)) * sig, rel=1e-3)
    # a plateau at the end of the record: the sample itself, no extrapolation
    assert peak_time(t, t)[0] == t[-1]


@pytest.mark.parametrize("f0", [4.7e3, 9.3e3, 21.1e3])
def test_frequency_content_of_synthetic_traces(f0):
    """Zero crossings and the spectral peak recover a sine's frequency over a window, whatever its
    phase and offset; the slower of two traces is found slower by both measures (Fig. 3's test)."""
    t = np.arange(0, 8e-4 + 1e-12, 1e-6)
    s = 0.2 * np.sin(2 * np.pi * f0 * t + 0.7) + 0.05
    window = (4e-4, 8e-4)
    assert zero_crossing_frequency(t, s, window) == pytest.approx(f0, rel=5e-3)
    assert dominant_frequency(t, s, window) == pytest.approx(f0, rel=1e-2)
    f, S = amplitude_spectrum(t, s, window)
    assert S.max() == pytest.approx(0.2, rel=0.02)  # normalised to the sine's amplitude
    fast = 0.1 * np.sin(2 * np.pi * 1.9 * f0 * t) + 0.02 * np.sin(2 * np.pi * 0.3 * f0 * t)
    assert zero_crossing_frequency(t, s, window) < zero_crossing_frequency(t, fast, window)
    assert dominant_frequency(t, s, window) < dominant_frequency(t, fast, window)


def test_fig5_snapshot_is_the_solid_energy_maximum():
    """Fig. 5's instant is the stored output with the largest solid energy (not a typed-in time)."""
    from granel.viz.figures import snapshot_time

    t = np.arange(0, 8e-4, 1e-6)
    e = np.exp(-0.5 * ((t - 1.234e-4) / 2e-5) ** 2) + 0.6 * np.exp(-0.5 * ((t - 5e-4) / 1e-5) ** 2)
    ds = xr.Dataset({"energy_solid": ("time", e)}, coords={"time": t})
    assert snapshot_time(ds) == pytest.approx(1.23e-4, abs=1e-12)
    ds["energy_solid"] = ("time", e[::-1].copy())
    assert snapshot_time(ds) == pytest.approx(t[-1] - 1.23e-4, abs=1e-12)


def test_claim_rules():
    """The explicit rules behind the verdicts."""
    from granel.studies.claims import about, potential_dominance

    assert about(0.141, 0.2) and not about(0.139, 0.2) and about(0.259, 0.2) and not about(0.261, 0.2)
    t = np.linspace(0, 1e-3, 1001)
    K = np.where(t < 5e-4, 0.1, 2.0)
    P = np.ones_like(t)
    P[t > 9e-4] = 0.0  # the solid is quiet at the end: below 2 % of the input, not judged
    K[t > 9e-4] = 0.0
    ds = xr.Dataset({"energy_solid_kinetic": ("time", K), "energy_solid_potential": ("time", P),
                     "energy_solid": ("time", P + K), "input_work": ("time", np.full_like(t, 10.0))}, coords={"time": t})
    # active (> 0.2 J) for t <= 0.9 ms; P > K before 0.5 ms only
    assert potential_dominance(ds) == pytest.approx(500 / 901, abs=2e-3)
    assert potential_dominance(ds, after=5e-4) == 0.0


def test_nonreciprocity_index():
    s = np.sin(np.linspace(0, 7, 500))
    assert nonreciprocity_index(s, s) == 0.0
    assert nonreciprocity_index(s, -s) == pytest.approx(1.0)
    assert nonreciprocity_index(2 * s, 2 * np.roll(s, 30)) == pytest.approx(nonreciprocity_index(s, np.roll(s, 30)))


def test_a_pure_mode_keeps_its_energy():
    """Modal coordinates of a vibrating single mode: all energy in that mode, constant in time."""
    beam = build_beam(Slab(0, 0, 0.01, 0.1, 0.001), Material(200e9, 7850, 0.3), [("c", "left", 0.05)], 40)
    md = modal_analysis(beam)
    k, A = 2, 3e-6
    w = md.omega[k]
    t = np.linspace(0, 5 * 2 * np.pi / w, 400)
    q = np.outer(A * np.cos(w * t), md.shapes[:, k])
    v = np.outer(-A * w * np.sin(w * t), md.shapes[:, k])
    ds = xr.Dataset({"solid_x": (("solid_time", "dof"), q), "solid_v": (("solid_time", "dof"), v)}, coords={"solid_time": t})
    tt, X, Xd, om = modal_coordinates(ds, md, beam)
    E = modal_energies(X, Xd, om)
    expected = 0.5 * (A * w) ** 2
    assert np.allclose(E[:, k], expected, rtol=1e-9)
    others = np.delete(E, k, axis=1)
    assert others.max() < 1e-12 * expected
    # and the modal energies add up to the solid energy 1/2 v'Mv + 1/2 q'Kq
    assert E.sum(axis=1) == pytest.approx([sum(beam.energy(q[i], v[i])) for i in range(len(t))], rel=1e-9)
    acc = time_averaged_accumulation(E, tt)
    assert acc[k - 1] < 1e-12 and acc[k] == pytest.approx(1.0)
    assert modes_for_fraction(acc, 0.9) == k + 1
    cum = accumulated_modal_energy(E, (1, 3, 10))
    assert np.allclose(cum[1], 0, atol=1e-12 * expected) and np.allclose(cum[3], expected, rtol=1e-9)


def test_energy_densities_integrate_back_to_the_total():
    rng = np.random.default_rng(2)
    beam = build_beam(Slab(0, 0, 0.01, 0.1, 0.001), Material(200e9, 7850, 0.3), [("c", "left", 0.05)], 40)
    q, v = rng.normal(size=beam.ndof) * 1e-6, rng.normal(size=beam.ndof)
    xe, ys, w = energy_density_strips(beam, q, v, strips=21)
    # each strip's area times the thickness, summed: the beam's energy (the strips hold the means)
    per_el = (w * np.diff(xe)[None, :]).sum(axis=1) * 0.001 * np.diff(ys)
    assert per_el.sum() == pytest.approx(sum(beam.energy(q, v)), rel=1e-10)  # round-off of ~10^3 terms
    # the strain part is 12 s^2 times its mean: on the middle strip, |s| < 1/42, its mean is 4 (1/42)^2
    kin, pot = beam.element_energies(q, v)
    mid = w[:, 10]
    assert np.allclose(mid, (kin + pot * 4 / 42**2) / beam.element_volume, rtol=1e-12)
    sc = S.load("paper")
    system, _, _ = S.build_granular(sc)
    plate = build_solid(sc, system)
    q, v = rng.normal(size=plate.ndof) * 1e-7, rng.normal(size=plate.ndof)
    dens = solid_energy_density(plate, q, v)
    assert (dens * plate.element_volume).sum() == pytest.approx(sum(plate.energy(q, v)), rel=1e-9)


# ---------------------------------------------------------------- figures, movies, report


@pytest.fixture(scope="module")
def short_study(tmp_path_factory):
    from granel.studies.paper import PaperOptions, paper_study

    out = tmp_path_factory.mktemp("paper")
    options = PaperOptions(animations=True, extra=('simulation.duration="0.06ms"',), frames=4, fig11_window=2.5e-5)
    res = paper_study(out, options)
    return out, res


def _png_ok(path, min_bytes=20_000):
    from PIL import Image

    im = Image.open(path)
    return path.stat().st_size > min_bytes and min(im.size) > 300


@pytest.mark.slow  # a shortened granel paper study (about 40 s)
def test_paper_study_writes_every_figure(short_study):
    out, res = short_study
    figs = out / "figures"
    for stem in ("fig1_geometry", "fig2_meshes", "fig3_velocities", "fig4_energies", "fig5_energy_density", "fig7_modal_accumulation",
                 "fig8_solid_energy_partition", "fig9_time_averaged_modes", "fig10_friction_law", "fig11_eigenvalues"):
        assert _png_ok(figs / f"{stem}.png"), stem
        assert (figs / f"{stem}.pdf").stat().st_size > 5_000
    assert _png_ok(figs / "fig6_modes.png")
    text = (out / "report.md").read_text()
    assert "| # | where | statement | paper | granel | rule | verdict |" in text and "plate-SSGMC-strong" in text
    assert "## What the outer walls change: the free-edge variant" in text and "## Errata" in text
    assert len(res["claims"]) >= 22
    # the free-edge table has a row per claim, and its runs really have no outer wall
    free = text[text.index("## What the outer walls change"):text.index("## Errata")]
    assert sum(line.startswith("| ") and line[2].isdigit() for line in free.splitlines()) == len(res["claims"])
    from granel.io.results import read_netcdf

    assert "outer_wall = false" in read_netcdf(out / "runs-free-edge" / "plate-LSGM3-strong.nc").attrs["scenario"]
    assert "outer_wall = true" in read_netcdf(out / "runs" / "plate-LSGM3-strong.nc").attrs["scenario"]


@pytest.mark.slow  # a shortened granel paper study (about 40 s)
def test_report_numbers_come_from_the_data(short_study):
    from granel.analysis import peak_time
    from granel.io.results import read_netcdf

    out, res = short_study
    ds = read_netcdf(out / "runs" / "plate-SSGMC-strong.nc")
    frac = peak_time(ds["time"].values, ds["energy_solid"].values)[1] / ds["input_work"].values.max()
    row = next(c for c in res["claims"] if c["claim"] == "the plate's energy peak, strong shock on the SSGM")
    assert row["granel"] == f"{100 * frac:.1f} %"
    assert row["verdict"] == ("agree" if abs(frac / 0.2 - 1) <= 0.3 else "differ")
    # Fig. 11 comes from the paper's own algorithm, run over its window
    f11 = read_netcdf(next((out / "runs").glob("paper-solver-*.nc")))
    assert f11.attrs["solver_name"] == "paper" and f11["time"].values[-1] == pytest.approx(2.5e-5)
    row = next(c for c in res["claims"] if c["where"].startswith("Fig. 11"))
    assert f"{f11['step_lambda'].values.max():.3f}" in row["granel"]


@pytest.mark.slow  # a shortened granel paper study (about 40 s)
def test_animations_have_the_frames(short_study):
    import imageio.v3 as iio

    out, _ = short_study
    movies = sorted((out / "animations").iterdir())
    assert len(movies) == 24  # Appendix C in full: 12 cases x (deformation, energy density)
    frames = iio.imread(movies[0])
    assert frames.shape[0] == 4 and frames.shape[-1] == 3


def _captured(runs, make):
    """Run a figure function with save_both intercepted: per saved figure, its axes."""
    from granel.viz import figures as F

    captured = {}
    orig = F.save_both

    def grab(fig, path):
        captured[str(path)] = fig.axes
        return orig(fig, path)

    F.save_both = grab
    try:
        make()
    finally:
        F.save_both = orig
    return captured


@pytest.mark.slow  # a shortened granel paper study (about 40 s)
def test_figure_curve_counts(short_study):
    from granel.viz import figures as F
    from granel.studies.paper import CASES, case_tag
    from granel.io.results import read_netcdf

    out, _ = short_study
    runs = {c: read_netcdf(out / "runs" / f"{case_tag(c)}.nc") for c in CASES}

    def make():
        F.fig4_energies(runs, out / "x4")
        F.fig9_time_averaged(runs, out / "x9")
        F.fig8_solid_partition(runs, out / "x8")
        F.fig7_modal_accumulation(runs, out / "x7")
        F.fig5_energy_density(runs, out / "x5")

    cap = {k: v for k, v in _captured(runs, make).items()}
    lines = {k: [len(ax.get_lines()) for ax in axes] for k, axes in cap.items()}
    assert lines[str(out / "x4")] == [10] * 6  # 5 curves x (plate, beam) per panel
    insets = [[len(c.get_lines()) for c in ax.child_axes] for ax in cap[str(out / "x4")]]
    assert insets == [[]] * 5 + [[2]]  # the inset of (f): the solid's energy, plate and beam
    assert lines[str(out / "x9")] == [4] * 3  # (plate, beam) x (LSGM, SSGM)
    assert lines[str(out / "x8")] == [3, 3]
    assert lines[str(out / "x7")] == [4, 4]  # total + 6, 100, 1000 modes
    # Fig. 5: each side at the plate's own energy maximum, printed in the titles; one frame for all
    panels = cap[str(out / "x5")][:4]
    for ax, (solid, exc) in zip(panels, [("plate", "LSGM:3"), ("beam", "LSGM:3"), ("plate", "SSGM:C"), ("beam", "SSGM:C")]):
        plate = runs[("plate", exc, "strong")]
        t = plate["time"].values[int(np.argmax(plate["energy_solid"].values))]
        assert f"t = {t * 1e3:.3f} ms" in ax.get_title()
        assert ax.get_xlim() == panels[0].get_xlim() and ax.get_ylim() == panels[0].get_ylim()


def test_reciprocity_command(tmp_path):
    res = CliRunner().invoke(app, ["reciprocity", "paper", "--solid", "rigid", "--duration", "0.05ms", "--out", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    import json

    m = json.loads(res.stdout[res.stdout.index("{"):])
    # rigid solid: nothing crosses, the far granule never moves
    assert m["forward"]["peak_velocity_m_s"] < 1e-9
    assert (tmp_path / "fig3_velocities.png").exists()
