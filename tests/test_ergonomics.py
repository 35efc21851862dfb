"""Scenario ergonomics: `--set key=-` removes a key or a list entry, and `granel show --resolved`
prints the scenario with every default, as TOML that reads back to the same scenario."""

import tomllib

import pytest
from typer.testing import CliRunner

from granel import scenario as S
from granel.cli import app

runner = CliRunner()


def test_an_override_removes_a_list_entry_or_a_key():
    sc = S.load("paper", ["media.1=-"])
    assert [m.name for m in sc.media] == ["LSGM"]
    raw, _ = S.load_raw("paper")
    out = S.apply_overrides(raw, ["media.0=-", "media.0.radius=0.006", "excitations.0.tau=-"])
    assert [m["name"] for m in out["media"]] == ["SSGM"] and out["media"][0]["radius"] == 0.006
    assert "tau" not in out["excitations"][0]
    assert len(raw["media"]) == 2  # the original is untouched
    for bad in ("media.7=-", "contact.nothing=-", "media.x=-"):
        with pytest.raises(S.ScenarioError, match="nothing to remove"):
            S.apply_overrides(raw, [bad])


def test_show_resolved_prints_every_default_and_reads_back():
    res = runner.invoke(app, ["show", "paper", "--resolved", "--set", "media.1=-", "--set", "contact.mu=0.2"])
    assert res.exit_code == 0, res.output
    data = tomllib.loads(res.stdout)
    assert data["contact"]["mu"] == 0.2 and len(data["media"]) == 1
    for key in ("ledger_tol", "balance_limit", "overlap_limit", "equilibrate", "integrator"):
        assert key in data["simulation"]
    again = S.validate(data)
    assert S.to_toml(again) == res.stdout
    res = runner.invoke(app, ["show", "paper", "--resolved", "--set", "media.9=-"])
    assert res.exit_code == 2 and "nothing to remove" in " ".join(res.output.split())


def test_init_writes_a_valid_commented_template_and_never_replaces_a_file(tmp_path, monkeypatch):
    """`granel init demo`: demo.toml is the paper's scenario under another name (identical once
    resolved), with the schema's descriptions as comments; a second init refuses (exit 2) and
    leaves the file as it was."""
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["init", "demo"])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "demo.toml").read_text()
    assert "# Coulomb friction coefficient" in text and "# granules_file = ..." in text
    sc = S.load(str(tmp_path / "demo.toml"))
    paper = S.load("paper")
    assert sc.name == "demo"
    assert S.to_toml(sc.model_copy(update={"name": paper.name, "description": paper.description})) == S.to_toml(paper)
    (tmp_path / "demo.toml").write_text(text + "# mine\n")
    res = runner.invoke(app, ["init", "demo"])
    assert res.exit_code == 2 and "never replaces" in " ".join(res.output.split())
    assert (tmp_path / "demo.toml").read_text().endswith("# mine\n")
    assert runner.invoke(app, ["init", "../x"]).exit_code == 2


def test_a_scenario_without_a_solid(tmp_path):
    """`solid.kind = "none"`: two steel granules (R = 5 mm) in head-on collision, nothing else:
    no solid contact, no solid energy, momentum conserved to round-off, and the rebound speeds
    those of an elastic collision of equal masses (exchanged) within 1e-6 of the impact speed;
    a hexagonal medium can be placed without a solid beside it."""
    import numpy as np

    from granel.run import run_scenario

    (tmp_path / "two.csv").write_text("label,x,y,radius\nA,0.0,0.0,0.005\nB,0.0101,0.0,0.005\n")
    (tmp_path / "two.toml").write_text("""name = "two"
[simulation]
duration = "250us"
output_every = "1us"
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "none"
[[media]]
name = "G"
side = "none"
granules_file = "two.csv"
[[initial_velocities]]
granule = "G:A"
v = [1.0, 0.0]
""")
    ds = run_scenario(S.load(str(tmp_path / "two.toml")))
    assert ds.attrs["solid_kind"] == "rigid" and ds.sizes.get("contact", 0) == 0
    assert np.abs(ds["energy_solid"].values).max() == 0.0
    p = ds["v_x"].values.sum(axis=1)
    assert np.abs(p - 1.0).max() < 1e-12
    assert ds["v_x"].values[-1, 0] == pytest.approx(0.0, abs=1e-6) and ds["v_x"].values[-1, 1] == pytest.approx(1.0, abs=1e-6)
    hexa = S.load("paper", ['solid.kind="none"', "media.1=-"])
    from granel.scenario.build import build_granular

    system, _, _ = build_granular(hexa, hexa.base)
    assert system.n == 14 and not system.solid_contacts


def test_a_hexagonal_medium_anywhere():
    """`media.N.face_x` (with `center_y`) places a hexagonal medium away from any solid: the
    paper's SSGM (R = 5 mm, columns 5, 4, 5) grown rightward from x = 0.3, centred on y = -0.2,
    has column 0 at x = 0.305 and its channel walls 5 mm beyond its outer granules."""
    import numpy as np

    from granel.scenario.build import build_granular

    sc = S.load("paper", ['solid.kind="none"', "media.0=-", "media.0.face_x=0.3", "media.0.center_y=-0.2",
                          'excitations.0.granule="SSGM:C"'])
    system, _, _ = build_granular(sc, sc.base)
    x, y = system.pos0[:, 0], system.pos0[:, 1]
    assert x.min() == pytest.approx(0.305, abs=1e-12)
    assert x.max() == pytest.approx(0.305 + 2 * 0.005 * np.sqrt(3), abs=1e-12)
    col0 = np.isclose(x, 0.305)
    assert col0.sum() == 5 and np.mean(y[col0]) == pytest.approx(-0.2, abs=1e-12)
    walls = {w.name: w for w in system.walls}
    assert walls["SSGM:bottom"].p0[1] == pytest.approx(y.min() - 0.005)
    assert walls["SSGM:top"].p0[1] == pytest.approx(y.max() + 0.005)


def test_one_version():
    """The package, its installed metadata and CITATION.cff give the same version."""
    from importlib.metadata import version
    from pathlib import Path

    import granel

    cff = (Path(__file__).resolve().parents[1] / "CITATION.cff").read_text()
    line = next(x for x in cff.splitlines() if x.startswith("version:"))
    assert line.split(":", 1)[1].strip() == granel.__version__ == version("granel")
