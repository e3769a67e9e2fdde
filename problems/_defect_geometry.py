"""The defect geometry of :mod:`dualfem.problems.gmsh_mesh`, checked in numpy before anything is meshed
(no gmsh needed): the curves (:func:`sample_defect`, :func:`rotate`), the element sizes near the tips
(:func:`effective_tip_size`) and the estimated triangle count (:func:`estimate_triangles`,
:func:`check_size`), and :func:`validate`, the check of every input of
:func:`~dualfem.problems.gmsh_mesh.mesh_with_defects`.

Body: the rectangle (0, width) x (0, height), lengths in the scene's units. Each defect is a curve through
``k >= 2`` points (k, 2): ``"polyline"`` (straight segments) or ``"spline"`` (gmsh's uniform Catmull-Rom
spline through the points, end tangents from the reflected neighbour ``2 P0 - P1``), checked on
:data:`SAMPLES_PER_SPAN` samples per span: every defect strictly inside the body, no self-intersection, no
two defects crossing or touching (distance > ``_TOL_REL * max(width, height)``), and the estimated triangle
count below :data:`MAX_TRIANGLES` (that estimate is the guard on the number of defects: each adds two
refined tips). Every pair check is near-linear (a spatial grid of the segments, a k-d tree of the points),
so thousands of defects validate in a fraction of a second. Problems raise
:class:`dualfem.errors.InputError` naming the defects as
``defects[i]`` (counted from 0, as in the ``[[defects]]`` list of a scene file).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from dualfem.errors import InputError, check_positive

from ._segments import closest, near_segment_pairs

CURVES = ("polyline", "spline")
#: the most triangles a mesh may have (estimated before meshing, :func:`check_size`)
MAX_TRIANGLES = 5_000_000
#: defect points checked for crossings and self-intersection (a polyline counts its points, a spline
#: SAMPLES_PER_SPAN per span); the default of ``max_samples`` in :func:`validate`. Crossings and
#: self-intersections are found on a spatial grid (near-linear cost): the bound is on memory (about
#: 100 bytes per point), far above what a mesh within MAX_TRIANGLES can resolve
MAX_SAMPLES = 400_000
SAMPLES_PER_SPAN = 64          # spline samples per span between two given points (validation only)
_TOL_REL = 1e-9                # "touching" tolerance, relative to max(width, height)
#: the default slope of the element size away from a tip (size per unit distance; the scene key
#: ``size_growth``) and its allowed range
GRADE = 0.3
GRADE_RANGE = (0.01, 1.0)
_TRI_PER_AREA = 4 / math.sqrt(3)   # triangles per h^2 of area for equilateral triangles of side h


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
    """Distinct points, inside the body, no self-intersection (S: the sampled curve); near-linear cost
    (a k-d tree of the points, a grid of the segments)."""
    from scipy.spatial import cKDTree

    same = cKDTree(P).query_pairs(tol, output_type="ndarray")
    if len(same):
        a, b = (int(v) for v in same[np.lexsort((same[:, 1], same[:, 0]))[0]])
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
    if len(seg) >= 3:       # non-adjacent segments within tol (a grid: no all-pairs loop)
        a, b, _ = near_segment_pairs(np.stack([S[:-1], S[1:]], axis=1), None, tol)
        far = np.abs(a - b) >= 2
        if far.any():
            k = np.lexsort((b[far], a[far]))[0]
            p, q = int(a[far][k]), int(b[far][k])
            raise InputError(f"defects[{i}] intersects itself near {_fmt(0.25 * (S[p] + S[p + 1] + S[q] + S[q + 1]))}")


def estimate_triangles(width: float, height: float, mesh_size: float, tip_size: float | None, n_tips: int,
                       grade: float = GRADE) -> int:
    """Rough triangle count: equilateral triangles of the local size, tips' discs added (the size grows
    from ``tip_size`` with slope ``grade`` away from each tip).

    Overflow-safe: a tiny size gives a huge count (capped at 1e30), never an exception."""
    with np.errstate(all="ignore"):
        count = _TRI_PER_AREA * (float(width) / mesh_size) * (float(height) / mesh_size)
        if tip_size is not None and tip_size < mesh_size:
            d_min, d_max = _tip_distances(mesh_size, tip_size, grade)
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
               label: str = "", grade: float = GRADE) -> int:
    """The estimated triangle count; InputError naming mesh_size (or tip_size) and its allowed range
    when it exceeds :data:`MAX_TRIANGLES`, before anything is meshed. ``label`` says where mesh_size
    comes from (e.g. "mesh_size = 0: min(width, height)/N = 0.0156"); ``n_tips``: 2 per defect, so this
    is also the guard on the number of defects (the message names it)."""
    est = estimate_triangles(width, height, mesh_size, tip_size, n_tips, grade)
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
        if estimate_triangles(width, height, mesh_size, math.exp(mid), n_tips, grade) > MAX_TRIANGLES:
            a = mid
        else:
            b = mid
    raise InputError(f"{what}, tip_size={tip_size:g} gives about {n} triangles (limit {MAX_TRIANGLES:,}) on {body} "
                     f"with {n_tips // 2:,} defects ({n_tips:,} tips, size_growth={grade:g}): tip_size must be in "
                     f"[{math.exp(b):.3g}, {mesh_size:g}], or use fewer defects or a larger size_growth")


def _tip_distances(mesh_size: float, tip_size: float, grade: float = GRADE) -> tuple[float, float]:
    """Threshold distances: size tip_size up to DistMin, linear growth (slope ``grade``) to mesh_size at DistMax."""
    d_min = tip_size
    return d_min, d_min + (mesh_size - tip_size) / grade


def check_growth(value, key: str = "size_growth") -> float:
    """``size_growth`` (the slope of the element size away from a tip or front: size per unit distance,
    dimensionless) as a float in :data:`GRADE_RANGE`; InputError naming ``key`` and the range otherwise."""
    lo, hi = GRADE_RANGE
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not lo <= float(value) <= hi:
        raise InputError(f"{key} must be a number in [{lo:g}, {hi:g}] (the element size's growth per unit "
                         f"distance away from a defect tip; default {GRADE:g}), got {value!r}")
    return float(value)


def effective_tip_size(mesh_size: float, tip_size: float | None) -> float | None:
    """The element size near the tips: ``tip_size`` when it is below ``mesh_size``; else None (no
    refinement: the uniform ``mesh_size`` already meets the bound ``tip_size``, so a default
    ``tip_size`` follows a smaller ``mesh_size``)."""
    return tip_size if tip_size is not None and tip_size < mesh_size else None


def validate(width: float, height: float, defects: list[dict], mesh_size: float,
             tip_size: float | None = None, max_samples: int = MAX_SAMPLES,
             grade: float = GRADE) -> list[tuple[np.ndarray, str]]:
    """Check all inputs of :func:`mesh_with_defects` (no gmsh needed); return [(points, curve)].

    ``max_samples``: the most curve points accepted (see :data:`MAX_SAMPLES`); ``grade``: the size
    field's slope (``size_growth``, :func:`check_growth`)."""
    grade = check_growth(grade)
    width, height = check_positive("width", width), check_positive("height", height)
    mesh_size = check_positive("mesh_size", mesh_size)
    if mesh_size > min(width, height):
        raise InputError(f"mesh_size must be in (0, min(width, height)] = (0, {min(width, height):g}], "
                         f"got {mesh_size:g}")
    if tip_size is not None:
        tip_size = effective_tip_size(mesh_size, check_positive("tip_size", tip_size))
    if not isinstance(defects, (list, tuple)):
        raise InputError(f"defects must be a list of tables {{points, curve}}, got {type(defects).__name__}")
    check_size(width, height, mesh_size, tip_size, 2 * len(defects), grade=grade)
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
