"""One computation of a solid's modes at a time (solid.mode_cache.cached_modes): a process that meets a
set another live process is computing waits for it instead of solving it again, and a lock
whose holder has died is taken over."""

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from granel.guard.owners import process_token
from granel.solid import cache_lock, mode_cache, mode_scaling, modal
from granel.solid.base import Material, Slab
from granel.solid.plate import LayerSpec, PlateMesh, assemble_plate


@pytest.fixture
def plate(tmp_path, monkeypatch):
    monkeypatch.setenv("GRANEL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(cache_lock, "LOCK_POLL_S", 0.02)
    layers = [LayerSpec("a", "left", 0.05, 0.001), LayerSpec("b", "right", 0.04, 0.001)]
    return assemble_plate(Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), layers, PlateMesh(2, 2.5, 8e-3))


def holder(token: str) -> str:
    """A lock's text naming the process of `token` as its holder (`cache_lock._lock_text`'s fields)."""
    pid = int(token.split("-")[1])
    return json.dumps({"token": token, "host": "here", "pid": pid, "since": time.time(), "what": "test modes"})


def test_a_process_waits_for_the_modes_another_is_computing(plate):
    stem = mode_cache._stem(plate, "modes", "")
    lock = stem.with_suffix(".lock")
    lock.parent.mkdir(parents=True)
    lock.write_text(holder(process_token()))  # a live holder: this process
    got = {}
    waiter = threading.Thread(target=lambda: got.setdefault("modes", mode_cache.all_modes(plate)))
    waiter.start()
    time.sleep(0.5)
    assert waiter.is_alive() and "modes" not in got  # it waits rather than solve
    modes = modal.modal_analysis(plate)
    mode_cache._store(plate, stem, mode_scaling._scale_free(plate), (float("inf"), None), modes)
    lock.unlink()  # the holder is done
    waiter.join(30)
    assert not waiter.is_alive()
    assert got["modes"].origin == "cache"
    assert np.array_equal(got["modes"].omega, modes.omega)  # the stored array read back, bit for bit


def test_a_lock_whose_holder_died_is_taken_over(plate):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = mode_cache._stem(plate, "modes", "").with_suffix(".lock")
    lock.parent.mkdir(parents=True)
    lock.write_text(holder(process_token(dead.pid)))
    modes = mode_cache.all_modes(plate)
    assert modes.origin == "computed" and not lock.exists()
    assert mode_cache.all_modes(plate).origin == "cache"


def test_an_empty_old_lock_is_taken_over(plate):
    lock = mode_cache._stem(plate, "modes", "").with_suffix(".lock")
    lock.parent.mkdir(parents=True)
    lock.write_text("")
    old = time.time() - 60
    os.utime(lock, (old, old))
    assert mode_cache.all_modes(plate).origin == "computed" and not lock.exists()


def test_the_lock_is_released_when_the_solve_fails(plate, monkeypatch):
    def broken(model, count=None):
        raise RuntimeError("no modes today")

    monkeypatch.setattr(mode_cache, "modal_analysis", broken)
    with pytest.raises(RuntimeError):
        mode_cache.all_modes(plate)
    assert not mode_cache._stem(plate, "modes", "").with_suffix(".lock").exists()
