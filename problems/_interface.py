"""The defect interface of a cut mesh, for 2D (triangles) and 3D (tetrahedra) alike.

What :mod:`.thin_defect` (polylines in a triangle mesh), :mod:`.fractured` (through thin_defect) and
:mod:`.three_d` (surfaces in a tetrahedral mesh) share once their cut has chosen the doubled nodes:

* **doubling** (:func:`double_nodes`): the "-" copy of interior defect node j is the original node
  ``lower[j]``, the "+" copy a new node ``upper[j] = n_nodes + j`` at the same place;
* **jumps** (:func:`jump_operators`): ``J_c x = u_c^+ - u_c^-`` per displacement component c (m x n);
* **the delta term and B** (:func:`interface`): ``K_param = sum_j coef_j |u_j^+ - u_j^-|^2`` (the whole
  jump vector; ``coef_j = w_j / delta_j`` by :func:`delta_coefficients`, w_j the nodal weight, a length in
  2D, an area in 3D) and ``B`` row j ``= nu_j . (u_j^+ - u_j^-)`` (``nu_j`` the unit "+" normal);
* **the local unknowns** (:func:`local_unknowns`): every unknown of a doubled node, on which ``K_param``
  and ``B`` act.

Conventions: ``node_dofs`` (dim, n_nodes) unknown of component c of node i (-1: fixed); ``normals``
(dim, m) here, as the cuts compute them (the typed :class:`~dualfem.core.parts.InterfacePart` stores (m, dim)).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dualfem.numerics.linalg import freeze
from dualfem.qp import InterfacePart


@dataclass
class DoubledNodes:
    """What every cut gives (2D: :class:`.thin_defect.cut.Cut`, 3D: :class:`.three_d.cut.Cut3`), defect by defect:
    ``points`` (dim, n_nodes) the doubled mesh's nodes; per constrained node j (m of them): ``lower``/``upper``
    node ids of its "-"/"+" copies, ``defect_id``, ``normals`` (dim, m) unit "+" normals (the cut's frame),
    ``weights`` (m,) nodal weights (a length in 2D, an area in 3D)."""

    points: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    defect_id: np.ndarray
    normals: np.ndarray
    weights: np.ndarray


def double_nodes(points: np.ndarray, lower: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points with a copy of each ``lower`` node appended, the copies' ids ``upper``)."""
    nn = points.shape[1]
    return np.hstack([points, points[:, lower]]), nn + np.arange(lower.size)


def cut_faults(n_points: int, cells: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[bool, np.ndarray]:
    """What makes a cut mesh wrong (``cells`` (k, nc) node ids, ``lower``/``upper`` the copies of the doubled nodes):
    whether a cell touches both copies of one node, and the pairs j whose ``lower[j]`` or ``upper[j]`` is in no
    cell (the node has cells on one side only)."""
    base = np.arange(n_points)
    base[upper] = lower
    orig = np.sort(base[cells], axis=0)
    count = np.bincount(cells.ravel(), minlength=n_points)
    return bool(np.any(orig[1:] == orig[:-1])), np.flatnonzero((count[lower] == 0) | (count[upper] == 0))


def jump_operators(node_dofs: np.ndarray, lower: np.ndarray, upper: np.ndarray, n: int) -> list[sp.csr_matrix]:
    """The jumps ``J_c`` (m x n, CSR), ``J_c x = u_c(upper[j]) - u_c(lower[j])``, one per component c.

    A fixed component (-1) of a defect node is refused (ValueError): its jump would not be an unknown."""
    m = lower.size
    if m and ((node_dofs[:, lower] < 0).any() or (node_dofs[:, upper] < 0).any()):
        raise ValueError("a defect node has a fixed component")
    rows = np.arange(m)
    return [sp.csr_matrix((np.r_[np.ones(m), -np.ones(m)], (np.r_[rows, rows], np.r_[node_dofs[c, upper],
                                                                                     node_dofs[c, lower]])),
                          shape=(m, n)) for c in range(node_dofs.shape[0])]


def interface(node_dofs: np.ndarray, lower: np.ndarray, upper: np.ndarray, normals: np.ndarray,
              coef: np.ndarray, n: int) -> tuple[sp.csc_matrix, sp.csr_matrix, list[sp.csr_matrix]]:
    """(``sum_j coef_j |u_j^+ - u_j^-|^2`` as an n x n CSC matrix, B (m x n, CSR): ``B x = nu_j . (u_j^+ -
    u_j^-)``, the jump operators of :func:`jump_operators`). ``normals`` (dim, m): unit "+" normals.

    The components are summed in order 0, 1(, 2) (the sparse sums' rounding is part of the QP's bits)."""
    J = jump_operators(node_dofs, lower, upper, n)
    W = sp.diags(coef)
    Ki = J[0].T @ W @ J[0]
    B = sp.diags(normals[0]) @ J[0]
    for c in range(1, len(J)):
        Ki = Ki + J[c].T @ W @ J[c]
        B = B + sp.diags(normals[c]) @ J[c]
    B = B.tocsr()
    B.eliminate_zeros()
    return Ki.tocsc(), B, J


def delta_coefficients(weights: np.ndarray, defect_id: np.ndarray, deltas) -> tuple[np.ndarray, np.ndarray]:
    """(per-node delta ``deltas[defect_id[j]]``, the interface coefficients ``w_j / delta_j``)."""
    delta = np.asarray(deltas, dtype=float)[defect_id]
    return delta, weights / delta


def delta_free_part(node_dofs: np.ndarray, cut: DoubledNodes, normals: np.ndarray, **extra) -> InterfacePart:
    """The :class:`~dualfem.core.parts.InterfacePart` of a cut (``upper``, ``lower``, ``weights``, ``defect_id``
    of a 2D or 3D cut) without delta, its arrays read-only but the weights (they become the QP's). ``normals``
    (m, dim) in the scene's frame; ``extra``: tangents, front, front_id, faces, s."""
    part = InterfacePart.make(node_dofs, cut.upper, cut.lower, normals, cut.weights, cut.defect_id, **extra)
    frozen = ("upper", "lower", "plus_dofs", "minus_dofs", "normals", "tangents", "defect_id", "front", "front_id",
              "faces", "s")
    freeze(*(getattr(part, f) for f in frozen if getattr(part, f) is not None))
    return part


def with_delta(part: InterfacePart, deltas) -> tuple[InterfacePart, np.ndarray]:
    """(the part with its per-node delta, the interface coefficients ``w_j / delta_j``) for one delta per defect."""
    delta, coef = delta_coefficients(part.weights, part.defect_id, deltas)
    return dataclasses.replace(part, delta=delta), coef


def local_unknowns(node_dofs: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The sorted unknowns of the doubled nodes (both copies, every component)."""
    return np.unique(np.concatenate([node_dofs[:, upper].ravel(), node_dofs[:, lower].ravel()]))
