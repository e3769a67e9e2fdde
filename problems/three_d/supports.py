"""Default supports and load of a 3D scene: the bottom face z = 0 clamped, a traction on the top face z = height.

``load`` (times ``load_scale``, stress units, positive along +z = pulling the top face up):

* a number: the normal traction t_z, uniform;
* three numbers [t_x, t_y, t_z]: a uniform vector traction (a string "tx, ty, tz" too);
* ``"f1"``, ``"f2"``, ``"f3"``: the 2D scenes' loads as normal tractions, functions of x (f2 is -10
  on x < width / 2 and +10 beyond);
* an expression in ``x``, ``y`` (and ``z``): the normal traction (:mod:`dualfem.core.expressions`).

Nodal forces: the traction integrated against the P1 hat functions on the top face's triangles
with the 6-point, degree-4 rule of Strang and Fix (exact for a uniform traction).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dualfem.core.expressions import compile_expression
from dualfem.errors import InputError

Traction = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]

# Strang-Fix 6-point rule on the reference triangle (barycentric coordinates, weights summing to 1)
_A, _B = 0.445948490915965, 0.091576213509771
_WA, _WB = 0.223381589678011, 0.109951743655322
_BARY = np.array([[_A, _A, 1 - 2 * _A], [_A, 1 - 2 * _A, _A], [1 - 2 * _A, _A, _A],
                  [_B, _B, 1 - 2 * _B], [_B, 1 - 2 * _B, _B], [1 - 2 * _B, _B, _B]])
_W = np.array([_WA] * 3 + [_WB] * 3)


def _vector(text: str) -> list[float] | None:
    parts = [s for s in text.strip().strip("[]()").replace(";", ",").replace(" ", ",").split(",") if s]
    try:
        return [float(s) for s in parts]
    except ValueError:
        return None


def resolve_load(load, width: float) -> Traction:
    """The ``load`` scene key as a function (x, y) -> (t_x, t_y, t_z) on the top face; InputError otherwise."""
    form = "a number (normal traction), [tx, ty, tz], f1, f2, f3 or an expression in x, y"
    if isinstance(load, str):
        nums = _vector(load)
        if nums is not None and len(nums) in (1, 3):
            load = nums[0] if len(nums) == 1 else nums
    if isinstance(load, (bool, np.bool_)):
        raise InputError(f"load must be {form}, got {load!r}")
    if isinstance(load, (int, float)):
        v = float(load)
        if not np.isfinite(v):
            raise InputError(f"load must be finite, got {load!r}")
        return lambda x, y: (np.zeros_like(x), np.zeros_like(x), np.full_like(x, v))
    if isinstance(load, (list, tuple)):
        if len(load) != 3 or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in load) \
                or not np.all(np.isfinite(load)):
            raise InputError(f"load as a vector must be 3 finite numbers [tx, ty, tz], got {load!r}")
        tx, ty, tz = (float(c) for c in load)
        return lambda x, y: (np.full_like(x, tx), np.full_like(x, ty), np.full_like(x, tz))
    if not isinstance(load, str) or not load.strip():
        raise InputError(f"load must be {form}, got {load!r}")
    name = load.strip()
    paper = {"f1": lambda x: np.full_like(x, -3.0), "f3": lambda x: np.full_like(x, 3.0),
             "f2": lambda x: np.where(x < 0.5 * width, -10.0, 10.0)}
    if name in paper:
        f = paper[name]
        return lambda x, y: (np.zeros_like(x), np.zeros_like(x), f(x))
    g = compile_expression(name, parameter="load", variables=("x", "y"), hint=f"use {form}")
    return lambda x, y: (np.zeros_like(x), np.zeros_like(x), np.broadcast_to(g(x, y), x.shape))


def face_on(points: np.ndarray, faces: np.ndarray, axis: int, value: float, tol: float) -> np.ndarray:
    """The boundary faces (3, k) whose three nodes lie on the plane x_axis = value."""
    on = np.abs(points[axis] - value) <= tol
    return faces[:, on[faces].all(axis=0)]


def traction_forces(points: np.ndarray, faces: np.ndarray, g: Traction, scale: float) -> np.ndarray:
    """Nodal forces (3, n_nodes) of the traction ``scale * g(x, y)`` on the triangles ``faces`` (3, k)."""
    P = points[:, faces]                                                   # (3, 3, k)
    area = 0.5 * np.linalg.norm(np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T), axis=1)
    X = np.einsum("qa,cak->ckq", _BARY, P)                                 # (3, k, 6) quadrature points
    with np.errstate(all="ignore"):
        tr = g(X[0], X[1])
    F = np.zeros((3, points.shape[1]))
    for c in range(3):
        val = np.broadcast_to(np.asarray(tr[c], dtype=float), X[0].shape)
        if not np.all(np.isfinite(val)):
            raise InputError("load gives NaN or infinite values on the top face; it must be finite there")
        for a in range(3):
            np.add.at(F[c], faces[a], scale * area * (val * _W * _BARY[:, a]).sum(axis=1))
    return F
