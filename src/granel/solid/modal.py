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
import scipy.sparse as sp

from .base import SolidModel


@dataclass
class Modes:
    omega: np.ndarray  # (n,) rad/s, ascending
    shapes: np.ndarray  # (ndof, n), mass-normalised: shapes' M shapes = I (or `ScaledShapes`)
    origin: str = "computed"  # "computed", "cache" (the solid's own cached modes) or "scaled" (another solid's)

    @property
    def periods(self) -> np.ndarray:
        return 2 * np.pi / self.omega

    @property
    def count(self) -> int:
        return len(self.omega)


DENSE_LIMIT = 8000


def modal_analysis(model: SolidModel, count: int | None = None) -> Modes:
    """The lowest `count` modes (all with count=None), mass-normalised. Shift-invert Lanczos
    for a few modes or beyond DENSE_LIMIT DOFs, else the dense symmetric solver, on the two
    halves of a solid symmetric about its mid-height (`solid.symmetry`) or on the whole."""
    n = model.ndof
    if count is not None and count > n:
        count = n
    if count is not None and count < min(200, n // 4):
        # a few low modes: shift-invert Lanczos is far cheaper than the dense solver
        from scipy.sparse.linalg import eigsh

        w2, phi = eigsh(model.K.tocsc(), count, model.M.tocsc(), sigma=0.0, which="LM")
        order = np.argsort(w2)
        w2, phi = w2[order], phi[:, order]
        phi /= np.sqrt(np.einsum("ij,ij->j", phi, model.M @ phi))[None, :]
    elif n <= DENSE_LIMIT:
        from .symmetry import mirror_operator, split_eigh

        S = mirror_operator(model)
        if S is not None:
            # symmetric about its mid-height (the paper's plate): two halves, a quarter of the cost
            w2, phi = split_eigh(model.K, model.M, S)
            if count is not None:
                w2, phi = w2[:count], np.ascontiguousarray(phi[:, :count])
        else:
            import scipy.linalg as sl

            K = model.K.toarray()
            M = model.M.toarray()
            sub = None if count is None else [0, count - 1]
            w2, phi = sl.eigh(K, M, subset_by_index=sub, check_finite=False)
    else:
        if count is None:
            raise ValueError(f"{n} DOFs: give a mode count (dense solution above {DENSE_LIMIT} DOFs is not attempted)")
        from scipy.sparse.linalg import eigsh

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


# granel's own cache files (modes, modes below a cut-off, their scale-free records, assembled
# plates): the only files pruning removes
CACHE_PATTERNS = ("modes-*.omega.npy", "modes-*.shapes.npy", "modes-*.scale.npz", "plate-*.npz")
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
    contacts (`at_dofs`), a field plot the whole matrix. A solid whose K and M are those of a
    cached one times two scalars (another thickness, Young's modulus or density of the same
    plate) gets that solid's modes scaled (`scaled_modes`), with no eigen-solve."""
    return _cached(model, "modes", "", lambda: modal_analysis(model, None), mmap=True)


def modes_below(model: SolidModel, f_cut: float, max_count: int | None = None) -> Modes:
    """The eigenmodes up to f_cut [Hz] (at most `max_count` of them) of a solid too large for all
    of them (beyond DENSE_LIMIT DOFs), by shift-invert Lanczos at 0 with the count raised until the
    highest passes f_cut; cached on disk by M, K, f_cut and max_count like `all_modes`, and
    scaled like it from a cached set of a proportional solid that reaches far enough."""
    w_cut = 2 * np.pi * f_cut
    top = model.ndof - 1 if max_count is None else min(model.ndof - 1, max_count)

    def compute():
        count = 64
        while True:
            modes = modal_analysis(model, min(count, top))
            if modes.omega[-1] > w_cut or modes.count >= top:
                break
            # the mode count grows as f^2 in a plate: aim past the cut-off
            count = int(min(top, max(2 * count, 1.2 * count * (w_cut / modes.omega[-1]) ** 2)))
        keep = modes.omega <= w_cut
        return Modes(modes.omega[keep], np.ascontiguousarray(modes.shapes[:, keep]))

    return _cached(model, "modes-below", repr((float(f_cut), max_count)), compute, mmap=False, wanted=(w_cut, top))


def _cached(model: SolidModel, prefix: str, key: str, compute, mmap: bool, wanted=(np.inf, None)) -> Modes:
    """Modes from the disk cache (by a hash of M, K and `key`), or scaled from the cached modes
    of a proportional solid (`scaled_modes`), or `compute()` and store them (atomically; without
    a writable cache they are simply recomputed next time). `wanted` = (w_cut [rad/s], most
    modes): what `compute` returns, the lowest modes up to w_cut, at most that many (None: no
    bound); all modes by default. Each stored set gets a scale-free record (`_write_record`).
    Only one process computes a given set at a time (`_acquire`): the others wait for it."""
    stem = _stem(model, prefix, key)
    free = _scale_free(model)
    lock = stem.with_suffix(".lock")
    while True:
        modes = _from_cache(model, stem, free, wanted, mmap)
        if modes is None and free is not None:
            modes = scaled_modes(model, prefix, free, wanted, mmap)
        if modes is not None:
            return modes
        held = _acquire(lock)
        if held is False:  # another process is computing these modes: wait for them
            _wait_for(lock)
            continue
        try:
            modes = compute()
            _store(model, stem, free, wanted, modes)
        finally:
            if held:
                _release(lock)
        return modes


def _stem(model: SolidModel, prefix: str, key: str) -> Path:
    """The cache entry's path without suffix: a hash of M, K and `key`."""
    import hashlib

    h = hashlib.sha256(key.encode())
    for A in (model.M, model.K):
        A = A.tocsr()
        A.sort_indices()
        for arr in (A.indptr, A.indices, A.data):
            h.update(np.ascontiguousarray(arr).tobytes())
    return cache_dir() / f"{prefix}-{model.kind}-{model.ndof}-{h.hexdigest()[:20]}"


def _from_cache(model: SolidModel, stem: Path, free, wanted, mmap: bool) -> Modes | None:
    """The solid's own modes from the cache files at `stem`, or None (absent or damaged)."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    if not (omega_path.exists() and shapes_path.exists()):
        return None
    try:
        omega = np.load(omega_path)
        shapes = np.load(shapes_path, mmap_mode="r" if mmap else None)
        if shapes.shape != (model.ndof, len(omega)):
            return None
        _touch(omega_path, shapes_path)  # recently used: pruned last
        if free is not None:
            record = _record_path(stem)
            if record.exists():
                _touch(record)
            else:  # a set cached before the records: it becomes a base too
                _write_record(stem, free, omega, model.ndof, wanted)
        return Modes(omega, shapes, "cache")
    except (OSError, ValueError):
        return None  # a damaged cache file is recomputed and replaced


def _store(model: SolidModel, stem: Path, free, wanted, modes: Modes) -> None:
    """Computed modes into the cache (atomically), with their scale-free record; nothing if the
    cache is not writable."""
    omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
    try:
        stem.parent.mkdir(parents=True, exist_ok=True)
        _save_atomic(shapes_path, modes.shapes)
        _save_atomic(omega_path, modes.omega)
        kept = [omega_path, shapes_path]
        if free is not None:
            kept.append(_write_record(stem, free, modes.omega, model.ndof, wanted))
        prune_cache(keep=kept)
    except OSError:
        pass


# ---------------------------------------------------------------- one computation at a time
#
# Workers of a sweep or a design study that meet the same new solid at once would each solve it
# (a plate's modes take seconds of both cores): the first takes a lock file beside the cache
# entry, and the others wait for its modes. A lock whose holder has died (its process gone on
# this host, or the lock older than LOCK_STALE_S) is taken over, so a killed run leaves nobody
# waiting.

LOCK_STALE_S = 1800.0
LOCK_POLL_S = 0.25


def _acquire(lock: Path) -> bool | None:
    """True: this process holds `lock`; False: a live holder has it; None: no lock can be taken
    (an unwritable cache), and the caller computes without one."""
    import os
    import socket

    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        if _stale(lock):
            _release(lock)
            return _acquire(lock)
        return False
    except OSError:
        return None
    with os.fdopen(fd, "w") as fh:
        fh.write(f"{socket.gethostname()} {os.getpid()}\n")
    return True


def _stale(lock: Path) -> bool:
    """The lock's holder is gone: its process no longer runs on this host, or the lock is older
    than LOCK_STALE_S (a holder on another host of a shared cache)."""
    import os
    import socket
    import time

    try:
        age = time.time() - lock.stat().st_mtime
        text = lock.read_text()
    except OSError:
        return False  # just released: look again
    try:
        host, pid = text.split()
    except ValueError:
        return age > 10.0  # being written, or left empty by a holder killed as it wrote
    if age > LOCK_STALE_S:
        return True
    if host != socket.gethostname():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except (PermissionError, ValueError):
        return False
    return False


def _wait_for(lock: Path) -> None:
    """Until `lock` is released or stale."""
    import time

    while lock.exists() and not _stale(lock):
        time.sleep(LOCK_POLL_S)


def _release(lock: Path) -> None:
    try:
        lock.unlink()
    except OSError:
        pass


# ---------------------------------------------------------------- modes of a proportional solid
#
# For one mesh, clamping, rigid layers and Poisson ratio, the plane-stress plate's K is E h times
# a fixed matrix and its M rho h times another (plate.plane_stress_forms: K = h D(E, nu), D
# proportional to E at a fixed nu; M = rho h N'N; the rigid layers' T and the clamps are
# geometric), and the beam's K is E I and its M rho A times fixed matrices (beam.build_beam: it
# has bending DOFs only, so its thickness and width scale both exactly). If K = a K0 and M = b M0,
# K phi = w^2 M phi has the shapes of (K0, M0), w^2 = (a / b) w0^2, and the mass-normalised shapes
# are phi0 / sqrt(b). The check is on the matrices themselves, not on the parameters: each cached
# set keeps K0 / tr K0 and M0 / tr M0 (a "scale-free record"), and a solid reuses it only when its
# own K / tr K and M / tr M agree with them within SCALE_TOL of their largest entry (entry by
# entry, a stored entry missing on one side counting as zero: a sparse product drops the entries
# that cancel to exactly zero, so the sparsity itself may differ at round-off); a changed Poisson
# ratio, mesh, clamping or any term that does not scale (a spring of fixed stiffness) fails that
# and the modes are computed.

SCALE_TOL = 1e-12  # the largest difference of the normalised matrices, relative to their largest entry


@dataclass
class _ScaleFree:
    k: sp.csr_matrix  # K / tr K
    m: sp.csr_matrix  # M / tr M
    k_trace: float
    m_trace: float


def _scale_free(model: SolidModel) -> _ScaleFree | None:
    """The solid's matrices divided by their traces; None if a trace is not positive (no
    proportional reuse then)."""
    parts = []
    for A in (model.K, model.M):
        A = A.tocsr()
        trace = float(A.diagonal().sum())
        if not (np.isfinite(trace) and trace > 0):
            return None
        parts.append((A * (1.0 / trace), trace))
    (k, tk), (m, tm) = parts
    return _ScaleFree(k, m, tk, tm)


def _record_path(stem: Path) -> Path:
    return stem.with_name(f"{stem.name}.scale.npz")


def _write_record(stem: Path, free: _ScaleFree, omega: np.ndarray, ndof: int, wanted) -> Path:
    """Store the scale-free record of the modes at `stem`: the normalised matrices, their traces
    and how far the set is complete (`complete_to` [rad/s]: every mode up to it is in the set;
    infinite for all modes)."""
    w_cut, top = wanted
    if len(omega) >= ndof:
        complete = np.inf
    elif top is None or len(omega) < top:
        complete = w_cut
    else:  # the count bound cut the set: complete up to its highest mode
        complete = float(omega[-1]) if len(omega) else 0.0
    arrays = dict(traces=np.array([free.k_trace, free.m_trace]), complete_to=np.array(complete))
    for name, A in (("k", free.k), ("m", free.m)):
        arrays.update({f"{name}_data": A.data, f"{name}_indices": A.indices, f"{name}_indptr": A.indptr})
    path = _record_path(stem)
    try:
        _save_atomic(path, arrays)
    except OSError:
        pass
    return path


def _same_up_to_scale(a: sp.csr_matrix, z, name: str) -> bool:
    """Whether the normalised matrix `a` equals the record's (`z`, `name`) within SCALE_TOL."""
    b = sp.csr_matrix((z[f"{name}_data"], z[f"{name}_indices"], z[f"{name}_indptr"]), shape=a.shape)
    scale = float(abs(b).max()) if b.nnz else 0.0
    return scale > 0 and float(abs(a - b).max()) <= SCALE_TOL * scale


def scaled_modes(model: SolidModel, prefix: str, free: _ScaleFree, wanted, mmap: bool) -> Modes | None:
    """The modes of `model` from a cached set (`prefix`: "modes" or "modes-below") of a solid with
    K0 = K / a and M0 = M / b, or None. a and b are the ratios of the traces; omega = sqrt(a / b)
    omega0 and the shapes phi0 / sqrt(b), which stay memory-mapped (`ScaledShapes`) when `mmap`.
    A set of modes below a cut-off serves when it reaches the wanted cut-off (in its own
    frequencies) or holds the wanted count below it. Nothing new is written."""
    w_cut, top = wanted
    for record in sorted(cache_dir().glob(f"{prefix}-{model.kind}-{model.ndof}-*.scale.npz")):
        stem = record.with_name(record.name.removesuffix(".scale.npz"))
        omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
        try:
            with np.load(record) as z:
                if not (_same_up_to_scale(free.k, z, "k") and _same_up_to_scale(free.m, z, "m")):
                    continue
                k_trace, m_trace = (float(t) for t in z["traces"])
                complete = float(z["complete_to"])
            omega0 = np.load(omega_path)
            shapes0 = np.load(shapes_path, mmap_mode="r" if mmap else None)
        except (OSError, ValueError, KeyError):
            continue  # a damaged or half-removed entry: not a base
        if shapes0.shape != (model.ndof, len(omega0)) or not (k_trace > 0 and m_trace > 0):
            continue
        a, b = free.k_trace / k_trace, free.m_trace / m_trace
        c = np.sqrt(a / b)
        w0 = w_cut / c  # the wanted cut-off in the base's frequencies
        if w0 <= complete:
            n = int(np.count_nonzero(omega0 <= w0))
            n = n if top is None else min(n, top)
        elif top is not None and np.count_nonzero(omega0 <= complete) >= top:
            n = top
        else:
            continue  # the base stops short of the wanted cut-off
        _touch(omega_path, shapes_path, record)
        omega = omega0[:n] * c
        factor = 1.0 / np.sqrt(b)
        part = shapes0 if n == shapes0.shape[1] else shapes0[:, :n]
        if factor == 1.0:
            shapes = part
        elif mmap:
            shapes = ScaledShapes(part, factor)
        else:
            shapes = np.asarray(part) * factor
        return Modes(omega, shapes, "scaled")
    return None


class ScaledShapes(np.lib.mixins.NDArrayOperatorsMixin):
    """A (memory-mapped) matrix of mode shapes times a scalar, the product taken on what is read:
    `shapes[rows]`, `shapes[:, :n]` read only those entries; `np.asarray(shapes)` and products
    read it all. Stands in for the mass-normalised shapes of a solid proportional to a cached one."""

    def __init__(self, base, factor: float):
        self.base, self.factor = base, float(factor)

    shape = property(lambda self: self.base.shape)
    ndim = property(lambda self: self.base.ndim)
    size = property(lambda self: self.base.size)
    dtype = property(lambda self: self.base.dtype)
    nbytes = property(lambda self: self.base.nbytes)

    def __len__(self) -> int:
        return len(self.base)

    def __repr__(self) -> str:
        return f"ScaledShapes(shape={self.shape}, factor={self.factor:.17g})"

    def __getitem__(self, index):
        return np.asarray(self.base[index]) * self.factor

    def __array__(self, dtype=None, copy=None):
        out = np.asarray(self.base) * self.factor
        return out if dtype is None else out.astype(dtype, copy=False)

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if any(isinstance(x, ScaledShapes) for x in kwargs.get("out", ())):
            return NotImplemented
        inputs = tuple(np.asarray(x) if isinstance(x, ScaledShapes) else x for x in inputs)
        return getattr(ufunc, method)(*inputs, **kwargs)

    def __matmul__(self, other):
        return (self.base @ other) * self.factor

    def __rmatmul__(self, other):
        return (other @ self.base) * self.factor

    @property
    def T(self) -> np.ndarray:
        return np.asarray(self).T

    def copy(self) -> np.ndarray:
        return np.asarray(self)

    def astype(self, dtype, copy=True) -> np.ndarray:
        return np.asarray(self).astype(dtype)


def _save_atomic(path, array) -> None:
    """np.save `array` (np.savez for a dict of arrays) to `path` through a temporary file."""
    import os

    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            if isinstance(array, dict):
                np.savez(fh, **array)
            else:
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
