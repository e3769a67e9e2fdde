"""Parsing and checking the defect scene keys (``defect`` and ``[[defects]]``) in the reference frame."""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError, check_positive

CURVES = ("polyline", "spline")


def _numbers(value):
    if isinstance(value, str):
        try:
            return [float(s) for s in value.replace(";", ",").replace(" ", ",").split(",") if s]
        except ValueError:
            return []
    return value


def parse_defect(value) -> np.ndarray:
    """The single-segment key ``defect = [[x1, y1], [x2, y2]]`` (or ``"x1,y1,x2,y2"``) as a (2, 2) array."""
    value = _numbers(value)
    try:
        arr = np.asarray(value, dtype=float).reshape(2, 2)
    except (ValueError, TypeError):
        raise InputError(f"defect must be two points [[x1, y1], [x2, y2]] (or 'x1,y1,x2,y2'), got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise InputError(f"defect coordinates must be finite, got {value!r}")
    return arr


def _points(key: str, value) -> np.ndarray:
    try:
        arr = np.asarray(_numbers(value), dtype=float)
        arr = arr.reshape(-1, 2)
    except (ValueError, TypeError):
        raise InputError(f"{key} must be a list of points [[x, y], ...], got {value!r}") from None
    if arr.shape[0] < 2 or arr.size != np.asarray(_numbers(value), dtype=float).size:
        raise InputError(f"{key} must be at least two points [[x, y], ...], got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{key} coordinates must be finite, got {value!r}")
    return arr


def _check_inside(key: str, pts: np.ndarray, width: float, height: float) -> None:
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if np.any(seg <= 1e-12 * max(width, height)):
        k = int(np.argmax(seg <= 1e-12 * max(width, height)))
        what = "defect has zero length" if len(pts) == 2 else f"{key} has two equal consecutive points"
        raise InputError(f"{what}: both ends at {tuple(float(c) for c in pts[k])}")
    for pt in pts:
        if not (0 < pt[0] < width and 0 < pt[1] < height):
            raise InputError(f"{key} must lie strictly inside the domain (0, {width:g}) x (0, {height:g}); "
                             f"point {tuple(float(c) for c in pt)} touches or leaves it")


def parse_defects(tables, defect: np.ndarray, delta: float, width: float, height: float,
                  mesh: str) -> list[dict]:
    """The defects as dicts {points (k, 2), curve, delta}; ``defect`` when ``tables`` is empty.

    Checks: each table has ``points`` (>= 2 distinct consecutive points strictly inside the body),
    ``curve`` in CURVES (``"spline"`` needs ``mesh = "gmsh"``), ``delta`` > 0; unknown keys refused.
    Whether defects touch or cross is checked by the mesher (gmsh) or on the grid (structured).
    """
    if tables is None or (isinstance(tables, (list, tuple)) and len(tables) == 0):
        _check_inside("defect", defect, width, height)
        return [{"points": defect, "curve": "polyline", "delta": delta}]
    if not isinstance(tables, (list, tuple)) or not all(isinstance(t, dict) for t in tables):
        raise InputError("defects must be a list of tables ([[defects]] in TOML) with points = [[x, y], ...], "
                         f"optional curve and delta; got {tables!r}")
    out = []
    for k, tab in enumerate(tables):
        key = f"defects[{k}]"
        unknown = sorted(set(tab) - {"points", "curve", "delta"})
        if unknown:
            raise InputError(f"{key}: unknown key {unknown[0]!r}; allowed: points, curve, delta")
        if "points" not in tab:
            raise InputError(f"{key}.points is missing: give points = [[x, y], ...]")
        pts = _points(f"{key}.points", tab["points"])
        curve = tab.get("curve", "polyline")
        if curve not in CURVES:
            raise InputError(f"{key}.curve must be one of {', '.join(CURVES)}, got {curve!r}")
        if curve == "spline" and mesh != "gmsh":
            raise InputError(f"{key}.curve = 'spline' needs mesh = 'gmsh' (the structured grid carries "
                             f"only defects along its edges)")
        d = check_positive(f"{key}.delta", tab.get("delta", delta))
        _check_inside(f"{key}.points", pts, width, height)
        out.append({"points": pts, "curve": curve, "delta": d})
    return out


def defects_label(defects: list[dict]) -> str:
    """A compact, JSON-like text of the defects (for ``QP.params``)."""
    return "[" + ", ".join(f"{{points: {np.round(d['points'], 12).tolist()}, curve: {d['curve']}, "
                           f"delta: {d['delta']:g}}}" for d in defects) + "]"
