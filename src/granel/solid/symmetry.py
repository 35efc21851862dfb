"""A solid's mirror symmetry about its mid-height y = y_c, which splits its modal analysis in two:
the reflection is a signed permutation S of the DOFs (S' K S = K, S' M S = M), and the modes
symmetric and antisymmetric under S each solve (Q' K Q) z = w^2 (Q' M Q) z, phi = Q z, on an
orthonormal basis Q_s or Q_a, so the shapes stay mass-normalised (`modal.modal_analysis`). A
solid without S (read from the mesh, checked on K and M to round-off) is solved whole.
docs/solids.md ("Modal analysis") explains it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

# nodes match their mirror image within this share of the solid's size, and S' K S equals K (and
# M) within this share of the largest entry
GEOMETRY_TOL = 1e-9
MATRIX_TOL = 1e-11


def mirror_operator(model) -> sp.csr_matrix | None:
    """S, the reflection about the solid's mid-height on its (reduced) DOFs, or None if the
    solid is not symmetric (or carries no mesh: beams and rigid solids). The reduced DOFs are
    x = T q; the reflection of the full DOFs (u_x kept, u_y flipped, node to mirror node) is
    carried to q by T's left inverse, and must come out a signed permutation."""
    nodes, node_dofs = getattr(model, "nodes", None), getattr(model, "node_dofs", None)
    if nodes is None or node_dofs is None or len(node_dofs) != 2:  # a planar mesh's u_x and u_y
        return None
    nodes = np.asarray(nodes, float)
    size = float(np.ptp(nodes, axis=0).max())
    yc = 0.5 * (nodes[:, 1].min() + nodes[:, 1].max())
    image = _mirror_nodes(nodes, yc, GEOMETRY_TOL * size)
    if image is None:
        return None
    dx, dy = np.asarray(node_dofs[0]), np.asarray(node_dofs[1])
    nfull = int(max(dx.max(), dy.max())) + 1
    rows = np.concatenate([dx[image], dy[image]])
    cols = np.concatenate([dx, dy])
    vals = np.concatenate([np.ones(len(dx)), -np.ones(len(dy))])
    Sf = sp.csr_matrix((vals, (rows, cols)), shape=(nfull, nfull))
    T = getattr(model, "T", None)
    if T is None:
        S = Sf
    else:
        S = _left_solve(sp.csc_matrix(T.T @ T), sp.csc_matrix(T.T @ (Sf @ T)))
    if not _signed_permutation(S):
        return None
    S.data = np.sign(S.data)
    for A in (model.K, model.M):
        A = sp.csr_matrix(A)
        scale = abs(A).max()
        if abs(S @ A @ S.T - A).max() > MATRIX_TOL * scale:
            return None
    return S


def _left_solve(A: sp.csc_matrix, B: sp.csc_matrix) -> sp.csr_matrix:
    """A^-1 B, entries below 1e-9 dropped, for a block-diagonal A (T' T: a free node's DOFs
    alone, a rigid layer's few together): each block inverted on its own."""
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(A, directed=False)
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(count + 1))
    A = sp.csr_matrix(A)
    size = np.diff(starts)
    alone = order[starts[:-1][size == 1]]  # a DOF of its own: its diagonal's inverse
    rows, cols, vals = [alone], [alone], [1.0 / A.diagonal()[alone]]
    for k in np.flatnonzero(size > 1):
        idx = order[starts[k]:starts[k + 1]]
        inv = np.linalg.inv(A[idx][:, idx].toarray())
        r, c = np.meshgrid(idx, idx, indexing="ij")
        rows.append(r.ravel())
        cols.append(c.ravel())
        vals.append(np.ravel(inv))
    Ainv = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=A.shape)
    S = sp.csr_matrix(Ainv @ B)
    S.data[np.abs(S.data) < 1e-9] = 0.0
    S.eliminate_zeros()
    return S


def _mirror_nodes(nodes: np.ndarray, yc: float, tol: float) -> np.ndarray | None:
    """image[i]: the node at node i's mirror position, or None if one is missing."""
    from scipy.spatial import cKDTree

    mirrored = nodes.copy()
    mirrored[:, 1] = 2.0 * yc - nodes[:, 1]
    dist, image = cKDTree(nodes).query(mirrored)
    if dist.max() > tol or len(np.unique(image)) != len(image):
        return None
    return image


def _signed_permutation(S: sp.csr_matrix) -> bool:
    n = S.shape[0]
    if S.shape != (n, n) or S.nnz != n:
        return False
    ok_rows = np.all(np.diff(S.indptr) == 1)
    ok_cols = len(np.unique(S.indices)) == n
    return bool(ok_rows and ok_cols and np.allclose(np.abs(S.data), 1.0, atol=1e-9))


def symmetric_bases(S: sp.csr_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """Orthonormal bases (Q_s, Q_a) of the DOFs symmetric and antisymmetric under S."""
    Sc = sp.csc_matrix(S)
    Sc.sort_indices()
    n = Sc.shape[0]
    land, sign = Sc.indices, Sc.data  # column i's one entry: S e_i = sign[i] e_land[i]
    sym, anti = [], []  # (dof, its image, the sign of the combination)
    for i in range(n):
        j = int(land[i])
        if j < i:
            continue
        sym.append((i, j, sign[i]))
        anti.append((i, j, -sign[i]))
    return _basis(sym, n), _basis(anti, n)


def _basis(pairs, n: int) -> sp.csc_matrix:
    rows, cols, vals = [], [], []
    k = 0
    for i, j, s in pairs:
        if i == j:
            if s > 0:  # a DOF its own image with this sign belongs here
                rows.append(i)
                cols.append(k)
                vals.append(1.0)
                k += 1
            continue
        rows += [i, j]
        cols += [k, k]
        vals += [1.0 / np.sqrt(2.0), s / np.sqrt(2.0)]
        k += 1
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, k))


def split_eigh(K, M, S) -> tuple[np.ndarray, np.ndarray]:
    """(w^2 ascending, mass-normalised shapes) of K phi = w^2 M phi, solved on the symmetric and
    antisymmetric halves under S (`mirror_operator`) and merged."""
    import scipy.linalg as sl

    w2s, shapes = [], []
    for Q in symmetric_bases(S):
        if Q.shape[1] == 0:
            continue
        Kq = (Q.T @ (K @ Q)).toarray()
        Mq = (Q.T @ (M @ Q)).toarray()
        w2, z = sl.eigh(Kq, Mq, check_finite=False)
        w2s.append(w2)
        shapes.append(np.asarray(Q @ z))
    w2 = np.concatenate(w2s)
    order = np.argsort(w2, kind="stable")
    return w2[order], np.ascontiguousarray(np.hstack(shapes)[:, order])
