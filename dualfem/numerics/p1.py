"""Geometry of P1 tetrahedra shared by the 3D assembly (problems/three_d) and the 3D post-processing."""
from __future__ import annotations

import numpy as np


def tet_gradients(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (4, 3, nt) of the four P1 hat functions of each tetrahedron (1 / length) and the signed
    volumes (nt,): positive for a positively oriented tetrahedron. The gradients do not depend on the
    orientation; a degenerate tetrahedron (volume 0) gives infinite gradients."""
    x = p[:, t]                                                      # (3, 4, nt)
    a, b, c = (x[:, k] - x[:, 0] for k in (1, 2, 3))                 # (3, nt)
    bc, ca, ab = np.cross(b, c, axis=0), np.cross(c, a, axis=0), np.cross(a, b, axis=0)
    det = (a * bc).sum(axis=0)
    g = np.empty((4, 3, t.shape[1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        g[1], g[2], g[3] = bc / det, ca / det, ab / det
    g[0] = -(g[1] + g[2] + g[3])
    return g, det / 6.0
