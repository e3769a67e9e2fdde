"""The defect interface of a cut mesh for quadratic (P2) elements, 2D (triangles) and 3D (tetrahedra) alike.

A P2 mesh has one node per vertex and one per edge. Numbering (the "P2 nodes"): the ``nv`` vertices of the
cut mesh first (their ids unchanged, so the P1 cut's ``lower``/``upper`` pairs stay valid), then edge ``k`` of
``edges`` (2, ne) as node ``nv + k``. On a cut mesh the doubled vertices are separate nodes, so an edge of
the "-" face and its copy on the "+" face are different mesh edges, and their mid-edge nodes are distinct.

What this module adds to the P1 cut (:class:`._interface.DoubledNodes`):

* **mid-edge pairs** (:func:`mid_edge_pairs`): crack edge ``(a, b)`` on the "-" face pairs with ``(a', b')`` on
  the "+" face, ``a' = upper[j]`` when ``a = lower[j]`` is doubled and ``a' = a`` when ``a`` is a tip / front
  vertex (single). The mid-edge node of an edge with a doubled vertex IS doubled (its two edges differ); an
  edge with both vertices on the tips / front is the same edge on both faces: not a pair (no jump there).
* **normals** at the mid-edge pairs: the mean of the "+" normals of the edge's doubled vertices with its
  component along the edge removed, normalised (2D: exactly the edge's normal, oriented as the cut's).
* **positive nodal weights** (``integral over the defect of phi ~ sum_j w_j phi_j``):
  2D (:func:`edge_weights`): the row sums of the isoparametric P2 mass matrix on each crack edge,
  ``w_i = int_edge N_i ds`` (5-point Gauss): Simpson's ``L/6, 2L/3, L/6`` for a mid-edge node at the middle,
  ``0, 2L/3, L/3`` for a quarter-point edge (mid-edge node at L/4 from the tip, the tip first).
  3D (:func:`face_weights`): P2 row-sum lumping gives the vertices weight 0 on a flat triangle, so each P2
  face is split into its 4 sub-triangles (corner, corner's two mid-edge nodes; and the middle one) and P1
  lumping applied on each: vertex ``A/12``, mid-edge node ``A/4`` per face of area A (every weight > 0).

With these pairs, normals and weights the QP keeps its form: the delta term ``sum_j (w_j / delta_j)
|u_j^+ - u_j^-|^2`` and the rows ``B_j x = nu_j . (u_j^+ - u_j^-) >= 0`` are
:func:`._interface.interface` on the P2 node numbering, so every solver and the certificate run unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._interface import DoubledNodes

#: Gauss-Legendre points per crack edge for the isoparametric edge weights (exact for degree 9 on straight edges)
_EDGE_GAUSS = 5


@dataclass
class MidPairs:
    """The mid-edge node pairs of the crack edges (k of them): ``lower``/``upper`` (k,) P2 node ids on the "-"
    / "+" face; ``edge`` (2, k) the "-" face's edge (vertex ids, the order given); ``vertex_pairs`` (2, k): for
    each end of the edge, the index j of its vertex pair in the P1 cut, -1 for a tip / front vertex."""

    lower: np.ndarray
    upper: np.ndarray
    edge: np.ndarray
    vertex_pairs: np.ndarray


def edge_table(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(edges (2, ne) sorted vertex pairs, ``cell_edges`` (ne_per_cell, nc) the edge ids of each cell) of
    simplex ``cells`` (dim + 1, nc); the local edges of a cell are its vertex pairs (i, j), i < j, in order."""
    cells = np.asarray(cells, dtype=np.int64)
    nv = cells.shape[0]
    loc = [(i, j) for i in range(nv) for j in range(i + 1, nv)]
    a = np.stack([cells[i] for i, _ in loc])
    b = np.stack([cells[j] for _, j in loc])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(cells.max()) + 1 if cells.size else 0
    keys, inv = np.unique(lo.ravel() * n + hi.ravel(), return_inverse=True)
    return np.stack([keys // max(n, 1), keys % max(n, 1)]), inv.reshape(lo.shape)


def edge_index(edges: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index into ``edges`` (2, ne; sorted vertex pairs, as :func:`edge_table`) of the edges (a, b); -1 if absent."""
    n = int(max(edges.max(initial=0), np.max(a, initial=0), np.max(b, initial=0))) + 1
    keys = edges[0].astype(np.int64) * n + edges[1]
    want = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    pos = np.searchsorted(keys, want)
    pos = np.minimum(pos, keys.size - 1)
    return np.where((keys.size > 0) & (keys[pos] == want), pos, -1)


def mid_edge_pairs(cut: DoubledNodes, edges: np.ndarray, crack_edges: np.ndarray) -> MidPairs:
    """The doubled mid-edge nodes of the crack edges (see the module docstring).

    ``edges`` (2, ne): every edge of the cut mesh as sorted vertex pairs (:func:`edge_table`; edge k is P2 node
    ``nv + k``, nv = ``cut.points.shape[1]``); ``crack_edges`` (2, k): the crack's edges on the "-" face
    (vertex ids of the cut mesh: doubled vertices by their ``lower`` id); an edge given twice (3D: the edge of two
    crack faces) is taken once, as first given. ValueError when an edge or its "+" copy is not an edge of the
    mesh (the cut is at fault).
    """
    nv = cut.points.shape[1]
    pair_of = np.full(nv, -1, np.int64)
    pair_of[cut.lower] = np.arange(cut.lower.size)
    ce = np.asarray(crack_edges, dtype=np.int64).reshape(2, -1)
    _, first = np.unique(np.minimum(ce[0], ce[1]) * nv + np.maximum(ce[0], ce[1]), return_index=True)
    ce = ce[:, np.sort(first)]
    vp = pair_of[ce]
    doubled = (vp >= 0).any(axis=0)
    ce, vp = ce[:, doubled], vp[:, doubled]
    plus = np.where(vp >= 0, cut.upper[np.maximum(vp, 0)], ce)
    lo, up = edge_index(edges, ce[0], ce[1]), edge_index(edges, plus[0], plus[1])
    if np.any(lo < 0) or np.any(up < 0):
        raise ValueError("a crack edge (or its copy on the '+' face) is not an edge of the cut mesh")
    if np.any(lo == up):
        raise ValueError("a crack edge with a doubled vertex is the same edge on both faces")
    return MidPairs(nv + lo, nv + up, ce, vp)


def mid_normals(cut: DoubledNodes, points: np.ndarray, mid: MidPairs) -> np.ndarray:
    """Unit "+" normals (dim, k) at the mid-edge pairs: the mean of the edge's doubled vertices' normals
    (``cut.normals``) without its component along the edge (``points``: vertex coordinates (dim, >= nv))."""
    vp = mid.vertex_pairs
    n = np.where(vp[0] >= 0, 1.0, 0.0) * cut.normals[:, np.maximum(vp[0], 0)] + \
        np.where(vp[1] >= 0, 1.0, 0.0) * cut.normals[:, np.maximum(vp[1], 0)]
    t = points[:, mid.edge[1]] - points[:, mid.edge[0]]
    t = t / np.linalg.norm(t, axis=0)
    n = n - np.sum(n * t, axis=0) * t
    return n / np.linalg.norm(n, axis=0)


def _p2_line(xi: np.ndarray) -> np.ndarray:
    """Quadratic Lagrange functions (3, q) on [0, 1] at nodes 0, 1/2, 1 (the order: first, middle, last)."""
    return np.stack([2 * (xi - 0.5) * (xi - 1), 4 * xi * (1 - xi), 2 * xi * (xi - 0.5)])


def edge_weights(points: np.ndarray, triples: np.ndarray, n_nodes: int) -> np.ndarray:
    """Isoparametric row-sum weights (n_nodes,) of crack edges ``triples`` (3, k) = (first vertex, mid-edge node,
    last vertex) with P2 node coordinates ``points`` (dim, n_nodes): ``w_i += int_edge N_i ds`` (2D)."""
    g, wg = np.polynomial.legendre.leggauss(_EDGE_GAUSS)
    xi, wg = 0.5 * (g + 1), 0.5 * wg
    N = _p2_line(xi)                                                       # (3, q)
    dN = np.stack([4 * xi - 3, 4 - 8 * xi, 4 * xi - 1])                    # d/dxi
    X = points[:, triples]                                                 # (dim, 3, k)
    ds = np.linalg.norm(np.einsum("dik,iq->dkq", X, dN), axis=0)           # (k, q)
    w = np.einsum("iq,kq,q->ik", N, ds, wg)                                # (3, k)
    return np.bincount(triples.ravel(), weights=w.ravel(), minlength=n_nodes)


def face_weights(points: np.ndarray, faces6: np.ndarray, n_nodes: int) -> np.ndarray:
    """Weights (n_nodes,) of P2 crack faces ``faces6`` (6, k) = (v0, v1, v2, m01, m12, m02) (3D): P1 lumping on
    the 4 sub-triangles of each face (vertex A/12, mid-edge node A/4 on a flat face of area A; all > 0)."""
    v0, v1, v2, m01, m12, m02 = faces6
    subs = [(v0, m01, m02), (v1, m12, m01), (v2, m02, m12), (m01, m12, m02)]
    w = np.zeros(n_nodes)
    for a, b, c in subs:
        e1, e2 = points[:, b] - points[:, a], points[:, c] - points[:, a]
        area = 0.5 * np.linalg.norm(np.cross(e1.T, e2.T), axis=-1)
        for v in (a, b, c):
            w += np.bincount(v, weights=area / 3, minlength=n_nodes)
    return w


def quadratic_interface(cut: DoubledNodes, points: np.ndarray, mid: MidPairs, node_weights: np.ndarray) -> DoubledNodes:
    """The P2 interface: the cut's vertex pairs (first, in their order) then the mid-edge pairs, with the normals
    of :func:`mid_normals`, ``defect_id`` of their vertices and the weights ``node_weights`` (n_nodes,) read at the
    "-" node of each pair (:func:`edge_weights` / :func:`face_weights`); ``points`` (dim, n_nodes) the P2 nodes.
    ValueError when a pair's weight is not positive (a mid-edge node outside the middle half of its edge)."""
    vp = mid.vertex_pairs
    dmid = cut.defect_id[np.where(vp[0] >= 0, vp[0], vp[1])]
    lower = np.concatenate([cut.lower, mid.lower])
    w = node_weights[lower]
    if np.any(w <= 0):
        raise ValueError("a crack node's weight is not positive (a mid-edge node too far from its edge's middle)")
    return DoubledNodes(points=points, lower=lower, upper=np.concatenate([cut.upper, mid.upper]),
                        defect_id=np.concatenate([cut.defect_id, dmid]),
                        normals=np.hstack([cut.normals, mid_normals(cut, points, mid)]), weights=w)
