"""The mirror split of the modal analysis (solid.symmetry): a plate symmetric about its
mid-height has the same modes solved as two halves as solved whole."""

import numpy as np
import pytest
import scipy.linalg as sl

from granel.solid.base import Material, Slab
from granel.solid.beam import build_beam
from granel.solid.plate import LayerSpec, PlateMesh, assemble_plate
from granel.solid.symmetry import mirror_operator, split_eigh, symmetric_bases

MESH = PlateMesh(2, 2.5, 8e-3)  # a coarse plate: a few hundred DOFs
EPS = np.finfo(float).eps


def eigen_bounds(K, M, phi, w2):
    """For each computed pair (w2, phi) of K phi = w2 M phi, the distance within which an exact
    eigenvalue lies: the residual's M^-1 norm (Bauer-Fike for a definite pencil, phi
    M-normalised), plus that residual's own rounding (terms per row) eps (|K| + w2 |M|) |phi|."""
    cf = sl.cho_factor(M)
    terms = max(np.count_nonzero(K, axis=1).max(), np.count_nonzero(M, axis=1).max())

    def norm(r):
        return np.sqrt(np.abs(np.einsum("ij,ij->j", r, sl.cho_solve(cf, r))))

    rounding = terms * EPS * (np.abs(K) @ np.abs(phi) + (np.abs(M) @ np.abs(phi)) * w2)
    return norm(K @ phi - (M @ phi) * w2) + norm(rounding)


def plate(layers):
    return assemble_plate(Slab(0.0, 0.0, 0.01, 0.1, 0.001), Material(200e9, 7850.0, 0.3), layers, MESH)


SYMMETRIC = [LayerSpec("a", "left", 0.05, 0.001), LayerSpec("b", "left", 0.03, 0.001), LayerSpec("c", "left", 0.07, 0.001),
             LayerSpec("d", "right", 0.02, 0.0008), LayerSpec("e", "right", 0.08, 0.0008)]


def test_mirror_operator_is_the_reflection():
    m = plate(SYMMETRIC)
    S = mirror_operator(m)
    assert S is not None
    n = m.ndof
    assert abs(S @ S - np.eye(n)).max() == 0  # an involution: a signed permutation, exact
    # mirrored elements differ by their nodes' rounding, an ulp of y (0.1) against the smallest
    # spacing, which the element matrices feel through the Jacobian and the shape derivatives (a
    # few factors of it), plus their quadrature's rounding (measured 8e-15 of |K|, 2e-15 of |M|)
    y = m.nodes[:, 1]
    spacing = np.diff(np.unique(y)).min()
    tol = 4 * EPS * np.abs(y).max() / spacing + 64 * EPS
    for A in (m.K, m.M):
        assert abs(S @ A @ S.T - A).max() <= tol * abs(A).max()
    # a displacement field reflected node by node: u_x(x, 2yc - y) = u_x, u_y -> -u_y
    rng = np.random.default_rng(0)
    q = rng.normal(size=n)
    full, mirrored = m.full_displacement(q), m.full_displacement(S @ q)
    yc = 0.05
    nodes = m.nodes
    for i in rng.choice(len(nodes), 20, replace=False):
        k = int(np.argmin(np.hypot(nodes[:, 0] - nodes[i, 0], nodes[:, 1] - (2 * yc - nodes[i, 1]))))
        # a rigid layer's node combines three DOFs: a few roundings (measured exact)
        assert mirrored[k] == pytest.approx([full[i, 0], -full[i, 1]], abs=4 * EPS * np.abs(full).max())
    Qs, Qa = symmetric_bases(S)
    assert Qs.shape[1] + Qa.shape[1] == n
    Q = np.hstack([Qs.toarray(), Qa.toarray()])
    assert abs(Q.T @ Q - np.eye(n)).max() <= 4 * EPS  # columns of 1 and 1/sqrt(2) entries: two roundings


def test_split_modes_equal_the_whole_solve():
    """The halves' modes against one dense solve of the whole: each eigenvalue within the two
    solves' residual bounds (measured at most 0.09 of them; mode 1 1.8e-11 off, 4.1e-11 with
    Prescott's kernels, against 1.4e-9; eps (w_max / w)^2 alone would not hold: the high modes
    are 36 eps off), shapes M-orthonormal and backward stable, and each mode that the
    eigenproblem pins down the same up to sign (measured at most 0.27 of its bound)."""
    m = plate(SYMMETRIC)
    S = mirror_operator(m)
    w2s, phis = split_eigh(m.K, m.M, S)
    M, K, n = m.M.toarray(), m.K.toarray(), m.ndof
    w2, phi = sl.eigh(K, M)
    bs, b0 = eigen_bounds(K, M, phis, w2s), eigen_bounds(K, M, phi, w2)
    assert np.all(np.abs(w2s - w2) <= bs + b0)
    # the Cholesky reduction's rounding, n eps kappa of the unit-diagonal M (measured 1e-14 against 3e-12)
    d = 1 / np.sqrt(np.diag(M))
    orth = np.abs(phis.T @ M @ phis - np.eye(n)).max()
    assert orth < n * EPS * np.linalg.cond(d[:, None] * M * d[None, :])
    # LAPACK's backward error, n eps (|K| + w2 |M|) |phi| (measured 4e-3 of it)
    r = np.linalg.norm(K @ phis - M @ phis * w2s, axis=0)
    assert np.all(r <= n * EPS * (np.linalg.norm(K, 2) + w2s * np.linalg.norm(M, 2)) * np.linalg.norm(phis, axis=0))
    # each split mode is a whole-solve mode up to sign where its gap to the others exceeds both
    # bounds: the angle between the two is then below (bs + b0) / (gap - bs - b0) (Davis-Kahan),
    # 1 - cos below half its square, besides the two shapes' normalisation errors
    gap = np.minimum(np.r_[np.inf, np.diff(w2)], np.r_[np.diff(w2), np.inf])
    single = gap > 2 * (bs + b0)
    assert single.sum() > 0.9 * n
    orth0 = np.abs(phi.T @ M @ phi - np.eye(n)).max()
    overlap = np.abs(np.einsum("ij,ij->j", phis, M @ phi))
    tol = 0.5 * ((bs + b0) / (gap - bs - b0)) ** 2 + orth + orth0
    assert np.all(np.abs(overlap - 1)[single] <= tol[single])


def test_no_split_without_symmetry():
    assert mirror_operator(plate(SYMMETRIC[:-1])) is None  # one layer without its image
    assert mirror_operator(build_beam(Slab(0, 0, 0.01, 0.1, 0.001), Material(200e9, 7850, 0.3), [("c", "left", 0.05)], 20)) is None


def test_modal_analysis_uses_the_split():
    from granel.solid.modal import modal_analysis

    m = plate(SYMMETRIC)
    modes = modal_analysis(m)
    K, M = m.K.toarray(), m.M.toarray()
    w2, phi = sl.eigh(K, M)
    # within the two solves' residual bounds (`eigen_bounds`), as in the split's own test
    bound = eigen_bounds(K, M, np.asarray(modes.shapes), modes.omega**2) + eigen_bounds(K, M, phi, w2)
    assert np.all(np.abs(modes.omega**2 - w2) <= bound)
    few = modal_analysis(m, m.ndof // 2)
    assert np.array_equal(few.omega, modes.omega[: m.ndof // 2])  # the same split solve, cut


@pytest.mark.parametrize("layers", [SYMMETRIC, SYMMETRIC[:-1]], ids=["halves", "whole"])
def test_modes_up_to_a_cut_off_are_the_dense_solve_s(layers):
    """modal.modes_up_to (shift-invert Lanczos, on the halves when the plate is symmetric, the
    count raised past the cut-off) against one dense solve of the whole: the same modes below a
    cut-off set midway between two eigenvalues, more than the first Lanczos count (48) so that
    the count is raised, each eigenvalue within the two solves' residual bounds
    (`eigen_bounds`), each well-separated shape the dense one up to sign (Davis-Kahan, as in
    test_split_modes_equal_the_whole_solve)."""
    from granel.solid.modal import modes_up_to

    m = plate(layers)
    K, M = m.K.toarray(), m.M.toarray()
    w2, phi = sl.eigh(K, M)
    n = 130  # beyond 48 in each half of the symmetric plate too
    w_cut = np.sqrt(0.5 * (w2[n - 1] + w2[n]))
    modes = modes_up_to(m, w_cut, m.ndof - 1)
    assert modes.count == n
    shapes, w2k = np.asarray(modes.shapes), modes.omega**2
    bound = eigen_bounds(K, M, shapes, w2k) + eigen_bounds(K, M, phi[:, :n], w2[:n])
    assert np.all(np.abs(w2k - w2[:n]) <= bound)
    gap = np.minimum(np.r_[np.inf, np.diff(w2)], np.r_[np.diff(w2), np.inf])[:n]
    single = gap > 2 * bound
    assert single.sum() > 0.9 * n
    overlap = np.abs(np.einsum("ij,ij->j", shapes, M @ phi[:, :n]))
    orth = np.abs(shapes.T @ M @ shapes - np.eye(n)).max()
    orth0 = np.abs(phi.T @ M @ phi - np.eye(m.ndof)).max()
    tol = 0.5 * (bound / (gap - bound)) ** 2 + orth + orth0
    assert np.all(np.abs(overlap - 1)[single] <= tol[single])
    few = modes_up_to(m, w_cut, 40)  # at most `top`: the lowest
    assert few.count == 40
    bound = eigen_bounds(K, M, np.asarray(few.shapes), few.omega**2) + eigen_bounds(K, M, phi[:, :40], w2[:40])
    assert np.all(np.abs(few.omega**2 - w2[:40]) <= bound)
