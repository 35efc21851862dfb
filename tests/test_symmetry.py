"""The mirror split of the modal analysis (solid.symmetry): a plate symmetric about its
mid-height has the same modes solved as two halves as solved whole."""

import numpy as np
import pytest
import scipy.linalg as sl

from granel.solid.beam import build_beam
from granel.solid.plate import LayerSpec, PlateMesh, assemble_plate
from granel.solid.symmetry import mirror_operator, split_eigh, symmetric_bases

MESH = PlateMesh(2, 2.5, 8e-3)  # a coarse plate: a few hundred DOFs


def plate(layers):
    return assemble_plate(0.0, 0.0, 0.01, 0.1, 0.001, 200e9, 0.3, 7850.0, layers, MESH)


SYMMETRIC = [LayerSpec("a", "left", 0.05, 0.001), LayerSpec("b", "left", 0.03, 0.001), LayerSpec("c", "left", 0.07, 0.001),
             LayerSpec("d", "right", 0.02, 0.0008), LayerSpec("e", "right", 0.08, 0.0008)]


def test_mirror_operator_is_the_reflection():
    m = plate(SYMMETRIC)
    S = mirror_operator(m)
    assert S is not None
    n = m.ndof
    assert abs(S @ S - np.eye(n)).max() < 1e-14  # an involution
    for A in (m.K, m.M):
        assert abs(S @ A @ S.T - A).max() <= 1e-11 * abs(A).max()
    # a displacement field reflected node by node: u_x(x, 2yc - y) = u_x, u_y -> -u_y
    rng = np.random.default_rng(0)
    q = rng.normal(size=n)
    full, mirrored = m.full_displacement(q), m.full_displacement(S @ q)
    yc = 0.05
    nodes = m.nodes
    for i in rng.choice(len(nodes), 20, replace=False):
        k = int(np.argmin(np.hypot(nodes[:, 0] - nodes[i, 0], nodes[:, 1] - (2 * yc - nodes[i, 1]))))
        assert mirrored[k] == pytest.approx([full[i, 0], -full[i, 1]], abs=1e-12)
    Qs, Qa = symmetric_bases(S)
    assert Qs.shape[1] + Qa.shape[1] == n
    Q = np.hstack([Qs.toarray(), Qa.toarray()])
    assert abs(Q.T @ Q - np.eye(n)).max() < 1e-14


def test_split_modes_equal_the_whole_solve():
    m = plate(SYMMETRIC)
    S = mirror_operator(m)
    w2s, phis = split_eigh(m.K, m.M, S)
    w2, phi = sl.eigh(m.K.toarray(), m.M.toarray())
    assert np.abs(w2s / w2 - 1).max() < 1e-10
    M = m.M.toarray()
    assert np.abs(phis.T @ M @ phis - np.eye(m.ndof)).max() < 1e-10
    K = m.K.toarray()
    assert np.abs(K @ phis - M @ phis * w2s).max() < 1e-8 * np.abs(K).max() * np.abs(phis).max()
    # each split mode is a whole-solve mode up to sign, where the frequency is not repeated
    gap = np.minimum(np.r_[np.inf, np.diff(w2)], np.r_[np.diff(w2), np.inf]) / w2
    single = gap > 1e-6
    overlap = np.abs(np.einsum("ij,ij->j", phis, M @ phi))
    assert overlap[single] == pytest.approx(1.0, abs=1e-7)


def test_no_split_without_symmetry():
    assert mirror_operator(plate(SYMMETRIC[:-1])) is None  # one layer without its image
    assert mirror_operator(build_beam(0, 0, 0.01, 0.1, 0.001, 200e9, 7850, [("c", "left", 0.05)], 20)) is None


def test_modal_analysis_uses_the_split():
    from granel.solid.modal import modal_analysis

    m = plate(SYMMETRIC)
    modes = modal_analysis(m)
    w2, _ = sl.eigh(m.K.toarray(), m.M.toarray())
    assert np.abs(modes.omega[3:] ** 2 / w2[3:] - 1).max() < 1e-10
    few = modal_analysis(m, m.ndof // 2)
    assert few.omega == pytest.approx(modes.omega[: m.ndof // 2], rel=1e-12)
