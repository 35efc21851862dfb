"""The modes of a solid proportional to a cached one (another thickness, modulus or density): its
K and M are checked against each cached set's scale-free record, and that set's modes come back
scaled (`scaled_modes`), the shapes memory-mapped when asked (`ScaledShapes`)."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .base import SolidModel
from .cache_files import cache_dir, discard, touch, verify, write_checked
from .modal import Modes


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
    """Store the scale-free record of the modes at `stem` (a checked cache file): the normalised
    matrices, their traces and how far the set is complete (`complete_to` [rad/s]: every mode up
    to it is in the set; infinite for all modes). Raises OSError when it cannot be written."""
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
    return write_checked(_record_path(stem), arrays)


def _same_up_to_scale(a: sp.csr_matrix, z, name: str) -> bool:
    """Whether the normalised matrix `a` equals the record's (`z`, `name`) within SCALE_TOL."""
    b = sp.csr_matrix((z[f"{name}_data"], z[f"{name}_indices"], z[f"{name}_indptr"]), shape=a.shape)
    scale = float(abs(b).max()) if b.nnz else 0.0
    return scale > 0 and float(abs(a - b).max()) <= SCALE_TOL * scale


def scaled_modes(model: SolidModel, prefix: str, free: _ScaleFree, wanted, mmap: bool, exclude: Path | None = None
                 ) -> Modes | None:
    """The modes of `model` from a cached set (`prefix`: "modes" or "modes-below") of a solid with
    K0 = K / a and M0 = M / b, or None. a and b are the ratios of the traces; omega = sqrt(a / b)
    omega0 and the shapes phi0 / sqrt(b), which stay memory-mapped (`ScaledShapes`) when `mmap`.
    A set of modes below a cut-off serves when it reaches the wanted cut-off (in its own
    frequencies) or holds the wanted count below it. Only checked files serve (`verify`); a
    damaged set is removed. `exclude`: the stem of the solid's own entry, not a base. Nothing new
    is written."""
    w_cut, top = wanted
    for record in sorted(cache_dir().glob(f"{prefix}-{model.kind}-{model.ndof}-*.scale.npz")):
        stem = record.with_name(record.name.removesuffix(".scale.npz"))
        omega_path, shapes_path = stem.with_suffix(".omega.npy"), stem.with_suffix(".shapes.npy")
        if stem == exclude or not (omega_path.exists() and shapes_path.exists()):
            continue  # a half-pruned entry: not a base
        files = [omega_path, shapes_path, record]
        damage = verify(record)  # the small record first: the shapes are read only for a match
        if damage:  # never a base; removed unless its lock says it is being written
            discard(files, damage, busy=stem.with_suffix(".lock"))
            continue
        try:
            with np.load(record) as z:
                if not (_same_up_to_scale(free.k, z, "k") and _same_up_to_scale(free.m, z, "m")):
                    continue
                k_trace, m_trace = (float(t) for t in z["traces"])
                complete = float(z["complete_to"])
            damage = verify(omega_path) or verify(shapes_path)
            if damage:
                discard(files, damage, busy=stem.with_suffix(".lock"))
                continue
            omega0 = np.load(omega_path)
            shapes0 = np.load(shapes_path, mmap_mode="r" if mmap else None)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            continue  # removed meanwhile, or unreadable though it matches its record: not a base
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
        touch(omega_path, shapes_path, record)
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
