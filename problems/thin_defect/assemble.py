"""Assembly of the thin-defect QP on any (cut) triangle mesh, vectorized with numpy.

* Stiffness: P1 vector elements; the strains of P1 functions are constant per triangle, so one
  quadrature point (the element integral is the area times the constant integrand) is exact.
  DOF numbering: unknown 2 i + c (component c of node i) before clamping; after clamping the
  free unknowns keep their relative order (``node_dofs[c, i]``, -1 if clamped): scikit-fem's
  ``ElementVector(ElementTriP1())`` numbering restricted to the free DOFs.
* Traction on the loaded side: 4-point Gauss-Legendre per boundary edge (exact for P1 times a
  polynomial of degree <= 6), the traction evaluated in the reference (unrotated) frame.
* Interface: (1/delta_d) sum_j w_j |u_j^+ - u_j^-|^2 (whole jump vector, trapezoid rule);
  B row j = nu_j . (u_j^+ - u_j^-).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


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
    """
    d = node_dofs.astype(np.int32)[:, t]  # (2, 3, nt)
    touch = (d < 0).any(axis=(0, 1))
    if touch.any():  # triangles with clamped unknowns last: only they need masking below
        order = np.argsort(touch, kind="stable")
        t, d, k0 = t[:, order], d[:, :, order], int(np.count_nonzero(~touch))
    else:
        k0 = t.shape[1]
    gx, gy, area = shape_gradients(p, t)
    lm = lam + 2 * mu
    nt = t.shape[1]
    vals = np.empty((4, 3, 3, nt))
    rows = np.empty((4, 3, 3, nt), dtype=np.int32)
    cols = np.empty((4, 3, 3, nt), dtype=np.int32)
    # block a (3, 3, nt): entry (i, j) couples component r_a of node t[i] with component c_a of node t[j]
    # (few large temporaries: fresh memory costs page faults, which dominate at N = 512)
    gx, gy = gx * np.sqrt(area), gy * np.sqrt(area)
    tmp = np.empty((3, 3, nt))
    # block 0: lm gx_i gx_j + mu gy_i gy_j; 1: lm gy_i gy_j + mu gx_i gx_j; 2: lam gx_i gy_j + mu gy_i gx_j
    for out, (a1, b1, ca, a2, b2, cb) in zip(vals[:3], ((gx, gx, lm, gy, gy, mu), (gy, gy, lm, gx, gx, mu),
                                                     (gx, gy, lam, gy, gx, mu)), strict=True):
        np.multiply(a1[:, None], b1[None], out=out)
        out *= ca
        np.multiply(a2[:, None], b2[None], out=tmp)
        tmp *= cb
        out += tmp
    vals[3] = vals[2].transpose(1, 0, 2)
    for a, (r, c) in enumerate(((0, 0), (1, 1), (0, 1), (1, 0))):
        rows[a] = d[r][:, None]
        cols[a] = d[c][None, :]
    # entries of clamped unknowns (index -1): value 0 added to entry (0, 0), which exists anyway
    tv, tr, tc = vals[..., k0:], rows[..., k0:], cols[..., k0:]
    bad = (tr < 0) | (tc < 0)
    tv[bad] = 0.0
    tr[bad] = 0
    tc[bad] = 0
    return sp.csc_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))


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


def interface(node_dofs: np.ndarray, lower: np.ndarray, upper: np.ndarray, normals: np.ndarray,
              coef: np.ndarray, n: int) -> tuple[sp.csc_matrix, sp.csr_matrix, list[sp.csr_matrix]]:
    """(sum_j coef_j |u_j^+ - u_j^-|^2 as a CSC matrix, B, the jump operators J_c (u_c^+ - u_c^-))."""
    m = lower.size
    rows = np.arange(m)
    J = [sp.csr_matrix((np.r_[np.ones(m), -np.ones(m)], (np.r_[rows, rows], np.r_[node_dofs[c, upper],
                                                                                  node_dofs[c, lower]])),
                       shape=(m, n)) for c in range(2)]
    W = sp.diags(coef)
    Ki = (J[0].T @ W @ J[0] + J[1].T @ W @ J[1]).tocsc()
    B = (sp.diags(normals[0]) @ J[0] + sp.diags(normals[1]) @ J[1]).tocsr()
    B.eliminate_zeros()
    return Ki, B, J
