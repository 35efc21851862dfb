"""Hostile input to scenarios and `granel run`: every case ends with a clear message naming the
field (or file and line) and the documented exit code, before any computation where the input is
at fault, and nothing the user had is lost. Exit codes: 0 ok, 2 input or usage, 3 numerical or
physical stop, 4 input/output."""

from __future__ import annotations

import os

import numpy as np
import pytest
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app

runner = CliRunner()

NUMBER_FIELDS = [
    "simulation.abstol", "simulation.reltol", "simulation.lambda_max", "simulation.rtol", "simulation.atol",
    "simulation.mode_cutoff", "simulation.ledger_tol", "simulation.balance_limit", "simulation.overlap_limit",
    "simulation.duration", "simulation.dt", "simulation.output_every", "simulation.checkpoint_every",
    "simulation.max_step", "contact.mu", "contact.alpha_n", "contact.k_s", "materials.steel.E", "materials.steel.rho",
    "materials.steel.nu", "solid.x0", "solid.y0", "solid.width", "solid.length", "solid.thickness", "solid.mesh.growth",
    "solid.mesh.max_size", "media.0.radius", "media.0.center_y", "media.0.gap", "excitations.0.fmax",
    "excitations.0.tau", "excitations.0.t0", "solid.tension", "solid.foundation",
]


def refused(overrides, *words):
    """Loading the paper scenario with `overrides` raises a ScenarioError naming every word."""
    with pytest.raises(S.ScenarioError) as err:
        S.load("paper", overrides)
    for w in words:
        assert w in str(err.value), str(err.value)
    return str(err.value)


@pytest.mark.parametrize("field", NUMBER_FIELDS)
@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_non_finite_numbers_are_refused_naming_the_field(field, value):
    refused([f"{field}={value}"], field)


@pytest.mark.parametrize("field", ["media.0.radius", "contact.mu", "solid.width", "excitations.0.fmax",
                                   "materials.steel.E", "simulation.max_halvings", "media.0.columns", "solid.tension",
                                   "solid.surface_elements"])
def test_a_boolean_is_not_a_number(field):
    value = "[true, 3]" if field == "media.0.columns" else "true"
    refused([f"{field}={value}"], field, "boolean")


@pytest.mark.parametrize("field", ["simulation.adaptive", "media.0.outer_wall", "media.0.channel_walls",
                                   "solid.mesh.rigid_layers", "solid.bending_stiffness"])
@pytest.mark.parametrize("value", ["1", "0", '"yes"'])
def test_a_number_or_word_is_not_a_boolean(field, value):
    refused([f"{field}={value}"], field, "true or false")


@pytest.mark.parametrize("override, words", [
    ("contact.mu.x=1", ["contact.mu", "not a table"]),
    ("solid.kind.x.y=1", ["solid.kind", "not a table"]),
    ("media.7.radius=0.01", ["no list item"]),
    ("contact.mu", ["key=value"]),
])
def test_malformed_overrides(override, words):
    refused([override], *words)


@pytest.mark.parametrize("override, words", [
    ('solid.shape="sphere"', ["solid.shape"]),
    ("solid.shape=3", ["solid.shape"]),
    ("solid.edges=[]", ["solid.edges"]),
    ('solid.edges=["clamped", "clamped", "clamped", "clamped", "clamped"]', ["solid.edges"]),
    ('solid.edges=["welded", "clamped", "clamped", "clamped"]', ["solid.edges"]),
    ("solid.contact_refinement=-1", ["solid.contact_refinement"]),
    ("solid.contact_refinement=7", ["solid.contact_refinement"]),
    ("solid.contact_refinement=2.5", ["solid.contact_refinement"]),
    ("solid.contact_refinement=true", ["solid.contact_refinement", "boolean"]),
    ("solid.contact_refinement=2", ["solid.contact_refinement", "a plate solid does not use it"]),
])
def test_bad_surface_shapes_and_edges_are_refused_naming_the_field(override, words):
    refused([override], *words)


@pytest.mark.parametrize("center_y", ["0.5", "-0.2"])
def test_a_medium_beside_the_solid_but_beyond_its_ends_is_refused(center_y):
    """Its column 0 would face no surface (the paper's plate spans y = 0 to its length): named,
    before any computation."""
    with pytest.raises(S.ScenarioError, match=r"media.0: granule .* beyond them .*media.0.center_y"):
        S.build_granular(S.load("paper", [f"media.0.center_y={center_y}"]))


def test_duplicate_labels_in_a_medium():
    refused(['media.0.labels=["a", "b", "a"]'], "media.0.labels", "repeats")


# ---------------------------------------------------------------- CSV inputs

GRANULES = "label,x,y,radius\n"


def _medium_from(tmp_path, text):
    path = tmp_path / "g.csv"
    path.write_text(text)
    return [f'media.0.granules_file="{path}"', "media.0.columns=[]"]


@pytest.mark.parametrize("rows, words", [
    ("A,-0.01,0.05,0.005\nB,-0.02,0.05\n", ["line 3", "columns"]),
    ("A,-0.01,0.05,nan\n", ["line 2", "radius", "finite"]),
    ("A,-0.01,inf,0.005\n", ["line 2", "y", "finite"]),
    ("A,-0.01,0.05,abc\n", ["line 2", "radius", "not a number"]),
    ("A,-0.01,0.05,true\n", ["line 2", "radius", "not a number"]),
    ("A,-0.01,0.05,-0.005\n", ["line 2", "radius", "positive"]),
    ("A,-0.01,0.05,0.005\nA,-0.03,0.05,0.005\n", ["line 3", "'A'", "repeats line 2"]),
    (",-0.01,0.05,0.005\n", ["line 2", "empty label"]),
    ("", ["no granules"]),
])
def test_granule_csv_values_are_checked_with_file_and_line(tmp_path, rows, words):
    ov = _medium_from(tmp_path, GRANULES + rows)
    refused(ov, "media.0.granules_file", "g.csv", *words)


def test_granule_csv_without_a_radius_column(tmp_path):
    ov = _medium_from(tmp_path, "label,x,y\nA,0,0\n")
    refused(ov, "media.0.granules_file", "header")


@pytest.mark.parametrize("text, words", [
    ("0,0\n1e-5,nan\n", ["line 2", "finite"]),
    ("0,0\n1e-5,abc\n", ["line 2", "force", "not a number"]),
    ("time,force,extra\n0,0,1\n1e-5,1,2\n", ["line 1", "time,force"]),
    ("0,0\n0,1\n", ["line 2", "does not increase"]),
    ("time,force\n0,0\n", ["two rows"]),
    ("0\n1e-5\n", ["line 1", "time,force"]),
])
def test_force_table_values_are_checked_with_file_and_line(tmp_path, text, words):
    path = tmp_path / "f.csv"
    path.write_text(text)
    refused(['excitations.0.kind="table"', f'excitations.0.file="{path}"'], "excitations.0.file", "f.csv", *words)


def test_a_valid_force_table_with_header_and_comments_loads(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text("# a pulse\ntime,force\n0,0\n1e-5,10\n2e-5,0\n")
    sc = S.load("paper", ['excitations.0.kind="table"', f'excitations.0.file="{path}"', 'solid.kind="rigid"'])
    assert sc.excitations[0].history(None).times.tolist() == [0.0, 1e-5, 2e-5]


# ---------------------------------------------------------------- time and loads


@pytest.mark.parametrize("overrides, words", [
    (['simulation.duration="10ns"'], ["simulation.duration", "shorter than the step"]),
    (['simulation.duration="5us"', 'simulation.output_every="10us"'], ["simulation.output_every", "longer than"]),
    (['simulation.duration="1.05us"'], ["simulation.duration", "output intervals"]),
    (['simulation.dt="80ns"', 'simulation.integrator="newmark"'], ["simulation.output_every", "steps of simulation.dt"]),
    (['simulation.output_every="20ns"'], ["simulation.output_every", "shorter than the step"]),
])
def test_times_that_cannot_end_on_an_output_are_refused(overrides, words):
    refused(overrides, *words)


def test_the_last_output_is_exactly_at_the_duration():
    from granel.run import run_scenario

    ds = run_scenario(S.load("paper", ['solid.kind="rigid"', 'simulation.duration="3us"']))
    assert ds["time"].values[-1] == pytest.approx(3e-6, rel=1e-12)
    assert len(ds["time"]) == 4


def test_the_adaptive_exact_integrator_puts_outputs_on_the_grid_whatever_dt():
    from granel.run import run_scenario

    ds = run_scenario(S.load("paper", ['solid.kind="beam"', 'simulation.integrator="exact"', 'simulation.dt="30ns"',
                                       'simulation.duration="4us"']))
    assert np.allclose(ds["time"].values, np.arange(5) * 1e-6, rtol=0, atol=1e-18)


@pytest.mark.parametrize("overrides", [
    ['excitations.0.kind="constant"', "excitations.0.value=1e9"],
    ['excitations.0.kind="burst"', "excitations.0.amplitude=1e9", "excitations.0.frequency=1e4", "excitations.0.cycles=1"],
    ["excitations.0.fmax=1e9"],
    ['excitations.0.kind="harmonic"', "excitations.0.amplitude=1e9", "excitations.0.frequency=1e4"],
    ['excitations.0.kind="chirp"', "excitations.0.amplitude=1e9", "excitations.0.f0=1e3", "excitations.0.f1=1e4",
     'excitations.0.duration="0.1ms"'],
])
def test_loads_beyond_hertz_contact_are_refused(overrides):
    refused(overrides, "excitations.0", "overlap_limit")


@pytest.mark.parametrize("overrides, words", [
    (['excitations.0.kind="harmonic"', "excitations.0.amplitude=10"], ["excitations.0", "frequency"]),
    (['excitations.0.kind="harmonic"', "excitations.0.frequency=1e4"], ["excitations.0", "amplitude"]),
    (['excitations.0.kind="harmonic"', "excitations.0.amplitude=10", "excitations.0.frequency=-1e4"],
     ["excitations.0.frequency", "greater than 0"]),
    (['excitations.0.kind="harmonic"', "excitations.0.amplitude=10", "excitations.0.frequency=1e4",
      "excitations.0.ramp_cycles=-1"], ["excitations.0.ramp_cycles"]),
    (['excitations.0.kind="harmonic"', "excitations.0.amplitude=10", "excitations.0.frequency=1e4",
      'excitations.0.duration="-1ms"'], ["excitations.0.duration", "positive"]),
    (['excitations.0.kind="harmonic"', "excitations.0.amplitude=10", "excitations.0.frequency=1e4",
      "excitations.0.phase=nan"], ["excitations.0.phase", "finite"]),
    (['excitations.0.kind="chirp"', "excitations.0.amplitude=10", "excitations.0.f0=1e3", "excitations.0.f1=1e4"],
     ["excitations.0", "duration"]),
    (['excitations.0.kind="chirp"', "excitations.0.amplitude=10", "excitations.0.f0=1e3", "excitations.0.f1=1e4",
      'excitations.0.duration="0.1ms"', 'excitations.0.mode="cubic"'], ["excitations.0.mode"]),
])
def test_narrowband_drives_need_their_fields(overrides, words):
    refused(overrides, *words)


def test_a_constant_load_enters_the_safe_step():
    """A sustained load has no finite impulse; the safe step covers it by the period of the contact
    it compresses (2 pi sqrt(m / k), k = 3/2 A delta^(1/2), delta = (F / A)^(2/3)): finite, and
    shorter for a larger force (as F^(-1/6)). Measured: 1.89, 1.29, 0.88 us at 1e3, 1e4, 1e5 N."""
    from granel.granular.scales import safe_time_step

    bounds = []
    for F in (1e3, 1e4, 1e5):
        sc = S.load("paper", ['solid.kind="rigid"', 'excitations.0.kind="constant"', f"excitations.0.value={F}"])
        system = S.build_granular(sc, sc.base)[0]
        bounds.append(safe_time_step(system, system.excitations, 0.0))
    assert np.all(np.isfinite(bounds))
    assert np.allclose(np.array(bounds[1:]) / bounds[:-1], 10 ** (-1 / 6), rtol=0.02)


def test_a_huge_initial_velocity_is_refused():
    refused(['initial_velocities=[{granule = "LSGM:3", v = [1e6, 0.0]}]'], "initial_velocities.0", "overlap_limit")


def test_a_fast_initial_velocity_within_hertz_runs_and_keeps_the_balance():
    """100 m/s toward the solid (a 7 % overlap on a wall at most, inside the limit): the run
    holds the energy balance within 1e-6 of the initial energy and no granule passes through
    anything."""
    from granel.run import run_scenario

    ds = run_scenario(S.load("paper", ['solid.kind="rigid"', "excitations=[]", 'simulation.duration="30us"',
                                       'initial_velocities=[{granule = "LSGM:3", v = [100.0, 0.0]}]']))
    e0 = float(ds["energy_lsgm"].values[0])
    assert np.abs(ds["balance_error"].values).max() < 1e-6 * e0
    left = ds["medium"].values == "LSGM"
    assert np.all(ds["x"].values[:, left] < 0.0)  # every LSGM granule stays left of the solid's face (x0 = 0)


def test_the_guards_stop_a_run_that_leaves_the_physics():
    """The driver's checks on a block of outputs: a contact overlapping beyond the limit, a balance
    lost, a non-finite state, each reported at the first output that breaks it with its own time;
    healthy outputs pass, their balance measured from the start."""
    from granel.coupling.driver import Guards, PhysicsStop, check_guards
    from granel.coupling.observation import Observation

    def block(**bad):
        """Two outputs (t = 1 and 2 us); `bad` replaces the second one's values."""
        two = lambda v: np.array([v, bad.get("_", v)], float)  # noqa: E731
        values = {"pos": np.zeros((2, 2, 2)), "vel": np.zeros((2, 2, 2)), "ledger": two(0.8), "input_work": two(1.0),
                  "overlap_ratio": two(0.02)}
        for k, v in bad.items():
            if k != "_":
                values[k][1] = v
        return Observation(times=np.array([1e-6, 2e-6]), theta=np.zeros((2, 2)), omega=np.zeros((2, 2)),
                           energy_media=np.array([[1.0, 0.0]] * 2), energy_solid=two(0.5),
                           energy_solid_kinetic=two(0.5), energy_solid_potential=two(0.0), energy_gravity=two(0.0),
                           dissipated_viscous=two(0.2),
                           dissipated_friction=two(0.1), force_normal=np.zeros((2, 0)), force_tangential=np.zeros((2, 0)),
                           wall_force=np.zeros((2, 0, 2)), overlap_at=["granules A:1 and A:2"] * 2, **values)

    check_guards(block(), 0.8, 0.0, Guards())
    assert block().recorded(0.8)["balance_error"].tolist() == [0.0, 0.0]
    with pytest.raises(PhysicsStop, match=r"t = 2\.000000e-06 s: granules A:1 and A:2 overlap by 50\.0%"):
        check_guards(block(overlap_ratio=0.5), 0.8, 0.0, Guards())
    with pytest.raises(PhysicsStop, match=r"t = 2\.000000e-06 s: the energy balance \(13\) is off by 1\.00e-01"):
        check_guards(block(ledger=0.9), 0.8, 0.0, Guards(balance_limit=0.05))
    with pytest.raises(PhysicsStop, match="not finite"):
        check_guards(block(vel=np.array([[np.nan, 0.0], [0.0, 0.0]])), 0.8, 0.0, Guards())


def test_the_balance_excludes_the_initial_energy():
    """No load, one granule thrown at 1 m/s: the energy balance (13) starts at zero and stays at the
    integrator's level, although the initial kinetic energy is not input work: RK4 at a fixed 40 ns
    (Newmark's core) within 1e-8 of it, the exact integrator within its ledger tolerance (1e-5 of
    the thrown granule's energy; measured 2.5e-8)."""
    from granel.run import run_scenario

    base = ['solid.kind="rigid"', "excitations=[]", 'simulation.duration="20us"',
            'initial_velocities=[{granule = "LSGM:3", v = [1.0, 0.0]}]']
    for integrator, bound in (("newmark", 1e-8), ("exact", 1e-5)):
        ds = run_scenario(S.load("paper", base + [f'simulation.integrator="{integrator}"']))
        e0 = float(ds["energy_lsgm"].values[0])
        assert e0 > 1e-4
        assert np.abs(ds["balance_error"].values).max() < bound * e0


# ---------------------------------------------------------------- granel run: paths and exit codes

SMALL = ["--solid", "rigid", "--duration", "2us"]


def invoke(args):
    r = runner.invoke(app, ["run", "paper", *args])
    assert "Traceback" not in r.output
    return r


@pytest.mark.parametrize("name, code, words", [
    ("res.ckpt", 2, ["res.ckpt", "checkpoints"]),
    (".", 2, ["folder"]),
    ("afile/x.nc", 2, ["afile", "not a folder"]),
    ("/proc/granel-nowhere/x.nc", 4, ["cannot write"]),
])
def test_output_paths_are_checked_before_the_run(tmp_path, monkeypatch, name, code, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("keep me")
    r = invoke([*SMALL, "-o", name])
    assert r.exit_code == code, r.output
    for w in words:
        assert w in r.output
    assert "%" not in r.output  # no progress bar: nothing ran
    assert (tmp_path / "afile").read_text() == "keep me"


def test_the_scenario_file_is_never_the_output(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "keep.toml").write_text(S.to_toml(S.load("paper", ['solid.kind="rigid"', 'simulation.duration="2us"'])))
    before = (tmp_path / "keep.toml").read_text()
    r = runner.invoke(app, ["run", "keep.toml", "-o", "keep.toml"])
    assert r.exit_code == 2 and "input" in r.output
    assert (tmp_path / "keep.toml").read_text() == before


def test_an_unrelated_checkpoint_is_never_deleted(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mysc.ckpt").write_text("somebody's file")
    assert invoke([*SMALL, "-o", "mysc.nc"]).exit_code == 0
    assert (tmp_path / "mysc.ckpt").read_text() == "somebody's file"
    r = invoke([*SMALL, "-o", "mysc.nc", "--checkpoint-every", "1us"])  # would overwrite it: refused
    assert r.exit_code == 2 and "--resume" in r.output
    assert (tmp_path / "mysc.ckpt").read_text() == "somebody's file"


def test_stale_temporaries_of_a_dead_run_are_removed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    dead = 2**22 + 12345  # above the default pid_max: never a live process
    stale = tmp_path / f".out.nc.{dead}.abcd.tmp"
    stale.write_text("partial")
    alive = tmp_path / f".out.nc.{os.getpid()}.efgh.tmp"
    alive.write_text("being written")
    r = invoke([*SMALL, "-o", "out.nc"])
    assert r.exit_code == 0
    assert not stale.exists() and alive.exists()


@pytest.mark.parametrize("args, code", [
    (["--set", "contact.k_s=nan"], 2),
    (["--set", "media.0.radius=true"], 2),
    (["--shock", "nan"], 2),
    (["--shock", "loud"], 2),
    (["--duration", "abc"], 2),
    (["--set", "simulation.overlap_limit=1e-9"], 2),
    (["--set", "simulation.balance_limit=1e-300"], 3),
])
def test_exit_codes(tmp_path, monkeypatch, args, code):
    monkeypatch.chdir(tmp_path)
    r = invoke(["--solid", "rigid", "--duration", "5us", *args, "-o", "x.nc"])
    assert r.exit_code == code, r.output
    assert not (tmp_path / "x.nc").exists()


# ---------------------------------------------------------------- runaway cost


@pytest.mark.parametrize("override, words", [
    ("contact.k_s=1e12", ["contact.k_s", "sub-steps"]),
    ("contact.k_s=1e8", ["contact.k_s", "sub-steps"]),
    ("contact.alpha_n=1e6", ["contact.alpha_n", "too fast for RK4"]),
])
def test_contact_laws_too_stiff_for_the_step_are_refused(override, words):
    """These hung with no message: 4e8 sub-steps per step, or a damping rate 2300 times beyond
    RK4's stability at 40 ns."""
    refused([override], *words)


def test_a_stiff_but_feasible_friction_runs():
    """k_s = 1e4 s/m (100 times the paper's) needs sub-steps but stays within the limit."""
    S.load("paper", ["contact.k_s=1e4"])


@pytest.mark.parametrize("value", ["0", "-5", "abc", "nan", "inf"])
def test_max_wall_must_be_a_positive_time(tmp_path, monkeypatch, value):
    monkeypatch.chdir(tmp_path)
    r = invoke([*SMALL, "--max-wall", value, "-o", "x.nc"])
    assert r.exit_code == 2 and "--max-wall" in r.output


def test_max_wall_stops_a_long_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = invoke(["--solid", "rigid", "--duration", "0.8ms", "--max-wall", "0.001s", "-o", "x.nc"])
    assert r.exit_code == 3 and "wall-time limit" in r.output
    assert not (tmp_path / "x.nc").exists()


# ---------------------------------------------------------------- fuzzing

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_PAPER = S.load_raw("paper")[0]
NON_FINITE = st.sampled_from([float("nan"), float("inf"), float("-inf")])


def _set(raw, path, value):
    import copy

    raw = copy.deepcopy(raw)
    node = raw
    parts = path.split(".")
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node.setdefault(p, {})
    node[parts[-1]] = value
    return raw


@settings(max_examples=80, deadline=None)
@given(path=st.sampled_from(NUMBER_FIELDS), value=st.one_of(NON_FINITE, st.booleans()))
def test_fuzz_non_finite_and_boolean_numbers(path, value):
    """Any number field given nan, +-inf or a boolean: a ScenarioError naming the field."""
    with pytest.raises(S.ScenarioError) as err:
        S.validate(_set(_PAPER, path, value))
    assert path in str(err.value)


@settings(max_examples=40, deadline=None)
@given(labels=st.lists(st.sampled_from(["a", "b", "c", "d"]), min_size=10, max_size=10))
def test_fuzz_labels(labels):
    """Ten labels drawn from four names always repeat: refused, naming the first repeat."""
    raw = _set(_PAPER, "media.0.labels", labels)
    first = next(k for k, lab in enumerate(labels) if lab in labels[:k])
    with pytest.raises(S.ScenarioError) as err:
        S.validate(raw)
    assert f"labels.{first}" in str(err.value)


CELL = st.one_of(st.sampled_from(["nan", "inf", "-1", "0", "abc", "true", "", "1e-3", "0.005", "-0.02"]),
                 st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cells=st.lists(st.tuples(st.sampled_from(["A", "B", "C", ""]), CELL, CELL, CELL), min_size=0, max_size=4))
def test_fuzz_granule_csv(tmp_path, cells):
    """Random CSV content: either the scenario loads (every value finite, radius positive, labels
    unique and non-empty, no overlap) or a ScenarioError names the file; never another exception."""
    path = tmp_path / "g.csv"
    path.write_text(GRANULES + "".join(",".join(row) + "\n" for row in cells))
    raw = _set(_set(_PAPER, "media.0.granules_file", str(path)), "media.0.side", "none")
    raw["media"][0].pop("columns", None)
    raw["media"][0].pop("radius", None)
    raw["excitations"] = []
    try:
        S.validate(raw)
    except S.ScenarioError as e:
        assert "g.csv" in str(e) or "media" in str(e)


@pytest.mark.parametrize("out, code, words", [
    ("afile", 2, ["--out afile", "not a folder"]),
    ("/proc/granel-nowhere", 4, ["--out", "cannot write"]),
])
def test_paper_checks_its_folder_before_running(tmp_path, monkeypatch, out, code, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("keep me")
    r = runner.invoke(app, ["paper", "--out", out])
    assert r.exit_code == code, r.output
    assert all(w in r.output for w in words) and "Traceback" not in r.output
    assert (tmp_path / "afile").read_text() == "keep me"


@pytest.mark.parametrize("content, code", [(None, 2), (b"not a checkpoint", 4), (b"PK\x03\x04truncated", 4)])
def test_resume_from_a_missing_or_corrupt_checkpoint(tmp_path, monkeypatch, content, code):
    monkeypatch.chdir(tmp_path)
    if content is not None:
        (tmp_path / "out.ckpt").write_bytes(content)
    r = invoke([*SMALL, "-o", "out.nc", "--resume", "out.ckpt"])
    assert r.exit_code == code, r.output
    assert "out.ckpt" in r.output
    if content is not None:
        assert (tmp_path / "out.ckpt").read_bytes() == content  # kept: it was not this run's
