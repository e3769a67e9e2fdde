"""Meshes of the rectangular body: the structured grid, its straight-edge defects, rotation.

Node and triangle numbering of :func:`structured_mesh` are those of scikit-fem's
``MeshTri.init_tensor`` (the QPs of the paper's scenes keep their DOF numbering): node (i, j)
at ``(i W/N, j H/N)`` has id ``i (N + 1) + j``; each grid square is cut by its (1, 1) diagonal.
"""
from __future__ import annotations

import numpy as np

from dualfem.errors import InputError


def structured_mesh(N: int, width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (2, (N+1)^2) and triangles (3, 2 N^2) of the N x N grid cut by (1, 1) diagonals."""
    x = np.linspace(0, width, N + 1)
    y = np.linspace(0, height, N + 1)
    p = np.vstack([np.repeat(x, N + 1), np.tile(y, N + 1)])
    ix = np.arange((N + 1) ** 2).reshape(N + 1, N + 1)  # ix[i, j] = node (i, j)
    ll, ul, ur, lr = (ix[:-1, :-1].ravel(), ix[:-1, 1:].ravel(), ix[1:, 1:].ravel(), ix[1:, :-1].ravel())
    t = np.hstack([np.vstack([ll, ul, ur]), np.vstack([ll, lr, ur])]).astype(np.int32)
    return p, t


def _label(points: np.ndarray) -> str:
    return " -> ".join(f"({x:g}, {y:g})" for x, y in points)


def structured_segment_nodes(N: int, width: float, height: float, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Grid node ids along the segment a -> b (both ends included, ordered from a to b).

    The ends must be grid nodes and consecutive nodes must be joined by grid edges (horizontal,
    vertical or (1, 1)-diagonal); otherwise InputError naming ``N`` and the defect.
    """
    hx, hy = width / N, height / N
    fa, fb = np.array([a[0] / hx, a[1] / hy]), np.array([b[0] / hx, b[1] / hy])
    ia, ib = np.rint(fa), np.rint(fb)
    tol = 1e-8 * min(width, height) / N / min(hx, hy)
    if np.abs(fa - ia).max() > tol or np.abs(fb - ib).max() > tol:
        raise InputError(f"N={N} cannot carry the defect {a.tolist()} -> {b.tolist()}: its ends must be "
                         f"mesh nodes (multiples of width/N, height/N); choose N so that they are")
    d = (ib - ia).astype(np.int64)
    k = int(np.abs(d).max())
    step = d // max(k, 1)
    if k == 0 or np.any(step * k != d) or not (tuple(np.abs(step)) in ((1, 0), (0, 1), (1, 1))
                                              and (step[0] * step[1] >= 0)):
        raise InputError(f"N={N} cannot carry the defect {a.tolist()} -> {b.tolist()}: it does not run "
                         f"along mesh edges (allowed directions: horizontal, vertical, diagonal (1, 1))")
    i = ia[0].astype(np.int64) + step[0] * np.arange(k + 1)
    j = ia[1].astype(np.int64) + step[1] * np.arange(k + 1)
    return i * (N + 1) + j


def structured_defect_nodes(N: int, width: float, height: float, points: np.ndarray) -> np.ndarray:
    """Ordered grid node ids along a polyline whose segments all run along grid edges."""
    parts = [structured_segment_nodes(N, width, height, points[k], points[k + 1]) for k in range(len(points) - 1)]
    nodes = np.concatenate([parts[0]] + [q[1:] for q in parts[1:]])
    if np.unique(nodes).size != nodes.size:
        raise InputError(f"defect {_label(points)} crosses or retraces itself on the N={N} grid")
    return nodes


def rotation(deg: float) -> np.ndarray:
    """The 2 x 2 matrix of a counter-clockwise rotation by ``deg`` degrees."""
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return np.array([[c, -s], [s, c]])


def rotate(points: np.ndarray, deg: float, center: np.ndarray) -> np.ndarray:
    """Points (2, n) rotated counter-clockwise by ``deg`` degrees about ``center`` (2,)."""
    if deg == 0:
        return points
    c = np.asarray(center, dtype=float)[:, None]
    return rotation(deg) @ (points - c) + c
