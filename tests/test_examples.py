"""The examples gallery (examples/*.py) runs, shortened (GRANEL_EXAMPLE_QUICK=1), in a scratch
folder: each exits 0 and prints or writes what it says."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize("script, expect", [
    ("shock_on_the_paper_interface.py", "wrote shock_energies.png"),
    ("precompressed_chain_cutoff.py", "1.1 f_c: the far wall feels"),
    pytest.param("shaker_and_export.py", "repeats every 2 drive period(s)", marks=pytest.mark.slow),  # about 11 s
    pytest.param("dimer_on_a_cord.py", "wrote dimer_cord.png", marks=pytest.mark.slow),  # about 8 s
    pytest.param("zener_impact.py", "wrote zener_impact.png", marks=pytest.mark.slow),  # about 15 s (two plates' modes)
    pytest.param("solitary_wave_transducer.py", "wrote solitary_wave_transducer.png", marks=pytest.mark.slow),  # 10 s
])
def test_example_runs(tmp_path, script, expect):
    env = {**os.environ, "GRANEL_EXAMPLE_QUICK": "1", "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, str(EXAMPLES / script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert expect in res.stdout, res.stdout
    if script.startswith("shaker"):
        assert (tmp_path / "shaker-export" / "granules.pvd").exists()
        assert (tmp_path / "shaker-export" / "granules.extxyz").exists()


@pytest.mark.slow  # the notebook under nbmake (about 8 s)
def test_notebook_runs(tmp_path):
    """examples/nonreciprocal_transmission.ipynb runs top to bottom under nbmake (its own pytest, in a
    subprocess: `make test` does not pass --nbmake), shortened, on this interpreter's python3 kernel
    (ipykernel's, found first through JUPYTER_PATH); it writes nothing, and no .pytest_cache either."""
    notebook = EXAMPLES / "nonreciprocal_transmission.ipynb"
    kernels = str(Path(sys.prefix) / "share" / "jupyter")
    env = {**os.environ, "GRANEL_EXAMPLE_QUICK": "1",
           "JUPYTER_PATH": os.pathsep.join(filter(None, [kernels, os.environ.get("JUPYTER_PATH")]))}
    env.pop("MPLBACKEND", None)  # the kernel's own inline backend
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbmake",
                          "--nbmake-timeout=600", str(notebook)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, (res.stdout + res.stderr)[-4000:]
    assert "1 passed" in res.stdout, res.stdout
