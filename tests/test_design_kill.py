"""A design study killed at any moment on several workers loses no finished trial (issue 17):
the study lives in Optuna's journal, written as each trial is told; a rerun of the same command
replays the trials that were in flight and keeps every finished one as it was."""

import os
import signal
import subprocess
import sys
import time

import pytest

from test_design import write_design


def _finished(out):
    """{trial number: (params, values)} of the complete trials in out's journal."""
    from optuna.trial import TrialState

    from granel.studies.design import load_design
    from granel.studies.design_search import open_study

    spec, _ = load_design(out.parent / "d.toml")
    study = open_study(spec, out)
    return {t.number: (dict(t.params), list(t.values)) for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))}


@pytest.mark.slow
def test_a_study_killed_on_two_workers_loses_no_finished_trial(tmp_path):
    from granel.studies.design import load_design
    from granel.studies.design_search import DesignRunOptions, run_design

    path = write_design(tmp_path, trials=60, seed=3)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "granel", "design", str(path), "-o", str(out), "--workers", "2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.5)
            if (out / "study.journal").exists() and len(_finished(out)) >= 4:
                break
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the command, its scheduler and both workers at once
        proc.wait()
    before = _finished(out)
    assert 4 <= len(before) < 60, "the study was not caught mid-way"
    spec, base = load_design(path)
    res = run_design(spec, base, out, options=DesignRunOptions(workers=2))
    after = _finished(out)
    for number, held in before.items():  # every trial finished before the kill, unchanged
        assert after[number] == held
    ds = res["trials"]
    assert int((ds["status"].values == "ok").sum()) == 60
