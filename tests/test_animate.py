"""The Appendix C movies: frame counts, moving pictures, the energy density of eq. (14) on the
artists equal to figures.draw_energy_density, blitting equal to a full redraw, and parallel
rendering equal to serial rendering."""

import matplotlib.pyplot as plt
import numpy as np
import pytest

from granel.viz import animate as A

imageio = pytest.importorskip("imageio.v3")


@pytest.fixture(scope="module")
def plate_run(tmp_path_factory):
    """A 0.03 ms strong shock on SSGM:C against the plate (31 outputs), written to NetCDF."""
    from granel import scenario as S
    from granel.io.results import write_netcdf
    from granel.run import run_scenario

    sc = S.load("paper", ['solid.kind="plate"', 'excitations.0.granule="SSGM:C"', 'excitations.0.shock="strong"',
                          'simulation.duration="0.03ms"'])
    ds = run_scenario(sc)
    path = write_netcdf(ds, tmp_path_factory.mktemp("anim") / "plate.nc")
    return ds, path


def _inside_axes(ds, field, frames):
    """The frames cropped to the inside of the axes box (the title, which shows the time, is outside)."""
    mf = A.MovieFigure(A.plan_frames(ds, field, max_frames=2))
    bb = mf.ax.get_window_extent()
    h = mf.fig.canvas.get_width_height()[1]
    mf.close()
    return frames[:, int(h - bb.y1) + 3 : int(h - bb.y0) - 3, int(bb.x0) + 3 : int(bb.x1) - 3]


@pytest.mark.parametrize("field", A.FIELDS)
def test_movie_has_the_frames_and_moves(plate_run, tmp_path, field):
    ds, _ = plate_run
    out = A.animate(ds, tmp_path / f"{field}.mp4", field=field, max_frames=8, fps=10)
    assert out.suffix in (".mp4", ".gif") and out.exists()
    frames = imageio.imread(out)
    assert frames.shape[0] == 8 and frames.shape[-1] == 3
    inside = _inside_axes(ds, field, frames.astype(int))
    for a, b in zip(inside[:-1], inside[1:]):
        assert np.abs(a - b).max() > 20  # the granules / the colours move between frames


def test_energy_density_artists_equal_draw_energy_density(plate_run):
    from granel.viz.figures import draw_energy_density

    ds, _ = plate_run
    plan = A.plan_frames(ds, "energy-density", max_frames=12)
    mf = A.MovieFigure(plan)
    i = 9  # the wave has reached most of the plate: 356 of 552 elements above the 1e-6 floor
    mf.show(i)
    fig, ax = plt.subplots()
    pc = draw_energy_density(ax, ds, float(plan.times[i]))
    k = int(np.argmin(np.abs(ds["time"].values - plan.times[i])))
    np.testing.assert_allclose(np.asarray(mf.granules.get_array()), np.asarray(pc.get_array()), rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(mf.solid.get_array()), np.asarray(ax.collections[-1].get_array()), rtol=1e-12, atol=0)
    np.testing.assert_array_equal(mf.granules.get_offsets(), np.column_stack([ds["x"].values[k], ds["y"].values[k]]))
    assert mf.solid.norm.vmin == 1e-6 and mf.solid.norm.vmax == 1.0 and mf.granules.norm.vmin == 1e-6
    assert np.asarray(mf.granules.get_array()).max() > 1e-3  # not all clipped
    assert (np.asarray(mf.solid.get_array()) > 1e-6).sum() > 100
    plt.close(fig)
    mf.close()


@pytest.mark.parametrize("field", A.FIELDS)
def test_blitted_frame_equals_full_redraw(plate_run, field):
    ds, _ = plate_run
    plan = A.plan_frames(ds, field, max_frames=6)
    mf = A.MovieFigure(plan)
    mf.show(4)
    np.testing.assert_array_equal(mf.rgb(), mf.rgb(blit=False))
    mf.close()


def test_deformation_outlines_follow_the_plate(plate_run):
    from granel.analysis.result_model import result_solid
    from granel.viz.figures import solid_state_at
    ds, _ = plate_run
    plan = A.plan_frames(ds, "deformation", magnification=500.0, max_frames=5)
    model = result_solid(ds)
    q, _, _ = solid_state_at(ds, float(plan.times[-1]))
    # each Q8 element's outline: corner, mid-side, corner, ... (its nodes 0, 4, 1, 5, 2, 6, 3, 7)
    moved = model.nodes + 500.0 * model.full_displacement(q)
    ref = moved[np.asarray(model.elements)[:, [0, 4, 1, 5, 2, 6, 3, 7]]]
    np.testing.assert_allclose(plan.solid_polygons[-1], ref, rtol=0, atol=1e-12)
    assert plan.solid_line is None


def test_render_movies_parallel_equals_serial(plate_run, tmp_path):
    _, nc = plate_run
    jobs = [(nc, tmp_path / f"w{{w}}/{f}.mp4", f, None, 5, 10) for f in A.FIELDS]
    got = {}
    for w in (1, 2):
        paths = A.render_movies([(a, str(b).format(w=w), *c) for a, b, *c in jobs], workers=w)
        assert [p.stem for p in paths] == list(A.FIELDS)
        got[w] = [imageio.imread(p) for p in paths]
    for a, b in zip(got[1], got[2]):
        assert a.shape[0] == b.shape[0] == 5
        np.testing.assert_array_equal(a, b)


def test_errors_name_the_movie(plate_run, tmp_path):
    ds, nc = plate_run
    with pytest.raises(ValueError, match="field"):
        A.animate(ds, tmp_path / "x.mp4", field="sound")
    with pytest.raises(ValueError, match="bad.mp4"):
        A.render_movies([(nc, tmp_path / "bad.mp4", "sound")], workers=1)
    with pytest.raises(A.MovieError, match="missing-movie.mp4") as e:
        A.render_movies([dict(result=tmp_path / "nope.nc", out=tmp_path / "missing-movie.mp4")], workers=1)
    assert list(e.value.failures) == [str(tmp_path / "missing-movie.mp4")]
