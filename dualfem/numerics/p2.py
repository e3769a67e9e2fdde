"""Quadratic (P2) triangles on a QP's mesh: the 6-node cells and the isoparametric shape functions.

A P2 thin-defect QP (``qp.geometry.element`` ``"P2"`` or ``"P2-quarter-point"``, docs/elements.md) holds every
P2 node in ``geometry.nodes`` (2, nv + ne): the ``nv`` vertices of the cut mesh, then one node per mesh edge,
edge ``k`` being the k-th of the sorted vertex pairs ``(min, max)`` of every triangle edge (the numbering of
``problems/_quadratic.edge_table``), and only the linear triangles (vertex ids) in ``geometry.cells``.
:func:`quadratic_cells` rebuilds the 6-node cells from that numbering and checks them on the coordinates: each
mid-edge node must lie on its edge at 1/2 of it (P2) or at 1/4 from one end (a quarter-point edge at a tip).

Local node order (VTK's quadratic triangle, meshio's ``triangle6``): vertices 0, 1, 2, then the mid-edge nodes
of the edges (0, 1), (1, 2), (2, 0). Reference triangle (0, 0), (1, 0), (0, 1) with barycentrics
``l0 = 1 - xi - eta``, ``l1 = xi``, ``l2 = eta``: ``N_i = l_i (2 l_i - 1)`` at the vertices, ``4 l_a l_b`` at the
mid-edge node of (a, b). The element is isoparametric: ``x(xi) = sum_i N_i(xi) X_i``.
"""
from __future__ import annotations

import numpy as np

#: the local edges (a, b) whose mid-edge nodes are local nodes 3, 4, 5
LOCAL_EDGES = ((0, 1), (1, 2), (2, 0))
#: where a mid-edge node may sit on its edge (fraction of the edge from its first end): P2, quarter-point
_POSITIONS = (0.25, 0.5, 0.75)


def quadratic_cells(nodes: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The 6-node cells (6, nt) of a P2 QP's ``nodes`` (2, nv + ne) and linear ``cells`` (3, nt), in the order of
    the module docstring. ValueError when the nodes are not the vertices followed by one node per sorted edge, or
    a mid-edge node is not on its edge at 1/4, 1/2 or 3/4 of it (relative tolerance 1e-8 of the edge)."""
    cells = np.asarray(cells, dtype=np.int64)
    nodes = np.asarray(nodes, dtype=float)
    nv = int(cells.max()) + 1 if cells.size else 0
    a = np.stack([cells[i] for i, _ in LOCAL_EDGES])
    b = np.stack([cells[j] for _, j in LOCAL_EDGES])
    keys, inv = np.unique(np.minimum(a, b).ravel() * max(nv, 1) + np.maximum(a, b).ravel(), return_inverse=True)
    if nodes.shape[1] != nv + keys.size:
        raise ValueError(f"a P2 mesh needs {nv} vertices + {keys.size} mid-edge nodes, the QP has {nodes.shape[1]} "
                         f"nodes")
    mid = nv + inv.reshape(a.shape)
    pa, pb, pm = nodes[:, a], nodes[:, b], nodes[:, mid]
    d = pb - pa
    L2 = np.sum(d * d, axis=0)
    t = np.sum((pm - pa) * d, axis=0) / np.where(L2 > 0, L2, 1.0)
    off = np.linalg.norm(pm - pa - t * d, axis=0)
    near = np.min(np.abs(t[..., None] - np.asarray(_POSITIONS)), axis=-1)
    if np.any(off > 1e-8 * np.sqrt(L2)) or np.any(near > 1e-8):
        raise ValueError("the QP's mid-edge nodes are not on their edges at 1/4, 1/2 or 3/4 (not the P2 node "
                         "numbering of problems/_quadratic.edge_table)")
    return np.vstack([cells, mid])


def shape(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P2 shape functions (q, 6) and their reference gradients (q, 6, 2) at the reference points ``xi`` (q, 2)."""
    x, y = xi[:, 0], xi[:, 1]
    lam = np.stack([1 - x - y, x, y])                                       # (3, q)
    dlam = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])                # d l_i / d (xi, eta)
    N = [lam[i] * (2 * lam[i] - 1) for i in range(3)] + [4 * lam[i] * lam[j] for i, j in LOCAL_EDGES]
    dN = [(4 * lam[i] - 1)[:, None] * dlam[i] for i in range(3)] + \
         [4 * (lam[j][:, None] * dlam[i] + lam[i][:, None] * dlam[j]) for i, j in LOCAL_EDGES]
    return np.stack(N, axis=1), np.stack(dN, axis=1)


def triangle_rule(n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A collapsed (Duffy) Gauss rule on the reference triangle: points (n^2, 2), weights (n^2,) summing to 1/2,
    exact for polynomials of degree 2 n - 2; no point on the boundary (a quarter-point element's Jacobian
    vanishes at its tip vertex)."""
    g, w = np.polynomial.legendre.leggauss(n)
    g, w = 0.5 * (g + 1), 0.5 * w
    u, v = np.meshgrid(g, g, indexing="ij")
    wu, wv = np.meshgrid(w, w, indexing="ij")
    pts = np.stack([u.ravel(), (v * (1 - u)).ravel()], axis=1)
    return pts, (wu * wv * (1 - u)).ravel()


def gradients(X: np.ndarray, U: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement gradients (nt, q, 2, 2) ``[t, q, c, d] = d u_c / d x_d`` and Jacobian determinants (nt, q) of
    the isoparametric cells with node coordinates ``X`` (nt, 6, 2) and nodal displacements ``U`` (nt, 6, 2), at the
    points of the reference gradients ``dN`` (q, 6, 2) (:func:`shape`)."""
    J = np.einsum("tia,qib->tqab", X, dN)                                  # d x_a / d xi_b
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    inv = np.stack([np.stack([J[..., 1, 1], -J[..., 0, 1]], -1), np.stack([-J[..., 1, 0], J[..., 0, 0]], -1)], -2)
    inv = inv / det[..., None, None]
    dU = np.einsum("tic,qib->tqcb", U, dN)                                 # d u_c / d xi_b
    return np.einsum("tqcb,tqbd->tqcd", dU, inv), det
