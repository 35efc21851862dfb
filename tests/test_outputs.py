"""What a result stores (`[simulation.outputs]`): the traces of a few granules, groups left out,
compression; the stored values are the full run's own, bit for bit; every reader works on what is
there or stops with exit 2 naming what it needs and the setting that left it out."""

import numpy as np
import pytest
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app
from granel.io.results import read_netcdf, require_states, ResultFileError
from granel.run import load_result, run_scenario, run_to_file, summarize
from granel.scenario.estimate import run_needs

runner = CliRunner()
BASE = ['simulation.duration="0.04ms"', 'excitations.0.granule="SSGM:C"', 'excitations.0.shock="strong"']
REDUCED = ['simulation.outputs.granules=["SSGM:C", "LSGM:3"]', "simulation.outputs.steps=false",
           "simulation.outputs.solid=false", "simulation.outputs.contacts=false"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same plate run stored whole and reduced (two traces, no steps, solid or contacts)."""
    tmp = tmp_path_factory.mktemp("outputs")
    paths = {}
    for name, extra in (("full", []), ("reduced", REDUCED), ("none", ['simulation.outputs.granules="none"'])):
        paths[name] = tmp / f"{name}.nc"
        run_to_file(S.load("paper", BASE + extra), paths[name])
    return paths


def test_the_traces_are_the_full_runs_values(runs):
    full, reduced = read_netcdf(runs["full"]), read_netcdf(runs["reduced"])
    assert list(reduced["traced"].values) == ["LSGM:3", "SSGM:C"]  # in the granules' order
    assert reduced["v_x"].dims == ("time", "traced") and reduced.sizes["granule"] == 28
    for label in ("LSGM:3", "SSGM:C"):
        g = list(full["granule"].values).index(label)
        for v in ("x", "y", "theta", "v_x", "v_y", "omega"):
            np.testing.assert_array_equal(reduced[v].sel(traced=label).values, full[v].values[:, g])
    for v in ("balance_error", "input_work", "energy_solid", "energy_lsgm", "energy_ssgm", "dissipated_friction"):
        np.testing.assert_array_equal(reduced[v].values, full[v].values)
    absent = [v for v in ("step_time", "step_lambda", "solid_eta", "solid_time", "contact_force_normal", "lambda_max")
              if v in reduced]
    assert absent == [] and "wall_force_normal" in reduced
    assert reduced.attrs["outputs_left_out"] == "contacts steps solid"
    assert runs["reduced"].stat().st_size < runs["full"].stat().st_size / 10


def test_no_granule_state_at_all(runs):
    ds = load_result(runs["none"])
    assert "x" not in ds and "traced" not in ds.dims
    np.testing.assert_array_equal(ds["balance_error"].values, read_netcdf(runs["full"])["balance_error"].values)
    assert summarize(ds)["peak_speed"] == {}
    with pytest.raises(ResultFileError, match='simulation.outputs.granules = "none"'):
        require_states(ds, "a movie")


def test_a_reduced_result_reads_with_every_granule(runs):
    """`load_result` puts the traces along `granule` (NaN elsewhere); a reader of a traced granule
    works, one of another is refused naming the granule and the setting."""
    ds, full = load_result(runs["reduced"]), read_netcdf(runs["full"])
    assert ds["x"].dims == ("time", "granule")
    stored = np.isfinite(ds["x"].values[0])
    assert [str(g) for g in ds["granule"].values[stored]] == ["LSGM:3", "SSGM:C"]
    g = list(ds["granule"].values).index("SSGM:C")
    np.testing.assert_array_equal(ds["v_y"].values[:, g], full["v_y"].values[:, g])
    require_states(ds, "a trace", [g])
    with pytest.raises(ResultFileError, match=r"needs the state of granule LSGM:1: this result traces only 2 granules "
                                              r"\(LSGM:3, SSGM:C; simulation.outputs.granules\)"):
        require_states(ds, "a trace", [0])
    peak = summarize(ds)["peak_speed"]
    assert set(peak) == {"LSGM", "SSGM"} and peak["SSGM"]["granule"] == "SSGM:C"
    assert peak["SSGM"]["m_per_s"] == pytest.approx(np.hypot(full["v_x"].values[:, g], full["v_y"].values[:, g]).max(), rel=1e-15)


@pytest.mark.parametrize("command, needs", [
    (["animate", "{r}", "-o", "{d}/m.gif"], "every granule's state"),
    (["export", "{r}", "-o", "{d}/vtk"], "every granule's state"),
    (["wavefield", "{r}", "-o", "{d}/wf"], "solid_time: this result was run with simulation.outputs.solid = false"),
])
def test_readers_name_what_a_reduced_result_lacks(runs, tmp_path, command, needs):
    args = [a.format(r=runs["reduced"], d=tmp_path) for a in command]
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert needs in " ".join(res.output.split())
    assert not any(tmp_path.iterdir())  # nothing written


def test_an_unknown_traced_label_is_refused_before_any_computation(tmp_path):
    res = runner.invoke(app, ["run", "paper", "--set", 'simulation.outputs.granules=["SSGM:C", "SSGM:Z"]',
                              "-o", str(tmp_path / "x.nc")])
    assert res.exit_code == 2 and "simulation.outputs.granules" in res.output and "SSGM:Z" in res.output
    for bad in ('simulation.outputs.granules=[]', 'simulation.outputs.granules=["A:1", "A:1"]',
                "simulation.outputs.compression=10", "simulation.outputs.solid=1"):
        res = runner.invoke(app, ["run", "paper", "--set", bad, "-o", str(tmp_path / "x.nc")])
        assert res.exit_code == 2 and "simulation.outputs" in res.output, (bad, res.output)
    assert not (tmp_path / "x.nc").exists()


def test_compression_is_lossless(tmp_path):
    sc = BASE + ['simulation.duration="0.01ms"']
    plain, packed = tmp_path / "plain.nc", tmp_path / "packed.nc"
    run_to_file(S.load("paper", sc + ["simulation.outputs.compression=0"]), plain)
    run_to_file(S.load("paper", sc + ["simulation.outputs.compression=6"]), packed)
    a, b = read_netcdf(plain), read_netcdf(packed)
    assert packed.stat().st_size < plain.stat().st_size
    for v in ("solid_eta", "solid_eta_dot", "x", "v_x", "step_lambda", "balance_error"):
        np.testing.assert_array_equal(a[v].values, b[v].values)


def test_the_run_keeps_only_what_it_stores_and_the_estimate_counts_it():
    from granel.coupling.driver import drive

    problem = S.build_problem(S.load("paper", BASE + REDUCED + ['simulation.duration="2us"']))
    from granel.run import make_solver

    traj = drive(make_solver(problem), problem.schedule, stored=problem.stored)
    assert traj.series("pos").shape[1:] == (2, 2) and traj.series("omega").shape[1:] == (2,)
    assert traj.solid_names == []
    full = run_needs(S.load("paper", BASE + ['simulation.duration="0.8ms"']))
    small = run_needs(S.load("paper", BASE + REDUCED + ['simulation.duration="0.8ms"']))
    assert small.memory < full.memory and small.result < full.result / 10


def test_a_traced_run_resumes_to_the_uninterrupted_result(tmp_path):
    sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.granule="SSGM:C"', 'simulation.duration="0.05ms"',
                          'simulation.checkpoint_every="0.01ms"', 'simulation.outputs.granules=["SSGM:C"]'])
    whole = run_scenario(sc)
    ck = tmp_path / "run.ckpt"

    class Killed(Exception):
        pass

    def killer(t):
        if t > 0.033e-3:
            raise Killed

    with pytest.raises(Killed):
        run_scenario(sc, killer, ck)
    resumed = run_scenario(sc, None, ck, ck)
    assert resumed["v_x"].dims == ("time", "traced")
    np.testing.assert_array_equal(resumed["v_x"].values, whole["v_x"].values)
