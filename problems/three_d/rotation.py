"""Rigid rotations of a 3D scene (``rotate_deg`` about ``rotate_axis``)."""
from __future__ import annotations

import math

import numpy as np


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """The 3 x 3 rotation by ``angle_deg`` degrees about ``axis`` (any non-zero length), counter-clockwise
    seen from the axis' tip (right-hand rule); Rodrigues' formula. The identity for angle 0."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    a = math.radians(float(angle_deg))
    if a == 0.0:
        return np.eye(3)
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(a) * Kx + (1.0 - math.cos(a)) * (Kx @ Kx)
