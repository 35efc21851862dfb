"""The solids' modes on disk: all modes, or the modes below a cut-off, of a solid are stored
under a hash of its M and K, each file with a check record (size and CRC-32, `cache_files`) so
that a damaged entry is computed again, never used; one process computes a given set at a time,
the others wait for it (`cache_lock`); a solid proportional to a cached one (another thickness,
modulus or density) gets that one's modes scaled (`mode_scaling`); the least recently used
entries are pruned beyond a size bound."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..guard.fingerprints import sparse_digest
from .base import SolidModel
from .cache_files import cache_dir, note, prune_cache, touch, unwritable, verify, write_checked
from .cache_lock import _acquire, _release, _wait_for
from .modal import Modes, modal_analysis, modes_up_to
from .mode_scaling import _record_path, _scale_free, _write_record, scaled_modes


# ---------------------------------------------------------------- all modes, cached on disk


def all_modes(model: SolidModel) -> Modes:
    """All modes of the solid, cached on disk by a hash of M and K. The shapes come back
    memory-mapped: a run reads only the rows at its contacts (`at_dofs`), a field plot the whole
    matrix. A solid whose K and M are those of a cached one times two scalars (another thickness,
    Young's modulus or density of the same plate) gets that solid's modes scaled (`scaled_modes`),
    with no eigen-solve."""
    what = f"the modes of a {model.kind} of {model.ndof} DOFs"
    return cached_modes(model, "modes", "", lambda: modal_analysis(model, None), mmap=True, what=what)


def modes_below(model: SolidModel, f_cut: float, max_count: int | None = None) -> Modes:
    """The eigenmodes up to f_cut [Hz] (at most `max_count` of them) of a solid too large for all
    of them (beyond DENSE_LIMIT DOFs) or a run that keeps only those (`modal.modes_up_to`); cached on disk by M, K, f_cut and max_count like `all_modes`, and
    scaled like it from a cached set of a proportional solid that reaches far enough."""
    w_cut = 2 * np.pi * f_cut
    top = model.ndof - 1 if max_count is None else min(model.ndof - 1, max_count)

    def compute():
        return modes_up_to(model, w_cut, top)

    what = f"the modes below {f_cut / 1e6:.4g} MHz of a {model.kind} of {model.ndof} DOFs"
    return cached_modes(model, "modes-below", repr((float(f_cut), max_count)), compute, mmap=False, wanted=(w_cut, top),
                   what=what)


def cached_modes(model: SolidModel, prefix: str, key: str, compute, mmap: bool, wanted=(np.inf, None),
            what="modes") -> Modes:
    """Modes from the disk cache (by a hash of M, K and `key`), or scaled from the cached modes
    of a proportional solid (`scaled_modes`), or `compute()` and store them. Only files that match
    their check records are used (`verify`): a damaged entry is computed again, with a note.
    `wanted` = (w_cut [rad/s], most modes): what `compute` returns, the lowest modes up to w_cut,
    at most that many (None: no bound); all modes by default. Each stored set gets a scale-free
    record (`_write_record`). Only one process computes a given set at a time (`_acquire`): the
    others wait for it, within a bound (`_wait_for`). Without a writable cache the modes are
    computed, with a note, and nothing is stored."""
    stem = _stem(model, prefix, key)
    free = _scale_free(model)
    lock = stem.with_suffix(".lock")
    while True:
        modes, damage = _from_cache(model, stem, free, wanted, mmap)
        if modes is None and free is not None:
            modes = scaled_modes(model, prefix, free, wanted, mmap, exclude=stem)
        if modes is not None:
            return modes
        held = _acquire(lock, what)
        if held is False and _wait_for(lock, what):
            continue  # released, or its holder is gone: look again
        try:
            if held:  # stored by another process while this one waited for the lock
                modes, damage = _from_cache(model, stem, free, wanted, mmap)
                if modes is not None:
                    return modes
            if damage:
                note(("rebuilt", stem), f"cache: {damage}; computing {what} again")
            modes = compute()
            if held is not False:  # a live holder that outlasted the wait stores its own
                _store(model, stem, free, wanted, modes)
        finally:
            if held:
                _release(lock)
        return modes


def _stem(model: SolidModel, prefix: str, key: str) -> Path:
    """The cache entry's path without suffix: a hash of M, K and `key`."""
    return cache_dir() / f"{prefix}-{model.kind}-{model.ndof}-{matrix_key(model, key)}"


def matrix_key(model: SolidModel, key: str = "") -> str:
    """The hash of M, K (and `key`) that names the solid's mode-cache entries."""
    return sparse_digest((model.M, model.K), key)[:20]


def _from_cache(model: SolidModel, stem: Path, free, wanted, mmap: bool) -> tuple[Modes | None, str | None]:
    """(the solid's own modes from the cache files at `stem`, None), or (None, what is wrong
    with them) for a damaged entry, or (None, None) without one."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    if not (omega_path.exists() and shapes_path.exists()):
        return None, None
    for path in (omega_path, shapes_path):
        damage = verify(path)
        if damage:
            return None, damage
    try:
        omega = np.load(omega_path)
        shapes = np.load(shapes_path, mmap_mode="r" if mmap else None)
    except (OSError, ValueError, EOFError) as e:  # matches its record, yet unreadable: written so
        return None, f"{shapes_path.name} cannot be read ({type(e).__name__})"
    if shapes.shape != (model.ndof, len(omega)):
        return None, f"{shapes_path.name} holds {shapes.shape} shapes, not ({model.ndof}, {len(omega)})"
    touch(omega_path, shapes_path)  # recently used: pruned last
    if free is not None:
        record = _record_path(stem)
        damage = verify(record) if record.exists() else None
        if damage:
            note(("rebuilt", record), f"cache: {damage}; writing it again")
        if damage or not record.exists():  # lost or damaged on its own: written again from this solid
            try:
                _write_record(stem, free, omega, model.ndof, wanted)
            except OSError as e:
                unwritable(stem.parent, e)
        else:
            touch(record)
    return Modes(omega, shapes, "cache"), None


def _store(model: SolidModel, stem: Path, free, wanted, modes: Modes) -> None:
    """Computed modes into the cache (each file atomically, synced, then its check record), with
    their scale-free record; a note and nothing else if the cache cannot be written."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    try:
        write_checked(shapes_path, modes.shapes)
        write_checked(omega_path, modes.omega)
        kept = [omega_path, shapes_path]
        if free is not None:
            kept.append(_write_record(stem, free, modes.omega, model.ndof, wanted))
        prune_cache(keep=kept)
    except OSError as e:
        unwritable(stem.parent, e)
