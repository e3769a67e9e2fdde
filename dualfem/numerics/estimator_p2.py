"""Zienkiewicz-Zhu recovery on quadratic (P2, quarter-point) triangles: :func:`dualfem.numerics.estimator.estimate`
of a QP whose ``geometry.element`` is ``"P2"`` or ``"P2-quarter-point"`` (2D only).

The P2 stress ``sigma_h`` is linear on a straight triangle and singular like r^(-1/2) at the tip of a quarter-point
one (whose Jacobian vanishes there), so it is never evaluated at a node. Recovery, per triangle then per node:

1. the element-wise L2 projection of ``sigma_h`` onto the functions linear in the reference coordinates (exact on a
   straight triangle, where ``sigma_h`` is linear), by the collapsed Gauss rule of
   :func:`dualfem.numerics.p2.triangle_rule` (no point on the boundary), evaluated at the triangle's 6 nodes;
2. at every P2 node the area-weighted mean of those values over the triangles holding it: ``sigma*`` is continuous
   and P2 (isoparametric) on the *cut* mesh, jumping across a defect as the true stress does (the doubled vertex
   and mid-edge nodes average one face's triangles), the tips averaging both;
3. at every node of a defect pair (vertex and mid-edge) the face's actual traction imposed
   (:func:`dualfem.numerics.estimator.face_tractions`, :func:`dualfem.numerics.estimator.impose_traction`), as on P1.

Indicator ``eta_T^2 = int_T (sigma* - sigma_h) : C^-1 (sigma* - sigma_h)`` and ``energy2 = int_T sigma_h : C^-1
sigma_h``, both by the same rule (16 points, exact for degree 6 on straight triangles; on a quarter-point triangle
the integrand ~ 1/r times the Jacobian ~ r is bounded, so the rule converges). The :class:`~.estimator.Estimate`
carries ``order = 2``: P2's energy error scales as h^2 where the solution is smooth (the optimal-mesh rule's p).
"""
from __future__ import annotations

import numpy as np

from .estimator import Estimate, _energy_density, impose_traction
from .p2 import LOCAL_EDGES, gradients, quadratic_cells, shape, triangle_rule

#: points per direction of the collapsed Gauss rule (16 points: exact for degree 6 on straight triangles)
_RULE = 4


def zz_estimate_p2(nodes: np.ndarray, cells: np.ndarray, u: np.ndarray, lam: float, mu: float,
                   faces: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Estimate:
    """The ZZ estimate (module docstring) of the P2 displacement ``u`` (n, 2) on the P2 ``nodes`` (2, n) with the
    linear triangles ``cells`` (3, nt) (the mid-edge nodes by :func:`dualfem.numerics.p2.quadratic_cells`);
    ``faces``: (node ids, unit normals (k, 2), tractions (k, 2)) imposed on the recovered stress at those nodes."""
    c6 = quadratic_cells(nodes, cells)
    X, U = nodes.T[c6.T], np.asarray(u, dtype=float)[c6.T]                # (nt, 6, 2)
    xi, w = triangle_rule(_RULE)
    N, dN = shape(xi)
    du, det = gradients(X, U, dN)
    if np.any(det == 0) or np.any(np.sign(det) != np.sign(det[:, :1])):
        raise ValueError("a P2 triangle's Jacobian vanishes or changes sign inside it (an inverted element)")
    dx = w * np.abs(det)                                                  # (nt, q): the rule's weights on T
    tr = du[..., 0, 0] + du[..., 1, 1]
    s = np.stack([lam * tr + 2 * mu * du[..., 0, 0], lam * tr + 2 * mu * du[..., 1, 1],
                  mu * (du[..., 0, 1] + du[..., 1, 0])], axis=-1)           # (nt, q, 3)
    phi = np.stack([1 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]], axis=1)  # (q, 3)
    M = np.einsum("tq,qa,qb->tab", dx, phi, phi)
    coef = np.linalg.solve(M, np.einsum("tq,qa,tqc->tac", dx, phi, s))    # (nt, 3 vertices, 3 components)
    at_nodes = np.concatenate([coef, np.stack([0.5 * (coef[:, a] + coef[:, b]) for a, b in LOCAL_EDGES], 1)], 1)
    area = dx.sum(axis=1)
    n_nodes = nodes.shape[1]
    wsum = np.bincount(c6.ravel(), weights=np.tile(area, 6), minlength=n_nodes)
    star = np.stack([np.bincount(c6.T.ravel(), weights=(area[:, None] * at_nodes[..., k]).ravel(),
                                 minlength=n_nodes) for k in range(3)], axis=1) / np.where(wsum > 0, wsum, 1.0)[:, None]
    if faces is not None and len(faces[0]):
        ids = np.asarray(faces[0], dtype=np.int64)
        star[ids] = impose_traction(star[ids], faces[1], faces[2])
    s_star = np.einsum("qi,tic->tqc", N, star[c6.T])
    eta2 = np.sum(dx * _energy_density(s_star - s, lam, mu), axis=1)
    return Estimate(eta2=eta2, energy2=np.sum(dx * _energy_density(s, lam, mu), axis=1), area=area, order=2.0)
