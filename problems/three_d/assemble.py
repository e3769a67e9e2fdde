"""Assembly of 3D linear elasticity on P1 tetrahedra, vectorised with numpy, straight into CSC.

* Stiffness: a(u, v) = int lam div u div v + 2 mu eps(u) : eps(v). P1 strains are constant per
  tetrahedron, so one quadrature point is exact: the 3 x 3 block of node pair (i, j) is
  vol (lam g_i g_j' + mu g_j g_i' + mu (g_i . g_j) I) with g_i the gradient of node i's hat
  function. Unknown 3 i + c is component c of node i before the supports (scikit-fem's
  ``ElementVector(ElementTetP1())`` numbering); ``node_dofs[c, i]`` gives the kept unknowns (-1:
  fixed), numbered in (node, component) order.
* Into compressed form without scipy's COO conversion: the node pairs i < j of all tetrahedra (6
  per tetrahedron) are sorted once (:func:`node_pattern`), each of the 9 block components summed
  onto them (and the diagonal blocks onto the nodes) with ``np.bincount``, the 3 x 3 blocks turned
  into CSR by scipy's BSR conversion (canonical: sorted, no duplicates) with each block row laid out
  as [transposed lower blocks, diagonal, upper blocks], and the fixed unknowns dropped. K is
  symmetric: its CSR arrays are its CSC arrays.
* Interface term: sum_j coef_j |u_j^+ - u_j^-|^2 (all three components), B row j = nu_j . (u_j^+ - u_j^-):
  :func:`dualfem.problems._interface.interface` (shared with 2D).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.numerics.p1 import tet_gradients

from .._interface import interface  # noqa: F401  (the interface term and B: one code for 2D and 3D)
from .._pattern import distinct_pairs


def gradients(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (4, 3, nt) of the four P1 hat functions of each tetrahedron, and the volumes (nt,)
    (:func:`dualfem.numerics.p1.tet_gradients`). ``t`` must be positively oriented (the mesh module orders
    every tetrahedron so)."""
    return tet_gradients(p, t)


def node_pattern(a: np.ndarray, b: np.ndarray, nn: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct node pairs (a, b) (arrays of one shape, node ids < nn), sorted: (rows, cols) in
    row-major order and, for each entry of ``a.ravel()``, the index of its pair. One argsort of int64 keys."""
    return distinct_pairs(a.astype(np.int64).ravel() * nn + b.ravel(), nn)


_PAIRS = np.triu_indices(4, 1)          # the 6 corner pairs a < b of a tetrahedron


def stiffness(p: np.ndarray, t: np.ndarray, lam: float, mu: float, node_dofs: np.ndarray, n: int) -> sp.csc_matrix:
    """The P1 elasticity stiffness on the unknowns ``node_dofs`` (3, nn), in canonical CSC (n x n).

    Symmetry halves the work: each tetrahedron's corners are sorted by node id, its 6 off-diagonal
    blocks (i < j) summed onto the distinct pairs (one argsort of 6 nt keys) and its 4 diagonal
    blocks onto the nodes (no sort); the symmetric block matrix is laid out directly (:func:`_symmetric`),
    after dropping the nodes whose every component is fixed (the usual clamp), and single fixed
    components are masked out (:func:`_restrict`)."""
    nn = p.shape[1]
    g, vol = gradients(p, t)
    g *= np.sqrt(vol)
    o = np.argsort(t, axis=0)
    ts = np.take_along_axis(t, o, 0).astype(np.int64)
    g = np.take_along_axis(g, o[:, None, :], 0)
    ia, ib = _PAIRS
    rows, cols, pos = node_pattern(ts[ia], ts[ib], nn)
    ga, gb = g[ia], g[ib]                                            # (6, 3, nt)
    dot = mu * np.einsum("pkt,pkt->pt", ga, gb)
    dd = mu * np.einsum("pkt,pkt->pt", g, g)
    node = ts.ravel()
    V, Vd = np.empty((rows.size, 3, 3)), np.empty((nn, 3, 3))
    for r in range(3):
        for c in range(3):          # lam g_i[r] g_j[c] + mu g_i[c] g_j[r] (+ mu g_i . g_j on the diagonal)
            w = lam * ga[:, r] * gb[:, c] + mu * ga[:, c] * gb[:, r]
            wd = (lam + mu) * g[:, r] * g[:, c]
            if r == c:
                w += dot
                wd += dd
            V[:, r, c] = np.bincount(pos, weights=w.ravel(), minlength=rows.size)
            Vd[:, r, c] = np.bincount(node, weights=wd.ravel(), minlength=nn)
    del pos, ga, gb, dot, dd
    nd = np.asarray(node_dofs, dtype=np.int64)
    whole = (nd >= 0).all(axis=0) | (nd < 0).all(axis=0)
    if whole.all() and not (nd >= 0).all():          # supports fix whole nodes: drop them at block level
        free = (nd >= 0).all(axis=0)
        keep = free[rows] & free[cols]
        rank = np.cumsum(free) - 1
        rows, cols, V, Vd = rank[rows[keep]], rank[cols[keep]], V[keep], Vd[free]
        nn = int(free.sum())
        nd = np.arange(3 * nn).reshape(nn, 3).T
    return _restrict(_symmetric(rows, cols, V, Vd, nn), nd, n)


def _symmetric(rows: np.ndarray, cols: np.ndarray, V: np.ndarray, Vd: np.ndarray, nn: int) -> sp.csr_matrix:
    """The symmetric 3 nn x 3 nn CSR matrix (canonical) with blocks V[s] at node pair (rows[s], cols[s])
    (rows < cols, row-major sorted), their transposes at (cols[s], rows[s]) and Vd[i] at (i, i): every
    block row is [lower blocks, diagonal, upper blocks], already sorted by column (the lower ones by a
    counting sort on their column, through scipy's CSR -> CSC), then scipy's BSR -> CSR."""
    nU = np.bincount(rows, minlength=nn)
    nL = np.bincount(cols, minlength=nn)
    ptr = np.zeros(nn + 1, np.int64)
    np.cumsum(nL + 1 + nU, out=ptr[1:])
    k = np.arange(rows.size)
    # lower blocks: the pairs ordered by (col, row)
    startU = np.r_[0, np.cumsum(nU)[:-1]]
    startL = np.r_[0, np.cumsum(nL)[:-1]]
    oL = sp.csr_matrix((k + 1, cols, np.r_[0, np.cumsum(nU)]), shape=(nn, nn)).tocsc().data - 1
    cL = cols[oL]
    posL = ptr[cL] + (k - startL[cL])
    posU = ptr[rows] + nL[rows] + 1 + (k - startU[rows])
    posD = ptr[:-1] + nL
    B = np.empty((int(ptr[-1]), 3, 3))
    bcol = np.empty(int(ptr[-1]), np.int64)
    B[posL] = V[oL].transpose(0, 2, 1)
    bcol[posL] = rows[oL]
    B[posU] = V
    bcol[posU] = cols
    B[posD] = Vd
    bcol[posD] = np.arange(nn)
    A = sp.bsr_matrix((B, bcol, ptr), shape=(3 * nn, 3 * nn)).tocsr()
    A.has_sorted_indices = True
    return A


def _restrict(A: sp.csr_matrix, node_dofs: np.ndarray, n: int) -> sp.csc_matrix:
    """Rows and columns of the unknowns kept by ``node_dofs`` (symmetric A), canonical CSC."""
    new = np.asarray(node_dofs, dtype=np.int64).T.ravel()            # unknown 3 i + c -> its index, -1 dropped
    keep = new >= 0
    if not np.array_equal(new[keep], np.arange(n)):                  # another numbering: scipy sorts it out
        C = A.tocoo()
        k = keep[C.row] & keep[C.col]
        return sp.csc_matrix((C.data[k], (new[C.row[k]], new[C.col[k]])), shape=(n, n))
    if keep.all():
        data, indices, indptr = A.data, A.indices, A.indptr
    else:
        per_row = np.diff(A.indptr)
        ek = np.repeat(keep, per_row) & keep[A.indices]
        data, indices = A.data[ek], new[A.indices[ek]]
        kept_per_row = np.add.reduceat(ek.astype(np.int64), A.indptr[:-1]) if ek.size else np.zeros(keep.size, int)
        indptr = np.r_[0, np.cumsum(kept_per_row[keep])]
    idx = np.int32 if max(data.size, n) < 2 ** 31 else np.int64
    K = sp.csc_matrix((data, indices.astype(idx, copy=False), indptr.astype(idx, copy=False)), shape=(n, n))
    K.has_sorted_indices = True
    K.has_canonical_format = True
    return K


def free_dofs(fixed: np.ndarray) -> np.ndarray:
    """node_dofs (3, nn) from a mask ``fixed`` (3, nn) of fixed components: kept ones numbered in
    (node, component) order, -1 for fixed."""
    free = ~np.asarray(fixed, bool).T.ravel()
    idx = np.cumsum(free) - 1
    return np.where(free, idx, -1).reshape(-1, 3).T.copy()


def boundary_faces(t: np.ndarray) -> np.ndarray:
    """Faces (3, k) of the tetrahedra that belong to one tetrahedron only (the boundary), node ids sorted.

    Faces of defect triangles are shared by two tetrahedra before the cut and by one after it: call this on
    the uncut mesh, or filter by position."""
    nn = int(t.max()) + 1
    F = np.sort(t[[[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].transpose(0, 2, 1).reshape(-1, 3).astype(np.int64),
                axis=1)
    key = (F[:, 0] * nn + F[:, 1]) * nn + F[:, 2]
    _, idx, cnt = np.unique(key, return_index=True, return_counts=True)
    return F[idx[cnt == 1]].T
