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

import numpy as np

from ..guard.jit import njit
from .base import SolidModel
from .kinds import kind_of


@njit(cache=True, inline="always")
def mode_energy(eta, etad, omega):
    """Eq. (15): the kinetic 1/2 eta'^2 and strain 1/2 omega^2 eta^2 energies of a mode in
    mass-normalised coordinates (elementwise on arrays through `.py_func`)."""
    return 0.5 * etad * etad, 0.5 * omega**2 * eta * eta


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


def modes_up_to(model: SolidModel, w_cut: float, top: int) -> Modes:
    """The modes with omega <= w_cut [rad/s] (at most `top`, the lowest), mass-normalised, by
    shift-invert Lanczos at 0 on each half of a solid symmetric about its mid-height
    (`solid.symmetry`) or on the whole; each half's count grows until its highest mode passes
    w_cut. Two halves of half the modes each cost far less than the whole: Lanczos's work grows
    faster than the count."""
    from .symmetry import mirror_operator, symmetric_bases

    S = mirror_operator(model)
    parts = [None] if S is None else [Q for Q in symmetric_bases(S) if Q.shape[1]]
    w2s, shapes = [], []
    for Q in parts:
        K, M = (model.K, model.M) if Q is None else (Q.T @ (model.K @ Q), Q.T @ (model.M @ Q))
        w2, z = _lowest_up_to(K.tocsc(), M.tocsc(), w_cut**2, top)
        w2s.append(w2)
        shapes.append(z if Q is None else np.asarray(Q @ z))
    w2 = np.concatenate(w2s)
    order = np.argsort(w2, kind="stable")
    keep = order[w2[order] <= w_cut**2][:top]
    return Modes(np.sqrt(np.maximum(w2[keep], 0.0)), np.ascontiguousarray(np.hstack(shapes)[:, keep]))


def _lowest_up_to(K, M, w2_cut: float, top: int) -> tuple[np.ndarray, np.ndarray]:
    """(w^2 ascending, M-normalised shapes) of the lowest modes of (K, M), the count raised until
    the highest passes w2_cut or `top` are found; dense below 200 DOFs."""
    n = K.shape[0]
    if n <= 200:
        import scipy.linalg as sl

        w2, z = sl.eigh(K.toarray(), M.toarray(), check_finite=False)
        return w2[:top], z[:, :top]
    from scipy.sparse.linalg import eigsh

    count = min(48, n - 1, top)
    while True:
        w2, z = eigsh(K, count, M, sigma=0.0, which="LM")
        order = np.argsort(w2)
        w2, z = w2[order], z[:, order]
        if w2[-1] > w2_cut or count >= min(n - 1, top):
            break
        # the count below a frequency grows about as f^2 in a plate (as f in a beam): aim past it
        count = int(min(n - 1, top, max(count + 16, 1.15 * count * w2_cut / max(w2[-1], 1e-300))))
    z /= np.sqrt(np.einsum("ij,ij->j", z, M @ z))[None, :]
    return w2, z


def classify_modes(model: SolidModel, modes: Modes, which=None) -> list[str]:
    """Kind of each mode (bending / axial / bulk, as the solid's kind tells them:
    `SolidKind.mode_kinds`); all beam modes are bending."""
    idx = range(modes.count) if which is None else which
    return kind_of(model).mode_kinds(model, modes.shapes, idx)


def at_dofs(B, shapes, columns=slice(None)) -> np.ndarray:
    """B @ shapes[:, columns] reading only the rows of `shapes` that B touches (B: a sparse map
    from the solid's DOFs, e.g. its contact points; `shapes` may be memory-mapped)."""
    B = B.tocsc()
    rows = np.flatnonzero(np.diff(B.indptr))
    sub = np.asarray(shapes[rows])[:, columns]
    return np.ascontiguousarray(B[:, rows] @ sub)
