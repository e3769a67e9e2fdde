"""Triangle meshes of a rectangle with thin defects embedded as internal edges (gmsh).

Body: the rectangle (0, width) x (0, height). Each defect is a curve through ``k >= 2`` points:
``"polyline"`` (straight segments; the points are kinks) or ``"spline"`` (gmsh's Catmull-Rom
spline through the points: uniform parameter, end tangents from the reflected neighbour
``2 P0 - P1``; :func:`sample_defect` evaluates the same curve in numpy). The curves are embedded
in the 2D mesh (``gmsh.model.mesh.embed``), so the mesh conforms to them: consecutive defect
nodes are joined by a triangle edge. All defect points of a polyline are mesh nodes; for a
spline only its two ends are (the interior points are control points of the curve). Optional
refinement toward the tips: element size ``tip_size`` within ``tip_size`` of a tip, growing
linearly (slope ``size_growth``, default ``GRADE`` = 0.3) to ``mesh_size``; a ``tip_size >= mesh_size``
asks for nothing finer
than the uniform mesh (no refinement: ``tip_size`` follows ``mesh_size``, :func:`effective_tip_size`).

Before meshing the geometry is checked in numpy (:func:`validate`, in
:mod:`dualfem.problems._defect_geometry` with the curves and the size estimate, re-exported here): every
defect strictly inside the body, no self-intersection, no two defects crossing or touching, and the
estimated triangle count below ``MAX_TRIANGLES``. Problems raise :class:`dualfem.errors.InputError`
naming the defects as ``defects[i]`` (counted from 0, as in the ``[[defects]]`` list of a scene file).

gmsh is optional (``pip install 'dualfem[gmsh]'``) and imported only when meshing. It runs
single-threaded with fixed options and prints nothing, so the same input gives identical
arrays.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from dualfem.errors import InputError, MissingDependency

from ._defect_geometry import (  # noqa: F401  (the checks before meshing; public here too)
    CURVES,
    GRADE,
    GRADE_RANGE,
    MAX_SAMPLES,
    MAX_TRIANGLES,
    SAMPLES_PER_SPAN,
    _tip_distances,
    check_growth,
    check_size,
    effective_tip_size,
    estimate_triangles,
    rotate,
    sample_defect,
    validate,
)
from ._segments import closest, near_segment_pairs, segment_distances  # noqa: F401  (public here too)

SIDES = ("bottom", "top", "left", "right")
_OPTIONS = {                   # fixed gmsh options (reproducible, silent, first order, one thread)
    "General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1,
    "Mesh.MaxNumThreads1D": 1, "Mesh.MaxNumThreads2D": 1, "Mesh.RandomSeed": 1,
    "Mesh.Algorithm": 6, "Mesh.ElementOrder": 1, "Mesh.RecombineAll": 0, "Mesh.Smoothing": 1,
    "Mesh.MinimumCurveNodes": 3, "Mesh.MeshSizeFromPoints": 0, "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeMin": 0.0,
}

#: gmsh options per 2D algorithm (over _OPTIONS). "frontal": Frontal-Delaunay with one smoothing pass (the
#: meshes of the scene files and tests). "frontal_unsmoothed": the same without smoothing (the fractured
#: problem's, at 2 h then refined). "delaunay": gmsh's Delaunay without smoothing (it refines until every
#: circumradius <= h / sqrt 2). Their times and element qualities: docs/measurements.md
ALGORITHMS: dict[str, dict[str, float]] = {
    "frontal": {"Mesh.Algorithm": 6, "Mesh.Smoothing": 1},
    "frontal_unsmoothed": {"Mesh.Algorithm": 6, "Mesh.Smoothing": 0},
    "delaunay": {"Mesh.Algorithm": 5, "Mesh.Smoothing": 0},
}


@dataclass
class DefectMesh:
    """A conforming triangle mesh of the body with its defects.

    ``points`` (2, n) node coordinates; ``triangles`` (3, nt) node indices, counter-clockwise;
    ``defect_nodes[i]`` the nodes along defect i from its first given point to its last (tips
    and kinks included); ``boundary[side]`` for side in bottom, top, left, right: the nodes on
    that side (corners included), bottom/top ordered by x, left/right by y. ``mirror`` (only for
    :func:`dualfem.problems.gmsh_symmetric.mesh_symmetric`): node i's mirror image about x = width/2 is
    node ``mirror[i]``.
    """

    points: np.ndarray
    triangles: np.ndarray
    defect_nodes: list[np.ndarray]
    boundary: dict[str, np.ndarray] = field(default_factory=dict)
    mirror: np.ndarray | None = None


# --------------------------------------------------------------------------- gmsh
def _import_gmsh():
    try:
        import gmsh
    except ImportError:
        raise MissingDependency("meshing defects of any shape needs gmsh: pip install 'dualfem[gmsh]'") from None
    return gmsh


@contextmanager
def _session(gmsh, options: dict[str, float] | None = None) -> Iterator[None]:
    """A fresh gmsh model with the fixed options (``options`` replacing some of them); gmsh is finalized
    (or, if the caller had it initialized already, the model removed and the options restored) whatever
    happens."""
    owner = not gmsh.isInitialized()
    if owner:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    saved: dict[str, float] = {}
    previous = None if owner else gmsh.model.getCurrent()
    try:
        for name, value in {**_OPTIONS, **(options or {})}.items():
            saved[name] = gmsh.option.getNumber(name)
            gmsh.option.setNumber(name, value)
        gmsh.model.add("dualfem_defects")
        yield
    finally:
        if owner:
            gmsh.finalize()
        else:
            gmsh.model.remove()
            for name, value in saved.items():
                gmsh.option.setNumber(name, value)
            if previous:
                gmsh.model.setCurrent(previous)


_Built = tuple[dict[str, list[int]], int, list[tuple[list[int], int]], list[int]]


def _build(gmsh, width: float, height: float, parsed, right_split: tuple[float, ...] = ()) -> _Built:
    """Rectangle, defect curves embedded in it. Returns the side curve tags, the surface tag,
    per defect (its curve tags in order, its start point tag), and the tip point tags.

    ``right_split``: heights (strictly between 0 and height) of extra points on the right side
    x = width; a defect point exactly there ends on the side (it is no tip) and shares the point."""
    geo = gmsh.model.geo
    on_right = {float(y): geo.addPoint(width, float(y), 0.0) for y in sorted(right_split)}
    corners = [geo.addPoint(x, y, 0.0) for x, y in ((0, 0), (width, 0), (width, height), (0, height))]
    right_pts = [corners[1], *on_right.values(), corners[2]]
    sides = {"bottom": [geo.addLine(corners[0], corners[1])],
             "right": [geo.addLine(a, b) for a, b in zip(right_pts[:-1], right_pts[1:], strict=True)],
             "top": [geo.addLine(corners[2], corners[3])],
             "left": [geo.addLine(corners[3], corners[0])]}
    surface = geo.addPlaneSurface([geo.addCurveLoop([t for side in sides.values() for t in side])])
    curves, tips = [], []
    for P, curve in parsed:
        pts = [on_right[float(y)] if x == width and float(y) in on_right else geo.addPoint(float(x), float(y), 0.0)
               for x, y in P]
        if curve == "spline" and len(P) > 2:
            tags = [geo.addSpline(pts)]
        else:
            tags = [geo.addLine(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)]
        curves.append((tags, pts[0]))
        tips += [t for t in (pts[0], pts[-1]) if t not in on_right.values()]
    geo.synchronize()
    all_curves = [t for tags, _ in curves for t in tags]
    if all_curves:
        gmsh.model.mesh.embed(1, all_curves, 2, surface)
    return sides, surface, curves, tips


def background_sizes(gmsh, view: tuple[np.ndarray, np.ndarray, np.ndarray], scale: float = 1.0) -> int:
    """A gmsh post-processing view of a per-element size (``view`` = (points (dim, n), cells (3 or 4, nc),
    sizes (nc,)): list data "ST" on triangles, "SS" on tetrahedra, the size constant on each), coordinates and
    sizes times ``scale``, set as the background mesh (a ``PostView`` field); its tag."""
    pts, cells, sizes = (np.asarray(a) for a in view)
    cells = cells.astype(np.int64)
    nv, nc = cells.shape
    xyz = np.zeros((3, nv, nc))
    xyz[:pts.shape[0]] = pts[:, cells] * scale                            # (3, nv, nc)
    data = np.concatenate([xyz[0].T, xyz[1].T, xyz[2].T,
                           np.repeat(np.asarray(sizes, float)[:, None] * scale, nv, axis=1)], axis=1)
    tag = gmsh.view.add("dualfem_size")
    gmsh.view.addListData(tag, "ST" if nv == 3 else "SS", nc, data.ravel().tolist())
    fld = gmsh.model.mesh.field
    f = fld.add("PostView")
    fld.setNumber(f, "ViewTag", tag)
    fld.setAsBackgroundMesh(f)
    return tag


def _size_fields(gmsh, mesh_size: float, tip_size: float | None, tips: list[int], coarsen: float = 1.0,
                 grade: float = GRADE) -> None:
    """Element size mesh_size, tip_size near the tips growing with slope ``grade``; every size times
    ``coarsen`` (a mesh to be refined uniformly afterwards), the distances of the tips' refinement those of
    the final sizes."""
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size * coarsen)
    if tip_size is None or tip_size >= mesh_size or not tips:
        return
    d_min, d_max = _tip_distances(mesh_size, tip_size, grade)
    fld = gmsh.model.mesh.field
    dist = fld.add("Distance")
    fld.setNumbers(dist, "PointsList", tips)
    thr = fld.add("Threshold")
    fld.setNumber(thr, "InField", dist)
    fld.setNumber(thr, "SizeMin", tip_size * coarsen)
    fld.setNumber(thr, "SizeMax", mesh_size * coarsen)
    fld.setNumber(thr, "DistMin", d_min)
    fld.setNumber(thr, "DistMax", d_max)
    fld.setAsBackgroundMesh(thr)


def _chain(gmsh, curve_tags: list[int], start_point: int) -> np.ndarray:
    """gmsh node tags along consecutive curves, walking their line elements from start_point."""
    node = int(gmsh.model.mesh.getNodes(0, start_point)[0][0])
    out = [node]
    for tag in curve_tags:
        _, conn = gmsh.model.mesh.getElementsByType(1, tag)
        edges = np.asarray(conn, dtype=np.int64).reshape(-1, 2)
        nbr: dict[int, list[int]] = {}
        for a, b in edges.tolist():
            nbr.setdefault(a, []).append(b)
            nbr.setdefault(b, []).append(a)
        prev = -1
        for _ in range(len(edges)):
            nxt = [v for v in nbr.get(node, []) if v != prev]
            if len(nxt) != 1:
                raise RuntimeError(f"gmsh mesh of curve {tag} is not a simple chain at node {node}")
            prev, node = node, nxt[0]
            out.append(node)
    return np.asarray(out, dtype=np.int64)


def _extract(gmsh, sides, surface, curves) -> DefectMesh:
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, dtype=np.int64)
    xy = np.asarray(coords, dtype=float).reshape(-1, 3)[:, :2]
    _, conn = gmsh.model.mesh.getElementsByType(2, surface)
    tri_tags = np.asarray(conn, dtype=np.int64).reshape(-1, 3)
    mask = np.zeros(max(int(tags.max()), int(tri_tags.max())) + 1, dtype=bool)
    mask[tri_tags.ravel()] = True
    used = np.flatnonzero(mask)                   # = np.unique(tri_tags), without its sort; drops free (control) points
    pos = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    pos[tags] = np.arange(len(tags))
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    points = np.ascontiguousarray(xy[pos[used]].T)
    tri = index[tri_tags]
    p = points[:, tri]                            # (2, nt, 3)
    area2 = ((p[0, :, 1] - p[0, :, 0]) * (p[1, :, 2] - p[1, :, 0])
             - (p[0, :, 2] - p[0, :, 0]) * (p[1, :, 1] - p[1, :, 0]))
    tri[area2 < 0] = tri[area2 < 0][:, [0, 2, 1]]
    defect_nodes = [index[_chain(gmsh, ct, start)] for ct, start in curves]
    boundary = {}
    for side, side_tags in sides.items():
        b = np.unique(np.concatenate([gmsh.model.mesh.getNodes(1, t, includeBoundary=True)[0] for t in side_tags]))
        b = index[b.astype(np.int64)]
        axis = 0 if side in ("bottom", "top") else 1
        boundary[side] = b[np.argsort(points[axis, b], kind="stable")]
    if any((d < 0).any() for d in defect_nodes) or any((b < 0).any() for b in boundary.values()):
        raise RuntimeError("gmsh left a defect or boundary node outside the triangle mesh")
    return DefectMesh(points, np.ascontiguousarray(tri.T), defect_nodes,
                      {s: boundary[s] for s in SIDES})


def refine_uniformly(dm: DefectMesh) -> DefectMesh:
    """Every triangle split into four by its edges' midpoints (the new nodes numbered after the old ones,
    in the order of the sorted edge keys), every defect chain and boundary side with the midpoints of
    its edges inserted: a conforming mesh of elements half the size and of the same shapes.
    Counter-clockwise triangles stay counter-clockwise; ``mirror`` is dropped."""
    P, t = dm.points, np.asarray(dm.triangles, dtype=np.int64)
    n = P.shape[1]
    e = np.concatenate([t[[0, 1]], t[[1, 2]], t[[2, 0]]], axis=1)           # (2, 3 nt): edges ab, bc, ca
    keys = np.minimum(e[0], e[1]) * n + np.maximum(e[0], e[1])
    uniq, inverse = np.unique(keys, return_inverse=True)
    mid = (n + inverse).reshape(3, -1)                                       # ab, bc, ca per triangle
    a, b = uniq // n, uniq % n
    points = np.hstack([P, 0.5 * (P[:, a] + P[:, b])])

    def mids(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        k = np.minimum(u, v) * n + np.maximum(u, v)
        pos = np.searchsorted(uniq, k)
        if np.any(pos >= uniq.size) or np.any(uniq[np.minimum(pos, uniq.size - 1)] != k):
            raise RuntimeError("refine_uniformly: a defect or boundary edge is not a mesh edge")
        return n + pos

    def split(chain: np.ndarray) -> np.ndarray:
        chain = np.asarray(chain, dtype=np.int64)
        out = np.empty(2 * chain.size - 1, dtype=np.int64)
        out[0::2] = chain
        out[1::2] = mids(chain[:-1], chain[1:])
        return out

    ab, bc, ca = mid
    tri = np.hstack([np.vstack([t[0], ab, ca]), np.vstack([ab, t[1], bc]), np.vstack([ca, bc, t[2]]),
                     np.vstack([ab, bc, ca])])
    boundary = {side: split(nodes) for side, nodes in dm.boundary.items()}   # sorted along the side: edges
    return DefectMesh(points, np.ascontiguousarray(tri.astype(dm.triangles.dtype)),
                      [split(d) for d in dm.defect_nodes], boundary)


def mesh_with_defects(width: float, height: float, defects: list[dict], mesh_size: float,
                      tip_size: float | None = None, algorithm: str = "frontal", refine: int = 0,
                      max_samples: int = MAX_SAMPLES, size_growth: float = GRADE,
                      size_view: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> DefectMesh:
    """Mesh (0, width) x (0, height) with first-order triangles of size about ``mesh_size``
    (``tip_size`` near the defect tips), the defects embedded as internal edges.

    ``defects``: tables ``{"points": (k, 2), "curve": "polyline" | "spline"}`` (other keys are
    ignored). ``algorithm``: a key of :data:`ALGORITHMS` (``"frontal"``, the default: the meshes of
    every scene file; see there for the others). ``refine`` = r > 0: mesh with sizes 2^r times larger,
    then split every triangle into four r times (:func:`refine_uniformly`: the defect and boundary
    edges in two): elements of about the same size, of the coarse mesh's shapes, in a fraction of the
    time (:data:`ALGORITHMS`); polyline defects only (a spline's new nodes would be chord midpoints).
    ``max_samples``: see :func:`validate`. ``size_growth``: the slope of the element size away from a
    tip (size per unit distance, in :data:`GRADE_RANGE`; :func:`check_growth`). ``size_view``:
    (points (2, n), triangles (3, nt), sizes (nt,)) a per-triangle element size on any triangulation of the
    body (an earlier mesh: adaptive refinement, :mod:`dualfem.problems.adaptive`), used by gmsh as its
    background mesh in place of ``tip_size`` (sizes above ``mesh_size`` are cut to it).
    Raises InputError on bad input (see :func:`validate`), MissingDependency without gmsh.
    """
    if algorithm not in ALGORITHMS:
        raise InputError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {algorithm!r}")
    if refine not in (0, 1, 2, 3) or (refine and any(d.get("curve", "polyline") == "spline"
                                                     and len(d.get("points", ())) > 2 for d in defects)):
        raise InputError(f"refine must be 0, 1, 2 or 3 (and 0 with spline defects), got {refine!r}")
    parsed = validate(width, height, defects, mesh_size, tip_size, max_samples, size_growth)
    gmsh = _import_gmsh()
    # gmsh meshes the body scaled to max(width, height) = 1 (its tolerances are absolute), so a
    # scene in other length units gets the same mesh, scaled; a unit-size body is meshed as given
    L = float(max(width, height))
    parsed = [(np.asarray(P, dtype=float) / L, curve) for P, curve in parsed]
    with _session(gmsh, ALGORITHMS[algorithm]):
        sides, surface, curves, tips = _build(gmsh, float(width) / L, float(height) / L, parsed)
        view = None
        if size_view is None:
            _size_fields(gmsh, float(mesh_size) / L, None if tip_size is None else float(tip_size) / L, tips,
                         2.0 ** refine, size_growth)
        else:
            gmsh.option.setNumber("Mesh.MeshSizeMax", float(mesh_size) / L * 2.0 ** refine)
            view = background_sizes(gmsh, size_view, 2.0 ** refine / L)
        try:
            gmsh.model.mesh.generate(2)
        except Exception as exc:  # gmsh raises a bare Exception with its last error message
            raise RuntimeError(f"gmsh could not mesh the body with its defects: {exc}") from exc
        dm = _extract(gmsh, sides, surface, curves)
        if view is not None:
            gmsh.view.remove(view)
    for _ in range(refine):
        dm = refine_uniformly(dm)
    dm.points = dm.points * L
    return dm
