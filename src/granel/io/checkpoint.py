"""Resumable checkpoints: the full integrator state plus the outputs recorded so far (npz,
written atomically). A checkpoint carries a fingerprint of the scenario so that a run is only
resumed with the scenario that wrote it, and the digest of its own bytes (the archive's comment)
so that a file changed anywhere is refused."""

from __future__ import annotations

import hashlib
import io
import struct
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

    buffer = io.BytesIO()
    np.savez(buffer, **payload)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(signed(buffer.getvalue()))
    return path


DIGEST_TAG = b"granel-sha256:"


def signed(archive: bytes) -> bytes:
    """A zip archive with no comment, given the digest of its bytes as its comment (the last two
    bytes of a comment-less archive are the comment's length)."""
    comment = DIGEST_TAG + hashlib.sha256(archive).hexdigest().encode()
    return archive[:-2] + struct.pack("<H", len(comment)) + comment


def signature_holds(raw: bytes) -> bool | None:
    """Whether a signed archive's bytes match their digest; None for an archive written before
    checkpoints were signed."""
    size = len(DIGEST_TAG) + 64
    if len(raw) < size + 22 or raw[-size:-64] != DIGEST_TAG or raw[-size - 2:-size] != struct.pack("<H", size):
        return None
    return hashlib.sha256(raw[:-size - 2] + b"\x00\x00").hexdigest().encode() == raw[-64:]


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
        raw = path.read_bytes()
    except OSError as e:
        raise CheckpointError(f"checkpoint {path}: unreadable ({_why(e)})") from None
    if signature_holds(raw) is False:
        raise CheckpointError(f"checkpoint {path}: corrupt (its bytes do not match the digest it was written with)")
    try:
        z = np.load(io.BytesIO(raw), allow_pickle=False)
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
