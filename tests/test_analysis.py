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
    arrival_time,
    beam_energy_density_grid,
    modal_coordinates,
    modal_energies,
    modes_for_fraction,
    nonreciprocity_index,
    solid_energy_density,
    time_averaged_accumulation,
)
from granel.cli import app
from granel.solid.beam import build_beam
from granel.solid.build import build_solid
from granel.solid.modal import modal_analysis


def test_arrival_time_of_a_delayed_pulse():
    t = np.linspace(0, 1e-3, 20001)
    t0, sig = 4e-4, 2e-5
    s = np.exp(-0.5 * ((t - t0) / sig) ** 2)
    # |s| reaches half its peak at t0 - sig sqrt(2 ln 2)
    assert arrival_time(t, s, 0.5) == pytest.approx(t0 - sig * math.sqrt(2 * math.log(2)), abs=2e-8)
    assert arrival_time(t, -3 * s, 0.5) == pytest.approx(t0 - sig * math.sqrt(2 * math.log(2)), abs=2e-8)
    assert math.isnan(arrival_time(t, 0 * s))


def test_nonreciprocity_index():
    s = np.sin(np.linspace(0, 7, 500))
    assert nonreciprocity_index(s, s) == 0.0
    assert nonreciprocity_index(s, -s) == pytest.approx(1.0)
    assert nonreciprocity_index(2 * s, 2 * np.roll(s, 30)) == pytest.approx(nonreciprocity_index(s, np.roll(s, 30)))


def test_a_pure_mode_keeps_its_energy():
    """Modal coordinates of a vibrating single mode: all energy in that mode, constant in time."""
    beam = build_beam(0, 0, 0.01, 0.1, 0.001, 200e9, 7850, [("c", "left", 0.05)], 40)
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
    beam = build_beam(0, 0, 0.01, 0.1, 0.001, 200e9, 7850, [("c", "left", 0.05)], 40)
    q, v = rng.normal(size=beam.ndof) * 1e-6, rng.normal(size=beam.ndof)
    xs, ys, w = beam_energy_density_grid(beam, q, v, nx=401)
    # integrate across the width (trapezoid on the fine grid) and along each element
    from scipy.integrate import simpson

    per_el = simpson(w, x=xs, axis=1) * 0.001 * np.diff(ys)  # Simpson is exact for the parabola
    assert per_el.sum() == pytest.approx(sum(beam.energy(q, v)), rel=1e-10)
    # the strain part vanishes on the neutral axis
    kin, pot = beam.element_energies(q, v)
    mid = w[:, 200]
    assert np.allclose(mid, kin / beam.element_volume, rtol=1e-9)
    sc = S.load("paper")
    system, _, _ = S.build_granular(sc)
    plate = build_solid(sc, system)
    q, v = rng.normal(size=plate.ndof) * 1e-7, rng.normal(size=plate.ndof)
    dens = solid_energy_density(plate, q, v)
    assert (dens * plate.element_volume).sum() == pytest.approx(sum(plate.energy(q, v)), rel=1e-9)


# ---------------------------------------------------------------- figures, movies, report


@pytest.fixture(scope="module")
def short_study(tmp_path_factory):
    from granel.report import paper_study

    out = tmp_path_factory.mktemp("paper")
    res = paper_study(out, animations=True, extra=['simulation.duration="0.06ms"'], frames=4)
    return out, res


def _png_ok(path, min_bytes=20_000):
    from PIL import Image

    im = Image.open(path)
    return path.stat().st_size > min_bytes and min(im.size) > 300


def test_paper_study_writes_every_figure(short_study):
    out, res = short_study
    figs = out / "figures"
    for stem in ("fig3_velocities", "fig4_energies", "fig5_energy_density", "fig7_modal_accumulation",
                 "fig8_solid_energy_partition", "fig9_time_averaged_modes", "fig10_friction_law", "fig11_eigenvalues"):
        assert _png_ok(figs / f"{stem}.png"), stem
        assert (figs / f"{stem}.pdf").stat().st_size > 5_000
    assert _png_ok(figs / "fig6_modes.png")
    text = (out / "report.md").read_text()
    assert "| claim | paper | granel | verdict |" in text and "plate-SSGMC-strong" in text


def test_report_numbers_come_from_the_data(short_study):
    from granel.results import read_netcdf

    out, res = short_study
    ds = read_netcdf(out / "runs" / "plate-SSGMC-strong.nc")
    frac = ds["energy_solid"].values.max() / ds["input_work"].values.max()
    row = next(c for c in res["claims"] if c["claim"] == "peak plate energy, strong shock on SSGM")
    assert row["granel"] == f"{100 * frac:.1f} %"


def test_animations_have_the_frames(short_study):
    import imageio.v3 as iio

    out, _ = short_study
    movies = sorted((out / "animations").iterdir())
    assert len(movies) == 8  # 4 strong cases x (deformation, energy density)
    frames = iio.imread(movies[0])
    assert frames.shape[0] == 4 and frames.shape[-1] == 3


def test_figure_curve_counts(short_study):
    import matplotlib

    matplotlib.use("Agg")
    from granel import figures as F
    from granel.report import CASES, case_tag
    from granel.results import read_netcdf

    out, _ = short_study
    runs = {c: read_netcdf(out / "runs" / f"{case_tag(c)}.nc") for c in CASES}
    captured = {}
    orig = F.save_both

    def grab(fig, path):
        captured[str(path)] = [len(ax.get_lines()) for ax in fig.axes]
        return orig(fig, path)

    F.save_both = grab
    try:
        F.fig4_energies(runs, out / "x4")
        F.fig9_time_averaged(runs, out / "x9")
        F.fig8_solid_partition(runs, out / "x8")
        F.fig7_modal_accumulation(runs, out / "x7")
    finally:
        F.save_both = orig
    assert captured[str(out / "x4")] == [10] * 6  # 5 curves x (plate, beam) per panel
    assert captured[str(out / "x9")] == [4] * 3  # (plate, beam) x (LSGM, SSGM)
    assert captured[str(out / "x8")] == [3, 3]
    assert captured[str(out / "x7")] == [4, 4]  # total + 6, 100, 1000 modes


def test_reciprocity_command(tmp_path):
    res = CliRunner().invoke(app, ["reciprocity", "paper", "--solid", "rigid", "--duration", "0.05ms", "--out", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    import json

    m = json.loads(res.stdout[res.stdout.index("{"):])
    # rigid solid: nothing crosses, the far granule never moves
    assert m["forward"]["peak_velocity_m_s"] < 1e-9
    assert (tmp_path / "fig3_velocities.png").exists()
