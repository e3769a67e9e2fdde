"""Triangle meshes of a rectangle with thin defects embedded as internal edges (gmsh).

Body: the rectangle (0, width) x (0, height). Each defect is a curve through ``k >= 2`` points:
``"polyline"`` (straight segments; the points are kinks) or ``"spline"`` (gmsh's Catmull-Rom
spline through the points: uniform parameter, end tangents from the reflected neighbour
``2 P0 - P1``; :func:`sample_defect` evaluates the same curve in numpy). The curves are embedded
in the 2D mesh (``gmsh.model.mesh.embed``), so the mesh conforms to them: consecutive defect
nodes are joined by a triangle edge. All defect points of a polyline are mesh nodes; for a
spline only its two ends are (the interior points are control points of the curve). Optional
refinement toward the tips: element size ``tip_size`` within ``tip_size`` of a tip, growing
linearly (slope ``_GRADE``) to ``mesh_size``; a ``tip_size >= mesh_size`` asks for nothing finer
than the uniform mesh (no refinement: ``tip_size`` follows ``mesh_size``, :func:`effective_tip_size`).

Before meshing the geometry is checked in numpy (splines on 64 samples per span): every
defect strictly inside the body, no self-intersection, no two defects crossing or touching
(distance > ``_TOL_REL * max(width, height)``), and the estimated triangle count below
``MAX_TRIANGLES``. Problems raise :class:`dualfem.errors.InputError` naming the defects as
``defects[i]`` (counted from 0, as in the ``[[defects]]`` list of a scene file).

gmsh is optional (``pip install 'dualfem[gmsh]'``) and imported only when meshing. It runs
single-threaded with fixed options and prints nothing, so the same input gives identical
arrays.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualfem.errors import InputError, MissingDependency, check_positive

from ._segments import closest, near_segment_pairs, segment_distances  # noqa: F401  (public here too)

CURVES = ("polyline", "spline")
SIDES = ("bottom", "top", "left", "right")
MAX_TRIANGLES = 5_000_000
#: defect points checked for crossings and self-intersection (a polyline counts its points, a spline
#: SAMPLES_PER_SPAN per span); the default of ``max_samples`` in :func:`validate`. Crossings between
#: defects are found on a spatial grid (near-linear cost), a self-intersection of one defect pairwise
MAX_SAMPLES = 2048
SAMPLES_PER_SPAN = 64          # spline samples per span between two given points (validation only)
_TOL_REL = 1e-9                # "touching" tolerance, relative to max(width, height)
_GRADE = 0.3                   # growth of the element size per unit distance away from a tip
_TRI_PER_AREA = 4 / math.sqrt(3)   # triangles per h^2 of area for equilateral triangles of side h
_OPTIONS = {                   # fixed gmsh options (reproducible, silent, first order, one thread)
    "General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1,
    "Mesh.MaxNumThreads1D": 1, "Mesh.MaxNumThreads2D": 1, "Mesh.RandomSeed": 1,
    "Mesh.Algorithm": 6, "Mesh.ElementOrder": 1, "Mesh.RecombineAll": 0, "Mesh.Smoothing": 1,
    "Mesh.MinimumCurveNodes": 3, "Mesh.MeshSizeFromPoints": 0, "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeMin": 0.0,
}

#: gmsh options per 2D algorithm (over _OPTIONS). "frontal": Frontal-Delaunay with one smoothing pass (the
#: meshes of the scene files and tests). "delaunay": gmsh's Delaunay without smoothing. Measured on the
#: 400-crack scene (unit square, mesh_size 0.003, 2 cores shared with other jobs, generate only):
#: frontal 5.2-7.2 s (262 k triangles, gamma >= 0.65), frontal without smoothing 4.8-5.2 s, delaunay
#: 3.3-4.2 s (295 k triangles: it refines until every circumradius <= h / sqrt 2; gamma >= 0.47, mean
#: 0.91), "frontal-quad" (8) 6.3 s, BAMG (7) 23 s with slivers (gamma 0). Meshing at 2 h and splitting
#: every triangle in four (mesh_with_defects's refine=1, what the fractured problem does; the split by
#: refine_uniformly takes 0.02-0.04 s, gmsh's own refine 0.5-1.0 s): frontal 1.1-1.9 s (275 k triangles,
#: gamma >= 0.62, mean 0.98), frontal_unsmoothed 0.7 s (gamma >= 0.44, mean 0.976), delaunay 0.55 s
#: (302 k triangles); refine=2: frontal 0.25 s but 328 k triangles (the cracks force small elements at 4 h)
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


# --------------------------------------------------------------------------- geometry helpers
def rotate(points: np.ndarray, angle_deg: float, center) -> np.ndarray:
    """Rotate coordinates ``points`` of shape (2, n) by ``angle_deg`` degrees (counter-clockwise
    positive) about ``center`` = (cx, cy). Pass defect points of shape (k, 2) as ``pts.T``."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[0] != 2:
        raise InputError(f"rotate expects coordinates of shape (2, n), got shape {p.shape}")
    a = math.radians(float(angle_deg))
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    c = np.asarray(center, dtype=float).reshape(2, 1)
    return R @ (p - c) + c


def sample_defect(points: np.ndarray, curve: str, per_span: int = SAMPLES_PER_SPAN) -> np.ndarray:
    """Points (m, 2) along a defect: the given points for a polyline; for a spline
    ``per_span`` samples per span of gmsh's uniform Catmull-Rom curve (ends included)."""
    P = np.asarray(points, dtype=float)
    if curve == "polyline" or len(P) == 2:
        return P.copy()
    n = len(P) - 1
    ext = np.vstack([2 * P[0] - P[1], P, 2 * P[-1] - P[-2]])
    s = np.linspace(0.0, n, n * per_span + 1)
    i = np.minimum(s.astype(int), n - 1)
    t = (s - i)[:, None]
    p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
    return 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                  + (3 * p1 - p0 - 3 * p2 + p3) * t ** 3)


def _fmt(p) -> str:
    return f"({float(p[0]):.6g}, {float(p[1]):.6g})"


# --------------------------------------------------------------------------- validation
def _check_defect(i: int, d: Any) -> tuple[np.ndarray, str]:
    """One defect's points (k, 2) and curve type; InputError naming ``defects[i]`` otherwise."""
    if not isinstance(d, dict) or "points" not in d:
        raise InputError(f"defects[{i}] must be a table with 'points' (k >= 2 points [x, y]) and "
                         f"'curve' ({' or '.join(CURVES)}), got {d!r}")
    curve = d.get("curve", "polyline")
    if curve not in CURVES:
        raise InputError(f"defects[{i}]: curve must be {' or '.join(repr(c) for c in CURVES)}, got {curve!r}")
    try:
        P = np.array(d["points"], dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"defects[{i}]: points must be a list of [x, y] numbers, got {d['points']!r}") from None
    if P.ndim != 2 or P.shape[1] != 2 or P.shape[0] < 2:
        raise InputError(f"defects[{i}]: points must be k >= 2 points [x, y], got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise InputError(f"defects[{i}]: points must be finite numbers, got {d['points']!r}")
    return P, curve


def _check_one(i: int, P: np.ndarray, S: np.ndarray, width: float, height: float, tol: float) -> None:
    """Distinct points, inside the body, no self-intersection (S: the sampled curve)."""
    gaps = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    if gaps.min() <= tol:
        a, b = sorted(np.unravel_index(np.argmin(gaps), gaps.shape))
        raise InputError(f"defects[{i}]: points {a} and {b} coincide at {_fmt(P[a])}; the points must be distinct")
    margin = np.minimum.reduce([S[:, 0], width - S[:, 0], S[:, 1], height - S[:, 1]])
    if margin.min() <= tol:
        j = int(np.argmin(margin))
        what = "point" if len(S) == len(P) else "curve point"
        raise InputError(f"defects[{i}]: {what} {_fmt(S[j])} is not strictly inside the body "
                         f"(0, {width:g}) x (0, {height:g})")
    seg = np.diff(S, axis=0)
    if len(seg) >= 2:       # adjacent segments folding back onto each other
        c = seg[:-1, 0] * seg[1:, 1] - seg[:-1, 1] * seg[1:, 0]
        dot = (seg[:-1] * seg[1:]).sum(-1)
        norms = np.linalg.norm(seg[:-1], axis=1) * np.linalg.norm(seg[1:], axis=1)
        fold = np.flatnonzero((np.abs(c) <= 1e-12 * norms) & (dot < 0))
        if len(fold):
            raise InputError(f"defects[{i}] intersects itself: it folds back on itself at {_fmt(S[fold[0] + 1])}")
    if len(seg) >= 3:
        idx = np.arange(len(seg))
        mask = idx[None, :] >= idx[:, None] + 2          # non-adjacent pairs only
        dist, _, where = closest(S, S, mask)
        if dist <= tol:
            raise InputError(f"defects[{i}] intersects itself near {_fmt(where)}")


def estimate_triangles(width: float, height: float, mesh_size: float, tip_size: float | None, n_tips: int) -> int:
    """Rough triangle count: equilateral triangles of the local size, tips' discs added.

    Overflow-safe: a tiny size gives a huge count (capped at 1e30), never an exception."""
    with np.errstate(all="ignore"):
        count = _TRI_PER_AREA * (float(width) / mesh_size) * (float(height) / mesh_size)
        if tip_size is not None and tip_size < mesh_size:
            d_min, d_max = _tip_distances(mesh_size, tip_size)
            r = np.linspace(d_min, d_max, 401)
            size = tip_size + (mesh_size - tip_size) * (r - d_min) / (d_max - d_min)
            f = 2 * np.pi * r * (1 / size ** 2 - 1 / mesh_size ** 2)
            ring = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(r)))
            disc = float(np.pi * d_min ** 2 * (1 / np.float64(tip_size) ** 2 - 1 / np.float64(mesh_size) ** 2))
            count += n_tips * _TRI_PER_AREA * (ring + disc)
    if not count < 1e30:          # inf or NaN from an overflow: as large as we count
        count = 1e30
    return int(math.ceil(count))


def check_size(width: float, height: float, mesh_size: float, tip_size: float | None, n_tips: int,
               label: str = "") -> int:
    """The estimated triangle count; InputError naming mesh_size (or tip_size) and its allowed range
    when it exceeds :data:`MAX_TRIANGLES`, before anything is meshed. ``label`` says where mesh_size
    comes from (e.g. "mesh_size = 0: min(width, height)/N = 0.0156")."""
    est = estimate_triangles(width, height, mesh_size, tip_size, n_tips)
    if est <= MAX_TRIANGLES:
        return est
    top = min(width, height)
    lo = math.sqrt(_TRI_PER_AREA * width * height / MAX_TRIANGLES)      # mesh_size alone
    what = label or f"mesh_size={mesh_size:g}"
    body = f"the {width:g} x {height:g} body"
    n = f"{est:,}" if est < 1e15 else f"{est:.3g}"
    if lo > top:
        raise InputError(f"width={width:g}, height={height:g}: {body} needs about {n} triangles with {what} "
                         f"and at least {_TRI_PER_AREA * width * height / top ** 2:.3g} with any mesh_size <= "
                         f"min(width, height) (limit {MAX_TRIANGLES:,}): its aspect ratio max/min must be <= "
                         f"{MAX_TRIANGLES / _TRI_PER_AREA:.3g}")
    if estimate_triangles(width, height, mesh_size, None, 0) > MAX_TRIANGLES:
        raise InputError(f"{what} gives about {n} triangles (limit {MAX_TRIANGLES:,}) on {body}: "
                         f"mesh_size must be in [{lo:.3g}, {top:g}]")
    # the tips' refinement is what makes it too big: the smallest tip_size that fits (count falls with it)
    a, b = math.log(tip_size or mesh_size), math.log(mesh_size)
    for _ in range(60):
        mid = 0.5 * (a + b)
        if estimate_triangles(width, height, mesh_size, math.exp(mid), n_tips) > MAX_TRIANGLES:
            a = mid
        else:
            b = mid
    raise InputError(f"{what}, tip_size={tip_size:g} gives about {n} triangles (limit {MAX_TRIANGLES:,}) on "
                     f"{body}: tip_size must be in [{math.exp(b):.3g}, {mesh_size:g}]")


def _tip_distances(mesh_size: float, tip_size: float) -> tuple[float, float]:
    """Threshold distances: size tip_size up to DistMin, linear growth to mesh_size at DistMax."""
    d_min = tip_size
    return d_min, d_min + (mesh_size - tip_size) / _GRADE


def effective_tip_size(mesh_size: float, tip_size: float | None) -> float | None:
    """The element size near the tips: ``tip_size`` when it is below ``mesh_size``; else None (no
    refinement: the uniform ``mesh_size`` already meets the bound ``tip_size``, so a default
    ``tip_size`` follows a smaller ``mesh_size``)."""
    return tip_size if tip_size is not None and tip_size < mesh_size else None


def validate(width: float, height: float, defects: list[dict], mesh_size: float,
             tip_size: float | None = None, max_samples: int = MAX_SAMPLES) -> list[tuple[np.ndarray, str]]:
    """Check all inputs of :func:`mesh_with_defects` (no gmsh needed); return [(points, curve)].

    ``max_samples``: the most curve points accepted (see :data:`MAX_SAMPLES`)."""
    width, height = check_positive("width", width), check_positive("height", height)
    mesh_size = check_positive("mesh_size", mesh_size)
    if mesh_size > min(width, height):
        raise InputError(f"mesh_size must be in (0, min(width, height)] = (0, {min(width, height):g}], "
                         f"got {mesh_size:g}")
    if tip_size is not None:
        tip_size = effective_tip_size(mesh_size, check_positive("tip_size", tip_size))
    if not isinstance(defects, (list, tuple)):
        raise InputError(f"defects must be a list of tables {{points, curve}}, got {type(defects).__name__}")
    check_size(width, height, mesh_size, tip_size, 2 * len(defects))
    tol = _TOL_REL * max(width, height)
    parsed = [_check_defect(i, d) for i, d in enumerate(defects)]
    counts = [len(P) if c == "polyline" or len(P) == 2 else (len(P) - 1) * SAMPLES_PER_SPAN + 1 for P, c in parsed]
    if sum(counts) > max_samples:
        raise InputError(f"defects: {len(parsed)} defects with {sum(len(P) for P, _ in parsed)} points give "
                         f"{sum(counts):,} curve points to check for crossings (a spline counts {SAMPLES_PER_SPAN} "
                         f"per span); the limit is {max_samples:,}: use fewer points (a spline needs few)")
    samples = [sample_defect(P, c) for P, c in parsed]
    for i, (P, _) in enumerate(parsed):
        _check_one(i, P, samples[i], width, height, tol)
    if len(samples) > 1:
        # segments of different defects closer than tol (a spatial grid: no all-pairs loop); the first pair
        # of defects (i, j) in order that crosses or touches is reported
        seg = np.concatenate([np.stack([S[:-1], S[1:]], axis=1) for S in samples])
        owner = np.repeat(np.arange(len(samples)), [len(S) - 1 for S in samples])
        a, b, _ = near_segment_pairs(seg, None, tol)
        da, db = owner[a], owner[b]
        other = da != db
        if other.any():
            lo_, hi_ = np.minimum(da, db)[other], np.maximum(da, db)[other]
            k = np.lexsort((hi_, lo_))[0]
            i, j = int(lo_[k]), int(hi_[k])
            dist, crossing, where = closest(samples[i], samples[j])
            if crossing:
                raise InputError(f"defects[{i}] and defects[{j}] cross near {_fmt(where)}")
            raise InputError(f"defects[{i}] and defects[{j}] touch near {_fmt(where)} "
                             f"(distance {dist:.3g}); defects must be disjoint")
    return parsed


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


def _size_fields(gmsh, mesh_size: float, tip_size: float | None, tips: list[int], coarsen: float = 1.0) -> None:
    """Element size mesh_size, tip_size near the tips; every size times ``coarsen`` (a mesh to be refined
    uniformly afterwards), the distances of the tips' refinement those of the final sizes."""
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size * coarsen)
    if tip_size is None or tip_size >= mesh_size or not tips:
        return
    d_min, d_max = _tip_distances(mesh_size, tip_size)
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
                      max_samples: int = MAX_SAMPLES) -> DefectMesh:
    """Mesh (0, width) x (0, height) with first-order triangles of size about ``mesh_size``
    (``tip_size`` near the defect tips), the defects embedded as internal edges.

    ``defects``: tables ``{"points": (k, 2), "curve": "polyline" | "spline"}`` (other keys are
    ignored). ``algorithm``: a key of :data:`ALGORITHMS` (``"frontal"``, the default: the meshes of
    every scene file; see there for the others). ``refine`` = r > 0: mesh with sizes 2^r times larger,
    then split every triangle into four r times (:func:`refine_uniformly`: the defect and boundary
    edges in two): elements of about the same size, of the coarse mesh's shapes, in a fraction of the
    time (:data:`ALGORITHMS`); polyline defects only (a spline's new nodes would be chord midpoints).
    ``max_samples``: see :func:`validate`.
    Raises InputError on bad input (see :func:`validate`), MissingDependency without gmsh.
    """
    if algorithm not in ALGORITHMS:
        raise InputError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {algorithm!r}")
    if refine not in (0, 1, 2, 3) or (refine and any(d.get("curve", "polyline") == "spline"
                                                     and len(d.get("points", ())) > 2 for d in defects)):
        raise InputError(f"refine must be 0, 1, 2 or 3 (and 0 with spline defects), got {refine!r}")
    parsed = validate(width, height, defects, mesh_size, tip_size, max_samples)
    gmsh = _import_gmsh()
    # gmsh meshes the body scaled to max(width, height) = 1 (its tolerances are absolute), so a
    # scene in other length units gets the same mesh, scaled; a unit-size body is meshed as given
    L = float(max(width, height))
    parsed = [(np.asarray(P, dtype=float) / L, curve) for P, curve in parsed]
    with _session(gmsh, ALGORITHMS[algorithm]):
        sides, surface, curves, tips = _build(gmsh, float(width) / L, float(height) / L, parsed)
        _size_fields(gmsh, float(mesh_size) / L, None if tip_size is None else float(tip_size) / L, tips,
                     2.0 ** refine)
        try:
            gmsh.model.mesh.generate(2)
        except Exception as exc:  # gmsh raises a bare Exception with its last error message
            raise RuntimeError(f"gmsh could not mesh the body with its defects: {exc}") from exc
        dm = _extract(gmsh, sides, surface, curves)
    for _ in range(refine):
        dm = refine_uniformly(dm)
    dm.points = dm.points * L
    return dm
