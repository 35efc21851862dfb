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
    ("shaker_and_export.py", "repeats every 2 drive period(s)"),
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
