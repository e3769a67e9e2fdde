"""Quadratic (P2) tetrahedra on a cut mesh: the mid-edge nodes, the defect pairs at them, consistent loads.

A cut P1 mesh (:mod:`.three_d.cut`: the "+" copies of the doubled nodes are separate nodes) becomes a P2 mesh by
adding one node at the middle of every edge. Node ids (those of :mod:`._quadratic`): the P1 nodes ``0 .. nv-1``
first, then the mid-edge node of edge e of :func:`._quadratic.edge_table` (sorted vertex pairs) at ``nv + e``.
Cells (10, nt): the tetrahedron's corners as given, then its mid-edge nodes in VTK's ``tetra10`` order (0,1),
(1,2), (0,2), (0,3), (1,3), (2,3) (scikit-fem's ElementTetP2 order too).

Defect pairs, their normals and nodal weights: :mod:`._quadratic` (the vertex pairs of the cut, then the
mid-edge nodes of the defect's triangles with a doubled end; weights: the row-sum lumping of P2 triangles gives
the corners zero weight, so each P2 face is split into its 4 sub-triangles and lumped as P1: a corner gets A/12
and a mid-edge node A/4 per face of area A, positive and summing to the area). This module adds the 3D mesh
(:func:`quadratic_tets`), the pairs of a 3D cut (:func:`interface_pairs`) and the P2 shape functions on
triangles and tetrahedra for consistent loads (:func:`shape_values`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualfem.errors import InputError

from ._interface import DoubledNodes
from ._quadratic import edge_table, face_weights, mid_edge_pairs, quadratic_interface

#: the six edges of a tetrahedron in VTK's tetra10 (= scikit-fem's ElementTetP2) order
TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
#: the three edges of a triangle in the order of the quadratic triangle (VTK's triangle6)
TRI_EDGES = np.array([[0, 1], [1, 2], [0, 2]])


@dataclass(frozen=True)
class QuadraticTets:
    """A P2 tetrahedral mesh: ``points`` (3, nv + ne), ``cells`` (10, nt), ``edges`` (2, ne) vertex ids, ``nv``."""

    points: np.ndarray
    cells: np.ndarray
    edges: np.ndarray
    nv: int

    @property
    def tets(self) -> np.ndarray:
        return self.cells[:4]

    def midnodes(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The mid-edge node ids of the vertex pairs (a, b) (arrays of one shape); -1 where (a, b) is no edge."""
        lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
        keys = self.edges[0].astype(np.int64) * self.nv + self.edges[1]
        order = np.argsort(keys)
        k = lo * self.nv + hi
        pos = np.minimum(np.searchsorted(keys[order], k), keys.size - 1)
        found = keys[order][pos] == k
        return np.where(found, self.nv + order[pos], -1)

    def simplex_midnodes(self, simplices: np.ndarray) -> np.ndarray:
        """Mid-edge nodes (3, k) of triangles (3, k) (order :data:`TRI_EDGES`) or (6, k) of tetrahedra (4, k)
        (order :data:`TET_EDGES`); InputError if a side is not an edge of the mesh."""
        local = TRI_EDGES if simplices.shape[0] == 3 else TET_EDGES
        mids = self.midnodes(simplices[local[:, 0]], simplices[local[:, 1]])
        if mids.size and mids.min() < 0:
            raise InputError("a boundary or defect triangle is not made of mesh edges (internal error of the P2 mesh)")
        return mids


def quadratic_tets(points: np.ndarray, tets: np.ndarray) -> QuadraticTets:
    """The P2 mesh of a P1 mesh ``points`` (3, nv), ``tets`` (4, nt) (see the module docstring)."""
    edges, _ = edge_table(tets)
    nv = points.shape[1]
    mid = 0.5 * (points[:, edges[0]] + points[:, edges[1]])
    q = QuadraticTets(np.hstack([points, mid]), np.zeros((10, 0), np.int64), edges, nv)
    t = np.asarray(tets, dtype=np.int64)
    return QuadraticTets(q.points, np.vstack([t, q.simplex_midnodes(t)]), edges, nv)


def interface_pairs(q: QuadraticTets, cut: DoubledNodes, faces: np.ndarray) -> DoubledNodes:
    """The P2 defect pairs of a cut (:func:`._quadratic.quadratic_interface`): the cut's vertex pairs, then the
    mid-edge pairs of the defects' triangles ``faces`` (3, nf; "-" node ids, :class:`.three_d.cut.Cut3`
    ``faces``), the weights of :func:`._quadratic.face_weights` (A/12 per face at a vertex, A/4 at a mid-edge
    node). ``q``: the P2 mesh of the cut."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.hstack([f[TRI_EDGES[k]] for k in range(3)]), axis=0)
    crack_edges = np.unique(e, axis=1)
    mid = mid_edge_pairs(cut, q.edges, crack_edges)
    w = face_weights(q.points, np.vstack([f, q.simplex_midnodes(f)]), q.points.shape[1])
    return quadratic_interface(cut, q.points, mid, w)


def shape_values(lam: np.ndarray) -> np.ndarray:
    """P2 shape functions (q, k + 1 + edges) at barycentric points ``lam`` (q, k + 1), k = 2 or 3: the corners'
    l_i (2 l_i - 1), then 4 l_i l_j on the edges in the order of :data:`TRI_EDGES` / :data:`TET_EDGES`."""
    local = TRI_EDGES if lam.shape[1] == 3 else TET_EDGES
    return np.hstack([lam * (2 * lam - 1), 4 * lam[:, local[:, 0]] * lam[:, local[:, 1]]])
