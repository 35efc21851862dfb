"""Modal analysis: mass-normalised modes of a SolidModel and a mode-kind classifier.

Kinds (paper Sec. IV, Fig. 6), from the mode's symmetries under the two mirrors of the solid:
  bending  antisymmetric about the mid-line of the width (u_x even across the width);
  axial    symmetric across the width (u_x odd: a width-wise squeeze at most) and antisymmetric
           up-down, so the whole solid slides along y (u_y dominant; the paper's mode 4);
  bulk     symmetric across the width and up-down symmetric: the width squeezes/expands
           (the paper's mode 7; by MODEL.md its u_y is also large: it is the second axial mode).
A symmetric shock (the paper's) can only excite up-down symmetric modes: bending modes of odd
order and bulk modes.
"""

from __future__ import annotations

from dataclasses import dataclass

from pathlib import Path

import numpy as np
import scipy.linalg as sl
from scipy.sparse.linalg import eigsh

from .base import SolidModel


@dataclass
class Modes:
    omega: np.ndarray  # (n,) rad/s, ascending
    shapes: np.ndarray  # (ndof, n), mass-normalised: shapes' M shapes = I

    @property
    def periods(self) -> np.ndarray:
        return 2 * np.pi / self.omega

    @property
    def count(self) -> int:
        return len(self.omega)


DENSE_LIMIT = 8000


def modal_analysis(model: SolidModel, count: int | None = None) -> Modes:
    """The lowest `count` modes (all with count=None), mass-normalised. Shift-invert Lanczos
    for a few modes or beyond DENSE_LIMIT DOFs, else the dense symmetric solver."""
    n = model.ndof
    if count is not None and count > n:
        count = n
    if count is not None and count < min(200, n // 4):
        # a few low modes: shift-invert Lanczos is far cheaper than the dense solver
        w2, phi = eigsh(model.K.tocsc(), count, model.M.tocsc(), sigma=0.0, which="LM")
        order = np.argsort(w2)
        w2, phi = w2[order], phi[:, order]
        phi /= np.sqrt(np.einsum("ij,ij->j", phi, model.M @ phi))[None, :]
    elif n <= DENSE_LIMIT:
        K = model.K.toarray()
        M = model.M.toarray()
        sub = None if count is None else [0, count - 1]
        w2, phi = sl.eigh(K, M, subset_by_index=sub, check_finite=False)
    else:
        if count is None:
            raise ValueError(f"{n} DOFs: give a mode count (dense solution above {DENSE_LIMIT} DOFs is not attempted)")
        w2, phi = eigsh(model.K.tocsc(), count, model.M.tocsc(), sigma=0.0, which="LM")
        order = np.argsort(w2)
        w2, phi = w2[order], phi[:, order]
        # normalise to M (eigsh returns M-orthonormal vectors already; guard anyway)
        phi /= np.sqrt(np.einsum("ij,ij->j", phi, model.M @ phi))[None, :]
    w2 = np.maximum(w2, 0.0)
    return Modes(np.sqrt(w2), phi)


def _sample_grid(model: SolidModel, nx=9, ny=81):
    x0, x1 = model.nodes[:, 0].min(), model.nodes[:, 0].max()
    y0, y1 = model.nodes[:, 1].min(), model.nodes[:, 1].max()
    xs = np.linspace(x0, x1, nx)
    ys = np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return X.ravel(), Y.ravel(), 0.5 * (x0 + x1), 0.5 * (y0 + y1)


def _mirror_probes(model: SolidModel):
    """Point-evaluation matrices at a sample grid and at its two mirror images (cached)."""
    cached = getattr(model, "_mirror_probes", None)
    if cached is None:
        basis = model.basis
        X, Y, xc, yc = _sample_grid(model)
        cached = (basis.probes(np.vstack([X, Y])), basis.probes(np.vstack([2 * xc - X, Y])),
                  basis.probes(np.vstack([X, 2 * yc - Y])), len(X))
        model._mirror_probes = cached
    return cached


def symmetry_coefficients(model: SolidModel, shape: np.ndarray) -> tuple[float, float]:
    """(width-mirror, up-down-mirror) symmetry of a plate field in reduced coordinates, each in
    [-1, 1]: +1 symmetric, -1 antisymmetric. The width mirror flips u_x, the up-down one u_y."""
    P, Pw, Pu, npt = _mirror_probes(model)
    full = model.T @ shape
    u, uw, uu = P @ full, Pw @ full, Pu @ full
    mw = np.concatenate([-uw[:npt], uw[npt:]])
    mu = np.concatenate([uu[:npt], -uu[npt:]])
    return float(u @ mw / (u @ u)), float(u @ mu / (u @ u))


def classify_modes(model: SolidModel, modes: Modes, which=None) -> list[str]:
    """Kind of each mode (bending / axial / bulk); all beam modes are bending."""
    idx = range(modes.count) if which is None else which
    if model.kind == "beam":
        return ["bending" for _ in idx]
    if model.kind != "plate":
        return ["rigid" for _ in idx]
    kinds = []
    for k in idx:
        s_width, s_updown = symmetry_coefficients(model, modes.shapes[:, k])
        kinds.append("bending" if s_width < 0 else ("axial" if s_updown < 0 else "bulk"))
    return kinds


# ---------------------------------------------------------------- all modes, cached on disk


def cache_dir():
    import os
    from pathlib import Path

    return Path(os.environ.get("GRANEL_CACHE", Path.home() / ".cache" / "granel"))


# granel's own cache files (modes, modes below a cut-off, assembled plates): the only files pruning removes
CACHE_PATTERNS = ("modes-*.omega.npy", "modes-*.shapes.npy", "plate-*.npz")
CACHE_LIMIT = 2 * 1024**3  # bytes, unless GRANEL_CACHE_LIMIT says otherwise


def cache_limit() -> int:
    """The cache's size bound in bytes: GRANEL_CACHE_LIMIT (bytes, or with K, M, G suffix), or 2 GiB."""
    import os

    text = os.environ.get("GRANEL_CACHE_LIMIT", "").strip().upper().removesuffix("B")
    if not text:
        return CACHE_LIMIT
    scale = {"K": 1024, "M": 1024**2, "G": 1024**3}.get(text[-1], 1)
    try:
        value = float(text[:-1] if scale > 1 else text) * scale
    except ValueError:
        return CACHE_LIMIT
    return int(value) if value > 0 else CACHE_LIMIT


def prune_cache(keep=(), limit: int | None = None) -> list:
    """Remove the least recently used of granel's cache files (CACHE_PATTERNS; a cache hit
    touches its files) until the cache holds at most `limit` bytes (`cache_limit()`), never the
    files in `keep` (the ones just written or read). A design study meets a new plate at every
    trial (about 100 MB of modes each): without a bound the cache would grow without end.
    Returns the removed paths; files it cannot remove are left."""
    limit = cache_limit() if limit is None else limit
    folder = cache_dir()
    files = []
    for pattern in CACHE_PATTERNS:
        for f in folder.glob(pattern):
            try:
                st = f.stat()
            except OSError:
                continue
            files.append((st.st_mtime, st.st_size, f))
    total = sum(size for _, size, _ in files)
    keep = {Path(k).resolve() for k in keep}
    removed = []
    for _, size, f in sorted(files):
        if total <= limit:
            break
        if f.resolve() in keep:
            continue
        try:
            f.unlink()
        except OSError:
            continue
        total -= size
        removed.append(f)
    return removed


def _touch(*paths) -> None:
    import os

    for p in paths:
        try:
            os.utime(p)
        except OSError:
            pass


def all_modes(model: SolidModel) -> Modes:
    """All modes of the solid, cached on disk by a hash of M and K (the plate's 3584 take about
    9 s to compute). The shapes come back memory-mapped: a run reads only the rows at its
    contacts (`at_dofs`), a field plot the whole matrix."""
    return _cached(model, "modes", "", lambda: modal_analysis(model, None), mmap=True)


def modes_below(model: SolidModel, f_cut: float, max_count: int | None = None) -> Modes:
    """The eigenmodes up to f_cut [Hz] (at most `max_count` of them) of a solid too large for all
    of them (beyond DENSE_LIMIT DOFs), by shift-invert Lanczos at 0 with the count raised until the
    highest passes f_cut; cached on disk by M, K, f_cut and max_count like `all_modes`."""

    def compute():
        w_cut, count = 2 * np.pi * f_cut, 64
        top = model.ndof - 1 if max_count is None else min(model.ndof - 1, max_count)
        while True:
            modes = modal_analysis(model, min(count, top))
            if modes.omega[-1] > w_cut or modes.count >= top:
                break
            # the mode count grows as f^2 in a plate: aim past the cut-off
            count = int(min(top, max(2 * count, 1.2 * count * (w_cut / modes.omega[-1]) ** 2)))
        keep = modes.omega <= w_cut
        return Modes(modes.omega[keep], np.ascontiguousarray(modes.shapes[:, keep]))

    return _cached(model, "modes-below", repr((float(f_cut), max_count)), compute, mmap=False)


def _cached(model: SolidModel, prefix: str, key: str, compute, mmap: bool) -> Modes:
    """Modes from the disk cache (by a hash of M, K and `key`), or `compute()` and store them
    (atomically; without a writable cache they are simply recomputed next time)."""
    import hashlib

    h = hashlib.sha256(key.encode())
    for A in (model.M, model.K):
        A = A.tocsr()
        A.sort_indices()
        for arr in (A.indptr, A.indices, A.data):
            h.update(np.ascontiguousarray(arr).tobytes())
    stem = cache_dir() / f"{prefix}-{model.kind}-{model.ndof}-{h.hexdigest()[:20]}"
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    if omega_path.exists() and shapes_path.exists():
        try:
            omega = np.load(omega_path)
            shapes = np.load(shapes_path, mmap_mode="r" if mmap else None)
            if shapes.shape == (model.ndof, len(omega)):
                _touch(omega_path, shapes_path)  # recently used: pruned last
                return Modes(omega, shapes)
        except (OSError, ValueError):
            pass  # a damaged cache file is recomputed and replaced
    modes = compute()
    try:
        stem.parent.mkdir(parents=True, exist_ok=True)
        _save_atomic(shapes_path, modes.shapes)
        _save_atomic(omega_path, modes.omega)
        prune_cache(keep=(omega_path, shapes_path))
    except OSError:
        pass
    return modes


def _save_atomic(path, array) -> None:
    import os

    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.save(fh, array)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def at_dofs(B, shapes, columns=slice(None)) -> np.ndarray:
    """B @ shapes[:, columns] reading only the rows of `shapes` that B touches (B: a sparse map
    from the solid's DOFs, e.g. its contact points; `shapes` may be memory-mapped)."""
    B = B.tocsc()
    rows = np.flatnonzero(np.diff(B.indptr))
    sub = np.asarray(shapes[rows])[:, columns]
    return np.ascontiguousarray(B[:, rows] @ sub)
