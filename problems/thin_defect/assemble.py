"""Assembly of the thin-defect QP on any (cut) triangle mesh, vectorized with numpy.

* Stiffness: P1 vector elements; the strains of P1 functions are constant per triangle, so one
  quadrature point (the element integral is the area times the constant integrand) is exact.
  DOF numbering: unknown 2 i + c (component c of node i) before clamping; after clamping the
  free unknowns keep their relative order (``node_dofs[c, i]``, -1 if clamped): scikit-fem's
  ``ElementVector(ElementTriP1())`` numbering restricted to the free DOFs.
* Traction on the loaded side: 4-point Gauss-Legendre per boundary edge (exact for P1 times a
  polynomial of degree <= 6), the traction evaluated in the reference (unrotated) frame.
* Interface: (1/delta_d) sum_j w_j |u_j^+ - u_j^-|^2 (whole jump vector, trapezoid rule);
  B row j = nu_j . (u_j^+ - u_j^-): :func:`dualfem.problems._interface.interface` (shared with 3D).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._interface import interface  # noqa: F401  (the interface term and B: one code for 2D and 3D)
from .._pattern import distinct_pairs


def shape_gradients(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x- and y-derivatives (3, nt) of the three P1 basis functions, and the areas (nt,)."""
    x, y = p[0][t], p[1][t]
    twoA = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
    j, k = [1, 2, 0], [2, 0, 1]
    return (y[j] - y[k]) / twoA, (x[k] - x[j]) / twoA, 0.5 * np.abs(twoA)


def free_dofs(clamped_nodes: np.ndarray, nnodes: int) -> np.ndarray:
    """node_dofs (2, nnodes): index of component c of node i among the free unknowns, -1 if clamped."""
    free = np.ones((nnodes, 2), dtype=bool)
    free[clamped_nodes] = False
    idx = np.cumsum(free.ravel()) - 1
    return np.where(free.ravel(), idx, -1).reshape(nnodes, 2).T.copy()


def stiffness(p: np.ndarray, t: np.ndarray, lam: float, mu: float, node_dofs: np.ndarray, n: int) -> sp.csc_matrix:
    """P1 plane elasticity stiffness on the unknowns ``node_dofs`` (rows/cols with -1 dropped), CSC.

    Bilinear form lam div u div v + 2 mu eps(u) : eps(v), one-point (exact) quadrature.

    Assembled straight into canonical compressed form (sorted indices, no duplicates, no scipy COO
    conversion): the node pairs of the mesh are sorted once (:func:`node_pattern`), each 2 x 2 block
    component is summed onto them with ``np.bincount``, and the blocks are interleaved into the
    unknowns' rows (:func:`_expand`); K is symmetric, so its CSR arrays are its CSC arrays. At
    N = 512 (525 822 unknowns) 0.36 s against 0.74 s through scipy's COO -> CSC with duplicates
    (medians of 5 in one process; in a fresh process, whose every large array is fresh memory
    (page faults), 0.3-0.5 s against 0.8-2.5 s); the same matrix and pattern (to rounding; the
    structured scenes' bit for bit: tests/test_qp_frozen.py, tests/test_problem.py).
    """
    nn = p.shape[1]
    gx, gy, area = shape_gradients(p, t)
    gx *= np.sqrt(area)
    gy *= np.sqrt(area)
    rows, cols, pos = node_pattern(t, nn)
    lm = lam + 2 * mu
    buf, tmp = np.empty((3, 3, t.shape[1])), np.empty((3, 3, t.shape[1]))
    # component (r, c) of the block of node pair (i, j): 00 lm gx gx + mu gy gy, 11 lm gy gy + mu gx gx,
    # 01 lam gx_i gy_j + mu gy_i gx_j, 10 lam gy_i gx_j + mu gx_i gy_j (the transpose of 01, term by term)
    vals = tuple(tuple(_block(*terms, pos, rows.size, buf, tmp) for terms in pair)
                 for pair in (((gx, gx, lm, gy, gy, mu), (gx, gy, lam, gy, gx, mu)),
                              ((gy, gx, lam, gx, gy, mu), (gy, gy, lm, gx, gx, mu))))
    del buf, tmp, pos
    return _expand(rows, cols, vals, node_dofs, nn, n)


def _block(a1, b1, ca, a2, b2, cb, pos, npairs, buf, tmp) -> np.ndarray:
    """sum over the triangles of ca a1_i b1_j + cb a2_i b2_j (i, j: their nodes) on each node pair."""
    np.multiply(a1[:, None], b1[None], out=buf)
    buf *= ca
    np.multiply(a2[:, None], b2[None], out=tmp)
    tmp *= cb
    buf += tmp
    return np.bincount(pos, weights=buf.ravel(), minlength=npairs)


def node_pattern(t: np.ndarray, nn: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The node pairs (t[a, k], t[b, k]) of every triangle k (a, b = 0, 1, 2), sorted and distinct.

    Returns (rows, cols) of the distinct pairs in row-major order and, for each pair of the flattened
    (3, 3, nt) array, its index among them. One stable argsort of int64 keys (a merge of the nine
    sorted runs for the structured mesh, whose triangles come in node order: 0.03 s at N = 512).
    """
    keys = np.empty((3, 3, t.shape[1]), np.int64)
    keys[...] = t[:, None, :]
    keys *= nn
    keys += t[None, :, :]
    return distinct_pairs(keys.ravel(), nn, stable=True)


def _expand(rows: np.ndarray, cols: np.ndarray, vals, node_dofs: np.ndarray, nn: int, n: int) -> sp.csc_matrix:
    """The n x n matrix whose entry (node_dofs[r, i], node_dofs[c, j]) is ``vals[r][c][s]`` for node pair
    s = (rows[s], cols[s]) (row-major sorted, distinct); unknowns -1 are dropped.

    In canonical compressed form when the kept unknowns are numbered in (node, component) order, as
    :func:`free_dofs` does: scipy's block-to-CSR conversion of the 2 x 2 blocks, after dropping the
    pairs of clamped nodes (both components clamped: the usual case, no copy of the big arrays), or
    followed by one mask (some node clamped in one component only). Another numbering goes through
    scipy's COO -> CSC."""
    nd = np.asarray(node_dofs, dtype=np.int64)
    new = nd.T.ravel()                                           # unknown 2 i + c -> its index, -1 dropped
    keep_dof = new >= 0
    if not np.array_equal(new[keep_dof], np.arange(n)):       # another numbering: scipy sorts it out
        A = _blocks(rows, cols, vals, nn).tocoo()
        keep = keep_dof[A.row] & keep_dof[A.col]
        return sp.csc_matrix((A.data[keep], (new[A.row[keep]], new[A.col[keep]])), shape=(n, n))
    free_node = keep_dof.reshape(nn, 2)
    if np.array_equal(free_node[:, 0], free_node[:, 1]):         # clamps are whole nodes: drop their pairs
        free_node = free_node[:, 0]
        if not free_node.all():
            sel = free_node[rows] & free_node[cols]
            rank = np.cumsum(free_node) - 1
            rows, cols = rank[rows[sel]], rank[cols[sel]]
            vals = [[v[sel] for v in pair] for pair in vals]
            nn = int(free_node.sum())
        A = _blocks(rows, cols, vals, nn)
        data, indices, indptr = A.data, A.indices, A.indptr
    else:                                                         # a node clamped in one component
        A = _blocks(rows, cols, vals, nn)
        gone = np.flatnonzero(~keep_dof[A.indices])               # entries in dropped columns (few)
        per_row = np.diff(A.indptr) - np.bincount(np.searchsorted(A.indptr, gone, side="right") - 1,
                                                  minlength=2 * nn)
        keep = np.repeat(keep_dof, np.diff(A.indptr))
        keep[gone] = False
        data, indices = A.data[keep], new[A.indices[keep]]
        indptr = np.concatenate([[0], np.cumsum(per_row[keep_dof])])
    idx_dtype = np.int32 if max(data.size, n) < 2**31 else np.int64
    K = sp.csc_matrix((data, indices.astype(idx_dtype, copy=False), indptr.astype(idx_dtype, copy=False)),
                      shape=(n, n))
    K.has_sorted_indices = True
    K.has_canonical_format = True
    return K


def _blocks(rows: np.ndarray, cols: np.ndarray, vals, nn: int) -> sp.csr_matrix:
    """CSR of the 2 nn x 2 nn matrix with the 2 x 2 block [[vals[r][c][s]]] at node pair (rows[s], cols[s])
    (row-major sorted, distinct): unknown 2 i + c is component c of node i."""
    V = np.empty((rows.size, 2, 2))
    for r in range(2):
        for c in range(2):
            V[:, r, c] = vals[r][c]
    indptr = np.searchsorted(rows, np.arange(nn + 1))
    return sp.bsr_matrix((V, cols, indptr), shape=(2 * nn, 2 * nn)).tocsr()


def boundary_edges_on(p: np.ndarray, t: np.ndarray, on: np.ndarray) -> np.ndarray:
    """Edges (2, k) of triangles whose both end nodes satisfy the node mask ``on`` (a straight side)."""
    e = np.hstack([t[[0, 1]], t[[1, 2]], t[[2, 0]]])
    return e[:, on[e[0]] & on[e[1]]]


def traction_vector(p_ref: np.ndarray, edges: np.ndarray, g, scale: float) -> np.ndarray:
    """Nodal forces (2, nnodes) of the traction ``scale * g(x, y)`` on the edges, reference frame.

    ``g`` returns the vertical traction t2 or a tuple (t1, t2), evaluated on (nedges, 4) arrays.
    """
    q, wq = np.polynomial.legendre.leggauss(4)
    q, wq = 0.5 * (q + 1), 0.5 * wq
    a, b = p_ref[:, edges[0]], p_ref[:, edges[1]]
    L = np.hypot(*(b - a))
    X = a[0][:, None] + (b - a)[0][:, None] * q
    Y = a[1][:, None] + (b - a)[1][:, None] * q
    val = g(X, Y)
    tr = (np.broadcast_to(val[0], X.shape), np.broadcast_to(val[1], X.shape)) if isinstance(val, tuple) \
        else (np.zeros(X.shape), np.broadcast_to(val, X.shape))
    F = np.zeros((2, p_ref.shape[1]))
    for c in range(2):
        wt = scale * tr[c] * wq * L[:, None]
        np.add.at(F[c], edges[0], (wt * (1 - q)).sum(axis=1))
        np.add.at(F[c], edges[1], (wt * q).sum(axis=1))
    return F
