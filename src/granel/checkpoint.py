"""Resumable checkpoints: the full integrator state plus the outputs recorded so far (npz,
written atomically). A checkpoint carries a fingerprint of the scenario so that a run is only
resumed with the scenario that wrote it."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np


def fingerprint(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def save_checkpoint(path: str | Path, fp: str, arrays: dict, recorded: dict, times: list) -> Path:
    path = Path(path)
    payload = {"__fingerprint": np.array(fp), "__times": np.asarray(times)}
    for k, v in arrays.items():
        payload[f"state:{k}"] = np.asarray(v)
    for k, v in recorded.items():
        payload[f"rec:{k}"] = np.asarray(v)
    from .results import atomic_path

    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **payload)
    return path


def load_checkpoint(path: str | Path, fp: str) -> tuple[dict, dict, list]:
    path = Path(path)
    if path.suffix != ".ckpt" and path.with_suffix(".ckpt").exists():
        path = path.with_suffix(".ckpt")
    if not path.exists():
        raise RuntimeError(f"no checkpoint at {path}")
    with np.load(path, allow_pickle=False) as z:
        if str(z["__fingerprint"]) != fp:
            raise RuntimeError(f"checkpoint {path} was written by a different scenario or solver settings")
        state = {k[6:]: z[k] for k in z.files if k.startswith("state:")}
        rec = {k[4:]: list(z[k]) for k in z.files if k.startswith("rec:")}
        times = list(z["__times"])
    return state, rec, times


def checkpoint_period(checkpoint, every: float, output_steps: int, dt: float) -> int:
    """Output intervals between checkpoints (0: no checkpoints)."""
    if not checkpoint or every <= 0:
        return 0
    return max(1, int(round(every / (output_steps * dt))))
