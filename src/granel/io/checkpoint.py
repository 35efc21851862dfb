"""Resumable checkpoints: the full integrator state plus the outputs recorded so far (npz,
written atomically). A checkpoint carries a fingerprint of the scenario so that a run is only
resumed with the scenario that wrote it."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np


def fingerprint(text: str) -> str:
    """The checkpoint's key of a scenario text (file names that are not UTF-8 kept as bytes)."""
    return hashlib.sha256(text.encode(errors="surrogateescape")).hexdigest()[:16]


def save_checkpoint(path: str | Path, fp: str, arrays: dict, recorded: dict, times: list) -> Path:
    path = Path(path)
    from ..guard.owners import MARK

    payload = {"__fingerprint": np.array(fp), "__times": np.asarray(times), "__" + MARK.replace(" ", "_"): np.array(1)}
    for k, v in arrays.items():
        payload[f"state:{k}"] = np.asarray(v)
    for k, v in recorded.items():
        payload[f"rec:{k}"] = np.asarray(v)
    from .results import atomic_path

    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **payload)
    return path


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be resumed: missing, unreadable, truncated or corrupt, not a
    granel checkpoint, or written by another scenario or solver settings. The message names the
    file; `code` is the exit code: 2 (a wrong choice: no such file, or another scenario's
    checkpoint) or 4 (the file cannot be read as a checkpoint). A RuntimeError, as the errors of
    `load_checkpoint` always were."""

    def __init__(self, message: str, code: int = 4):
        super().__init__(message)
        self.code = code


# what every checkpoint holds besides the solver's own state arrays
_REQUIRED = ("__fingerprint", "__times", "state:k", "rec:times", "rec:solid_times")


def load_checkpoint(path: str | Path, fp: str) -> tuple[dict, dict, list]:
    """The (solver state, recorded outputs, output times) of a checkpoint written by
    `save_checkpoint` with fingerprint `fp`. `path` may also name the run's result file: its
    `.ckpt` sibling is read. Every problem with the file raises CheckpointError."""
    path = Path(path)
    if path.suffix != ".ckpt" and path.with_suffix(".ckpt").exists():
        path = path.with_suffix(".ckpt")
    if not path.exists():
        raise CheckpointError(f"checkpoint {path}: no such file", 2)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path}: not a file")
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - OSError, EOFError, BadZipFile, ValueError (pickled data), ...
        raise CheckpointError(f"checkpoint {path}: unreadable or not a checkpoint ({_why(e)})") from None
    if not isinstance(z, np.lib.npyio.NpzFile):  # a bare .npy array
        raise CheckpointError(f"checkpoint {path}: not a granel checkpoint (a single array, not an archive)")
    with z:
        missing = [k for k in _REQUIRED if k not in z.files]
        if missing:
            raise CheckpointError(f"checkpoint {path}: not a granel checkpoint (no {', '.join(missing)})")
        try:
            stored = z["__fingerprint"]
            if stored.shape != () or stored.dtype.kind != "U" or str(stored) != fp:
                raise CheckpointError(f"checkpoint {path} was written by a different scenario or solver settings", 2)
            state = {k[6:]: z[k] for k in z.files if k.startswith("state:")}
            rec = {k[4:]: list(z[k]) for k in z.files if k.startswith("rec:")}
            times = list(z["__times"])
        except CheckpointError:
            raise
        except Exception as e:  # noqa: BLE001 - a truncated or corrupted member (bad CRC, short read, ...)
            raise CheckpointError(f"checkpoint {path}: corrupt ({_why(e)})") from None
    _check_consistent(path, state, rec, times)
    return state, rec, times


def _why(e: Exception) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def _check_consistent(path: Path, state: dict, rec: dict, times: list) -> None:
    """The counts of a checkpoint written at output k agree: k + 1 output times, one record per
    output time. A mismatch means a damaged or hand-edited file."""
    k = state["k"]
    if k.shape != () or k.dtype.kind not in "iu" or int(k) < 1:
        raise CheckpointError(f"checkpoint {path}: corrupt (output counter k = {k!r})")
    nt = int(k) + 1
    if len(times) != nt or len(rec["times"]) != nt:
        raise CheckpointError(f"checkpoint {path}: corrupt ({len(rec['times'])} output times recorded for {nt} outputs)")
    if not np.all(np.isfinite(np.asarray(rec["times"], float))):
        raise CheckpointError(f"checkpoint {path}: corrupt (non-finite output times)")
    short = [name for name, v in rec.items() if name.startswith("rec:") and len(v) != nt]
    if short:
        raise CheckpointError(f"checkpoint {path}: corrupt (records {', '.join(short)} do not have {nt} outputs)")
    ns = len(rec["solid_times"])
    short = [name for name, v in rec.items() if name.startswith("solid:") and len(v) != ns]
    if short:
        raise CheckpointError(f"checkpoint {path}: corrupt (solid records {', '.join(short)} do not have {ns} entries)")


def checkpoint_period(checkpoint, every: float, output_steps: int, dt: float) -> int:
    """Output intervals between checkpoints (0: no checkpoints)."""
    if not checkpoint or every <= 0:
        return 0
    return max(1, int(round(every / (output_steps * dt))))
