"""Mirror-symmetric meshes of a body whose defects are symmetric about the axis x = width/2.

gmsh meshes are not symmetric even for symmetric geometry, so a symmetric scene solved on a
:func:`dualfem.problems.gmsh_mesh.mesh_with_defects` mesh has a contact set that is symmetric only up to
the discretization. :func:`mesh_symmetric` meshes the left half (0, width/2) x (0, height) with
gmsh and mirrors it, so the mesh itself is symmetric: node ``mirror[i]`` is node i reflected
(x -> width - x, the same y), the nodes on the axis are their own images.

The defect set must be mirror-symmetric: each defect is either its own mirror image (a polyline
crossing the axis; its half ends on the axis, where the mesh gets a node) or has a partner
defect that is its mirror image (points in the same or reversed order, same curve type).
A spline crossing the axis is refused: its left half is not a gmsh spline of the given points.
"""
from __future__ import annotations

import numpy as np

from dualfem.errors import InputError

from ._defect_geometry import _TOL_REL, validate
from .gmsh_mesh import DefectMesh, _build, _extract, _import_gmsh, _session, _size_fields


def _mirror(P: np.ndarray, width: float) -> np.ndarray:
    """Points reflected about x = width/2, in reversed order."""
    return np.column_stack([width - P[::-1, 0], P[::-1, 1]])


def _roles(parsed, width: float, tol: float) -> list[tuple[str, int]]:
    """Per defect: ("self", i) if it is its own mirror image, ("left", i) if it is the left one
    of a mirror pair, ("right", j) if it is the mirror image of the left defect j."""
    roles: list[tuple[str, int]] = []
    for i, (P, curve) in enumerate(parsed):
        Q = _mirror(P, width)
        if np.abs(P - Q).max() <= tol:
            if curve == "spline" and len(P) > 2:
                raise InputError(f"defects[{i}] is a spline crossing the symmetry axis x = {width / 2:g}; "
                                 f"symmetric meshing supports only polylines across the axis")
            roles.append(("self", i))
            continue
        partners = [j for j, (R, c) in enumerate(parsed)
                    if j != i and c == curve and R.shape == P.shape
                    and min(np.abs(R - Q).max(), np.abs(R - Q[::-1]).max()) <= tol]
        if not partners:
            raise InputError(f"defects[{i}] has no mirror image about x = {width / 2:g}: symmetric meshing "
                             f"needs every defect to be symmetric itself or mirrored by another defect")
        left = P[:, 0].mean() < width / 2
        roles.append(("left", i) if left else ("right", partners[0]))
    return roles


def _half(P: np.ndarray, width: float) -> np.ndarray:
    """The left half of a self-symmetric polyline, ending exactly on the axis."""
    k = len(P)
    if k % 2:
        H = P[: k // 2 + 1].copy()
    else:
        H = np.vstack([P[: k // 2], 0.5 * (P[k // 2 - 1] + P[k // 2])])
    H[-1, 0] = width / 2
    return H


def mesh_symmetric(width: float, height: float, defects: list[dict], mesh_size: float,
                   tip_size: float | None = None) -> DefectMesh:
    """Like :func:`dualfem.problems.gmsh_mesh.mesh_with_defects`, but the mesh is exactly symmetric about
    x = width/2 (``DefectMesh.mirror`` gives each node's image); the defects must be symmetric."""
    parsed = validate(width, height, defects, mesh_size, tip_size)
    W, H = float(width), float(height)
    roles = _roles(parsed, W, _TOL_REL * max(W, H))
    halves: list[tuple[np.ndarray, str]] = []     # the defects of the left half
    where: dict[int, int] = {}                    # defect index -> its index in halves
    split: list[float] = []                       # heights where half-defects end on the axis
    for role, i in roles:
        if role in ("self", "left"):
            P, curve = parsed[i]
            where[i] = len(halves)
            halves.append((_half(P, W), curve) if role == "self" else (P, curve))
            if role == "self":
                split.append(float(halves[-1][0][-1, 1]))
    gmsh = _import_gmsh()
    with _session(gmsh):
        sides, surface, curves, tips = _build(gmsh, W / 2, H, halves, right_split=tuple(split))
        _size_fields(gmsh, float(mesh_size), None if tip_size is None else float(tip_size), tips)
        try:
            gmsh.model.mesh.generate(2)
        except Exception as exc:  # gmsh raises a bare Exception with its last error message
            raise RuntimeError(f"gmsh could not mesh the half body with its defects: {exc}") from exc
        half = _extract(gmsh, sides, surface, curves)
    return _assemble(half, W, parsed, roles, where)


def _assemble(half: DefectMesh, W: float, parsed, roles, where) -> DefectMesh:
    """The half mesh and its mirror image glued along the axis (the half's right side)."""
    nh = half.points.shape[1]
    off = np.ones(nh, dtype=bool)
    off[half.boundary["right"]] = False
    image = np.arange(nh, dtype=np.int64)
    image[off] = nh + np.arange(int(off.sum()), dtype=np.int64)
    points = np.hstack([half.points, np.vstack([W - half.points[0, off], half.points[1, off]])])
    triangles = np.hstack([half.triangles, image[half.triangles][[0, 2, 1]]])
    mirror = np.arange(points.shape[1], dtype=np.int64)
    mirror[:nh] = image
    mirror[image[off]] = np.flatnonzero(off)
    defect_nodes = []
    for (role, i), (P, _) in zip(roles, parsed, strict=True):
        c = half.defect_nodes[where[i]]
        if role == "left":
            defect_nodes.append(c)
        elif role == "self":
            defect_nodes.append(np.concatenate([c, image[c[::-1][1:]]]))
        else:
            m = image[c]
            same = np.abs(points[:, m[0]] - P[0]).max() <= np.abs(points[:, m[-1]] - P[0]).max()
            defect_nodes.append(m if same else m[::-1])
    boundary = {}
    for side in ("bottom", "top"):
        b = np.unique(np.concatenate([half.boundary[side], image[half.boundary[side]]]))
        boundary[side] = b[np.argsort(points[0, b], kind="stable")]
    boundary["left"] = half.boundary["left"]
    boundary["right"] = image[half.boundary["left"]]
    return DefectMesh(points, np.ascontiguousarray(triangles), defect_nodes, boundary, mirror)
