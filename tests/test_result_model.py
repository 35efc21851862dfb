"""A result carries its model (issue 29): the record every run writes equals the system and solid
the scenario builds; figures, movie frames and the export read it without the scenario builder; a
result of an earlier granel (no record) gets one from its scenario, once, and renders the same;
a damaged record is refused with a message naming the file (code 2)."""

import matplotlib.pyplot as plt
import numpy as np
import pytest

import granel.scenario.build as B
from granel import scenario as S
from granel.analysis.result_model import result_modes, result_solid, result_system
from granel.io.model import check_result_model, read_record, record_entries
from granel.io.results import RECORD_DIMS, ResultFileError, read_netcdf, write_netcdf
from granel.run import load_result, run_scenario
from granel.solid.mode_cache import matrix_key
from granel.solid.recipe import SolidRecipe, build_solid_model
from granel.viz import animate as A
from granel.viz.export import export_result
from granel.viz.figures import draw_energy_density, draw_walls, system_extent
from test_shaker import shaker_scenario

# the record's attributes; an earlier granel wrote only solid_kind, solid_dofs and solid_elements
RECORD_ATTRS = ("model_record", "model_media", "model_granules", "model_walls", "model_contacts", "model_loads", "contact_mu",
                "contact_alpha_n", "contact_k_s", "granular_skin", "solid_recipe", "solid_matrices_sha256")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Strong shocks on SSGM:C over 0.03 ms against the plate and the beam: (scenario, Dataset, file)."""
    d = tmp_path_factory.mktemp("model")
    out = {}
    for kind in ("plate", "beam"):
        sc = S.load("paper", [f'solid.kind="{kind}"', 'excitations.0.granule="SSGM:C"', 'excitations.0.shock="strong"',
                              'simulation.duration="0.03ms"'])
        ds = run_scenario(sc)
        out[kind] = (sc, ds, write_netcdf(ds, d / f"{kind}.nc"))
    return out


def old_style(ds):
    """The result as an earlier granel wrote it: no record variables or attributes."""
    old = ds.drop_vars([v for v in RECORD_DIMS if v in ds.variables])
    old.attrs = {k: v for k, v in ds.attrs.items() if k not in RECORD_ATTRS}
    return old


@pytest.mark.parametrize("kind", ["plate", "beam"])
def test_the_record_is_the_built_model(results, kind):
    sc, ds, path = results[kind]
    problem = S.build_problem(sc)
    system, solid = problem.system, problem.solid
    rec = read_record(read_netcdf(path))
    assert rec.labels == tuple(system.labels) and rec.media == ("LSGM", "SSGM")
    for got, want in ((rec.radius, system.radius), (rec.mass, system.mass), (rec.inertia, system.inertia),
                      (rec.E, system.E), (rec.nu, system.nu), (rec.position0, system.pos0),
                      (rec.medium_index, system.medium_index), (rec.nodes, solid.nodes), (rec.elements, solid.elements),
                      (rec.mode_omega, ds["mode_omega"].values)):
        np.testing.assert_array_equal(got, want)
    assert (rec.mu, rec.alpha_n, rec.k_s, rec.skin) == (0.099, 6.313e-3, 100.0, system.skin)
    assert [(w.name, w.p0, w.p1, w.normal, w.medium) for w in rec.walls] == \
        [(str(n), tuple(w.p0), tuple(w.p1), tuple(w.normal), w.medium) for n, w in zip(ds["wall"].values, system.walls)]
    assert len(rec.walls) == 6 and all(w.drive == (0.0,) * 6 for w in rec.walls)
    assert [(c.name, c.granule, c.dofs) for c in rec.contacts] == \
        [(p.name, c.granule, (p.dof_x, p.dof_y, p.dof_rotation)) for c, p in zip(system.solid_contacts, solid.contacts)]
    assert len(rec.contacts) == 10 and rec.solid_kind == kind and rec.solid_dofs == solid.ndof == {"plate": 3584, "beam": 78}[kind]
    assert rec.solid_digest[:20] == matrix_key(solid)  # the mode cache's name of this solid
    # the system and the solid built from the record: the kernels' bundles and the matrices, to the bit
    again = result_system(ds)
    for a, b in zip((*again.wall_geometry, *again.points, *again.granules), (*system.wall_geometry, *system.points,
                                                                             *system.granules)):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(again.loads, system.loads):  # the loads' compiled bundle, and the force they give
        np.testing.assert_array_equal(a, b)
    assert len(again.excitations) == 1
    for t in np.linspace(0, 1.2e-5, 25):
        assert again.excitations[0].history(t) == system.excitations[0].history(t)
    model = result_solid(ds)
    assert (model.M != solid.M).nnz == 0 and (model.K != solid.K).nnz == 0 and (model.T != solid.T).nnz == 0
    assert model.recipe == solid.recipe == SolidRecipe.from_json(rec.solid_recipe)


def test_a_recipe_round_trips_to_the_same_solid():
    sc = S.load("paper", ['solid.kind="beam"', "solid.beam_elements=50"])
    system = B.build_granular(sc)[0]
    recipe = B.solid_recipe(sc, system)
    assert recipe.beam_elements == 50 and recipe.E == 200e9 and recipe.clamped == (True, True)
    again = SolidRecipe.from_json(recipe.to_json())
    assert again == recipe
    a, b = build_solid_model(recipe), build_solid_model(again)
    assert a.ndof == b.ndof == 98 and (a.K != b.K).nnz == 0 and (a.M != b.M).nnz == 0


def _refuse(*args, **kwargs):
    raise AssertionError("the scenario builder ran")


@pytest.mark.parametrize("kind", ["plate", "beam"])
def test_a_new_result_is_read_without_the_scenario_builder(results, tmp_path, monkeypatch, kind):
    _, _, path = results[kind]
    for module, name in ((S, "build_problem"), (S, "build_granular"), (B, "build_problem"), (B, "build_granular")):
        monkeypatch.setattr(module, name, _refuse)
    ds = load_result(path)
    plan = A.plan_frames(ds, "energy-density", max_frames=4)
    w = plan.solid_w
    assert np.all(np.isfinite(w)) and w.max() > 1e-3  # the shock has reached the solid
    assert plan.granule_w.max() > 0.1
    deform = A.plan_frames(ds, "deformation", magnification=200.0, max_frames=4)
    assert np.ptp(deform.centres[-1] - deform.centres[0]) > 0
    fig, ax = plt.subplots()
    draw_energy_density(ax, ds, float(ds["time"].values[-1]))
    draw_walls(ax, ds)
    (x0, x1), (y0, y1) = system_extent(ds)
    assert x0 < 0 < x1 and y0 < 0 < 0.1 < y1  # the granules on both sides of the 0.1 m tall solid at x = 0..0.01
    plt.close(fig)
    written = export_result(ds, tmp_path / "export", ["vtk"])
    assert len([p for p in written if p.parent.name == "solid"]) == ds.sizes["solid_time"]


def test_an_old_result_gets_its_record_once_and_renders_the_same(results, tmp_path, monkeypatch):
    _, ds, path = results["plate"]
    old_path = write_netcdf(old_style(read_netcdf(path)), tmp_path / "old.nc")
    old = read_netcdf(old_path)
    with pytest.raises(ResultFileError, match="no model record") as e:
        read_record(old, old_path)
    assert e.value.code == 2 and "old.nc" in str(e.value)
    builds = []

    def counted(sc, build=S.build_problem):
        builds.append(sc.name)
        return build(sc)

    monkeypatch.setattr(S, "build_problem", counted)
    migrated = load_result(old_path)
    fresh = load_result(path)
    (data_a, attrs_a), (data_b, attrs_b) = (record_entries(read_record(d)) for d in (migrated, fresh))
    assert attrs_a == attrs_b and data_a.keys() == data_b.keys()
    for name in data_a:
        np.testing.assert_array_equal(data_a[name][1], data_b[name][1])
    a, b = (A.plan_frames(d, "energy-density", max_frames=4) for d in (migrated, fresh))
    np.testing.assert_array_equal(a.solid_w, b.solid_w)
    np.testing.assert_array_equal(a.granule_w, b.granule_w)
    assert result_modes(migrated) is result_modes(fresh)  # one solid: one set of modes
    export_result(migrated, tmp_path / "old-export", ["csv"])
    assert builds == ["paper"]  # the migration built the scenario once; nothing else did


def test_a_damaged_record_is_refused(results, tmp_path):
    _, _, path = results["beam"]
    ds = read_netcdf(path)
    fewer = write_netcdf(ds.isel(granule=slice(0, 5)), tmp_path / "fewer.nc")
    with pytest.raises(ResultFileError, match="5 granules stored, its model has 28") as e:
        load_result(fewer)
    assert e.value.code == 2 and "fewer.nc" in str(e.value)
    bad = ds.copy()
    bad["contact_granule"] = bad["contact_granule"] + 100
    with pytest.raises(ResultFileError, match="contact's granule or DOF is out of range"):
        load_result(write_netcdf(bad, tmp_path / "contacts.nc"))
    other = ds.copy()
    other.attrs["solid_recipe"] = other.attrs["solid_recipe"].replace('"beam_elements": 40', '"beam_elements": 80')
    with pytest.raises(ResultFileError, match="its solid, built from its recipe, has 158 DOFs") as e:
        result_solid(other, "changed.nc")
    assert e.value.code == 2
    rec = read_record(ds)
    with pytest.raises(ResultFileError, match="solid_eta is not finite"):
        nan = ds.copy()
        nan["solid_eta"] = nan["solid_eta"] * np.nan
        check_result_model(nan, rec, "nan.nc")


def test_a_shaker_and_a_granule_file_are_recorded(tmp_path):
    """A moving wall keeps its drive (infinite duration included) and a result of an earlier granel
    whose scenario reads a granule file is given its record from the file's stored text."""
    sc, f, _ = shaker_scenario(tmp_path, 0.5, cycles=2)
    problem = S.build_problem(sc)
    path = write_netcdf(run_scenario(sc), tmp_path / "shaker.nc")
    (tmp_path / "one.csv").unlink()  # the result carries the file's text
    rec = read_record(load_result(path))
    assert rec.walls[0].drive == problem.system.walls[0].drive.params() == (1e-9, f, 0.0, np.inf, 0.0, 5.0)
    for a, b in zip(result_system(load_result(path)).wall_geometry, problem.system.wall_geometry):
        np.testing.assert_array_equal(a, b)
    migrated = load_result(write_netcdf(old_style(read_netcdf(path)), tmp_path / "old.nc"))
    assert read_record(migrated).walls == rec.walls and read_record(migrated).labels == ("G:A",)


def test_tabulated_loads_round_trip_through_the_record(results):
    """Loads of every kind, a table among them, are written and read back as they were: the
    tables' points split back to their loads, the parameters zero-padded."""
    from dataclasses import replace

    from granel.io.model import LoadRecord, with_record

    _, ds, _ = results["beam"]
    rec = read_record(ds)
    loads = (LoadRecord(3, (1.0, 0.0), "table", (0.0,) * 8, (0.0, 1e-5, 2e-5), (0.0, 5.0, 0.0)),
             LoadRecord(0, (0.0, -1.0), "constant", (2.5,) + (0.0,) * 7),
             LoadRecord(5, (0.6, 0.8), "table", (0.0,) * 8, (1e-6, 3e-6), (1.0, -1.0)))
    back = read_record(with_record(ds, replace(rec, loads=loads)))
    assert back.loads == loads
    system = result_system(with_record(ds, replace(rec, loads=loads)))
    assert [e.history(1e-5) for e in system.excitations] == [5.0, 2.5, 0.0]
    assert abs(system.excitations[2].history(2e-6)) <= 4 * np.finfo(float).eps  # the interpolation weight's rounding


def test_the_records_layouts_are_the_laws():
    """The record's parameter widths (io may not import granular, so it keeps its own) are the
    ones the compiled laws read: a load's parameter slots and a shaker's parameters."""
    from granel.granular.laws import LOAD_PARAMS
    from granel.granular.loads import WallDrive
    from granel.io.model import DRIVE_PARAMS, LOAD_PARAMS as RECORD_LOAD_PARAMS

    assert RECORD_LOAD_PARAMS == LOAD_PARAMS
    assert DRIVE_PARAMS == len(WallDrive(1e-6, 1e3).params())
