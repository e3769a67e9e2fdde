"""A synthetic 3D contact QP (Signorini-type) for the linear-algebra tests and benchmarks.

Body: the box [0, 1] x [0, 1] x [0, height], N x N x Nz cubes each cut into six tetrahedra
(scikit-fem's ``MeshTet.init_tensor``), P1 vector elasticity (E, nu), clamped on the base z = 0.
A rigid lid touches the top face z = height: every top node j gets one constraint row
``n_j . u_j >= 0`` with n_j = (0, 0, -1) (the node may move down, away from the lid, not up into it).
Load: a traction on the top face, pushing up (+q) where x < 1/2 (those nodes press against the
lid: contact) and pulling down (-q) where x >= 1/2 (open), plus a sideways shear q/2 in x, so the
contact set is a proper subset of the top nodes.

Multipliers mu_j >= 0 are the lid's nodal forces; ``weights`` the nodal areas of the top face.
The QP carries ``GeometryPart(dim=3, nodes (3, n), cells (4, nt), node_dofs (3, n))``, a
``LocalPart(K_fixed = K, dofs = the constrained unknowns)`` and the material.

The stiffness is the 3D problem's assembly (problems/three_d/assemble.py), checked against
scikit-fem's in tests/test_amg.py.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.core.parts import GeometryPart, MaterialPart, UnitsPart
from dualfem.core.qp import QP

#: N of the benchmark sizes: 3 N^2 (N + 1) ~ 14 k, 45 k, 148 k, 346 k, 670 k unknowns (height 1)
SIZES = (16, 24, 36, 48, 60)


def unknowns(N: int, Nz: int | None = None) -> int:
    """Number of unknowns of :func:`box_qp` (3 per node above the base)."""
    Nz = N if Nz is None else Nz
    return 3 * (N + 1) ** 2 * Nz


def elasticity_matrix(nodes: np.ndarray, cells: np.ndarray, E: float, nu: float) -> sp.csc_matrix:
    """Stiffness (3 n_nodes square, node-major: unknown 3 i + c) of P1 elasticity on tetrahedra: the 3D
    problem's vectorised assembly (:func:`dualfem.problems.three_d.assemble.stiffness`) with every node free,
    on the tetrahedra oriented positively as it requires (the stiffness does not depend on the orientation)."""
    from dualfem.core.elasticity import lame
    from dualfem.problems.three_d.assemble import gradients, stiffness

    t = np.array(cells, dtype=np.int64)
    _, vol = gradients(nodes, t)
    t[:, vol < 0] = t[[0, 2, 1, 3]][:, vol < 0]
    lam, G = lame(E, nu, "strain")
    nn = nodes.shape[1]
    return stiffness(nodes, t, lam, G, np.arange(3 * nn).reshape(nn, 3).T, 3 * nn)


def box_qp(N: int, Nz: int | None = None, height: float = 1.0, E: float = 1000.0, nu: float = 0.3,
           q: float = 1.0) -> QP:
    """The Signorini-type 3D QP of the module docstring on N x N x Nz cubes (6 tetrahedra each)."""
    import skfem

    Nz = N if Nz is None else Nz
    mesh = skfem.MeshTet.init_tensor(np.linspace(0, 1, N + 1), np.linspace(0, 1, N + 1),
                                     np.linspace(0, height, Nz + 1))
    X, t = np.asarray(mesh.p, float), np.asarray(mesh.t, np.int64)
    nn = X.shape[1]
    Kfull = elasticity_matrix(X, t, E, nu)
    base = np.isclose(X[2], 0.0)
    top = np.flatnonzero(np.isclose(X[2], height))
    node_dofs = np.full((3, nn), -1, np.int64)
    free_nodes = np.flatnonzero(~base)
    node_dofs[:, free_nodes] = np.arange(3 * free_nodes.size).reshape(-1, 3).T
    keep = (3 * free_nodes[:, None] + np.arange(3)).ravel()          # node-major order, as node_dofs
    K = Kfull[keep][:, keep].tocsc()
    K = (0.5 * (K + K.T)).tocsc()
    h = 1.0 / N
    # nodal areas of the top face (bilinear lumping: h^2 inside, halves on edges, quarters at corners)
    wx = np.where(np.isclose(X[0, top], 0) | np.isclose(X[0, top], 1), 0.5, 1.0)
    wy = np.where(np.isclose(X[1, top], 0) | np.isclose(X[1, top], 1), 0.5, 1.0)
    w = h * h * wx * wy
    n = K.shape[0]
    F = np.zeros(n)
    up = np.where(X[0, top] < 0.5, q, -q)
    F[node_dofs[2, top]] = up * w
    F[node_dofs[0, top]] = 0.5 * q * w
    zc = node_dofs[2, top]
    B = sp.csr_matrix((-np.ones(top.size), (np.arange(top.size), zc)), shape=(top.size, n))
    return QP(K=K, F=F, B=B, weights=w, K_fixed=K, local_dofs=np.sort(zc), name=f"box3d_N{N}",
              geometry=GeometryPart.make(X, t, node_dofs, dim=3), units=UnitsPart(E, 1.0),
              material=MaterialPart(E, nu))
