"""Parsing and checking the defect scene keys (``defect`` and ``[[defects]]``) in the reference frame."""
from __future__ import annotations

import numpy as np

from dualfem.errors import InputError, check_positive

from .._boundary import parse_scalar
from .._friction_keys import KEYS as FRICTION_KEYS
from .._friction_keys import table_keys
from ..defects_file import MAX_DEFECTS, file_or_tables

CURVES = ("polyline", "spline")
#: points of one defect. The number of defects is bounded by the mesh they need (the gmsh triangle
#: estimate, :func:`dualfem.problems.gmsh_mesh.check_size`; the checks are near-linear) and, as in a
#: defects file, by :data:`dualfem.problems.defects_file.MAX_DEFECTS` tables read at all
MAX_POINTS = 4096


def _numbers(value):
    if isinstance(value, str):
        try:
            return [float(s) for s in value.replace(";", ",").replace(" ", ",").split(",") if s]
        except ValueError:
            return []
    return value


def _point_list(key: str, value, form: str) -> np.ndarray:
    """``value`` as an (k, 2) float array: a list of [x, y] pairs, or a string of 2 k numbers.

    Refused (naming ``key``): a point with other than 2 coordinates (a 3-D point is not read as a
    2-D one), a TOML boolean or string for a coordinate, non-finite numbers.
    """
    if isinstance(value, str):
        flat = _numbers(value)
        if not flat or len(flat) % 2:
            raise InputError(f"{key} must be {form}, got {value!r}")
        arr = np.asarray(flat, dtype=float).reshape(-1, 2)
    else:
        if not isinstance(value, (list, tuple, np.ndarray)) or not len(value):
            raise InputError(f"{key} must be {form}, got {value!r}")
        for i, pt in enumerate(value):
            if not isinstance(pt, (list, tuple, np.ndarray)):
                raise InputError(f"{key} must be {form}, got {value!r}")
            if len(pt) != 2:
                raise InputError(f"{key}: point {i} must have exactly 2 coordinates [x, y] (the scene is 2-D), "
                                 f"got {pt!r} ({len(pt)} coordinates)")
            for c in pt:
                if isinstance(c, (bool, np.bool_)) or not isinstance(c, (int, float, np.integer, np.floating)):
                    raise InputError(f"{key}: point {i} coordinates must be numbers, got {pt!r}")
        arr = np.asarray(value, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{key} coordinates must be finite, got {value!r}")
    return arr


def parse_defect(value) -> np.ndarray:
    """The single-segment key ``defect = [[x1, y1], [x2, y2]]`` (or ``"x1,y1,x2,y2"``) as a (2, 2) array."""
    form = "two points [[x1, y1], [x2, y2]] (or 'x1,y1,x2,y2')"
    arr = _point_list("defect", value, form)
    if arr.shape != (2, 2):
        raise InputError(f"defect must be {form}, got {value!r}")
    return arr


def _points(key: str, value) -> np.ndarray:
    if isinstance(value, (list, tuple, np.ndarray)) and len(value) > MAX_POINTS:
        raise InputError(f"{key} has {len(value)} points; the limit is {MAX_POINTS} per defect")
    arr = _point_list(key, value, "a list of at least two points [[x, y], ...]")
    if arr.shape[0] < 2:
        raise InputError(f"{key} must be at least two points [[x, y], ...], got {value!r}")
    if arr.shape[0] > MAX_POINTS:
        raise InputError(f"{key} has {arr.shape[0]} points; the limit is {MAX_POINTS} per defect")
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
    """The defects as dicts {points (k, 2), curve, delta, face_pressure}: ``defect`` when ``tables`` is None
    (not given), none at all when it is empty (``defects = []``: an uncracked body, a QP without constraints).

    Checks: each table has ``points`` (>= 2 distinct consecutive points strictly inside the body),
    ``curve`` in CURVES (``"spline"`` needs ``mesh = "gmsh"``), ``delta`` > 0, optional ``face_pressure``
    (a number or an expression in x, y, finite in the body: :func:`dualfem.problems._boundary.parse_scalar`;
    None when not given), the friction keys as given (``"friction"``: checked by
    :func:`dualfem.problems._friction_keys.parse_friction`); unknown keys refused.
    Whether defects touch or cross is checked by the mesher (gmsh) or on the grid (structured).
    """
    if isinstance(tables, (list, tuple)) and len(tables) == 0:
        return []
    if tables is None:
        _check_inside("defect", defect, width, height)
        return [{"points": defect, "curve": "polyline", "delta": delta, "face_pressure": None}]
    if not isinstance(tables, (list, tuple)) or not all(isinstance(t, dict) for t in tables):
        raise InputError("defects must be a list of tables ([[defects]] in TOML) with points = [[x, y], ...], "
                         f"optional curve and delta; got {tables!r}")
    if len(tables) > MAX_DEFECTS:
        raise InputError(f"defects: {len(tables):,} [[defects]] tables; the limit is {MAX_DEFECTS:,}")
    out = []
    for k, tab in enumerate(tables):
        key = f"defects[{k}]"
        allowed = ("points", "curve", "delta", "face_pressure", *FRICTION_KEYS)
        unknown = sorted(set(tab) - set(allowed))
        if unknown:
            raise InputError(f"{key}: unknown key {unknown[0]!r}; allowed: {', '.join(allowed)}")
        if "points" not in tab:
            raise InputError(f"{key}.points is missing: give points = [[x, y], ...]")
        pts = _points(f"{key}.points", tab["points"])
        curve = tab.get("curve", "polyline")
        if curve not in CURVES:
            raise InputError(f"{key}.curve must be one of {', '.join(CURVES)}, got {curve!r}")
        if curve == "spline" and mesh != "gmsh":
            raise InputError(f"{key}.curve = 'spline' needs mesh = 'gmsh' (the structured grid carries "
                             f"only defects along its edges)")
        dv = tab.get("delta", delta)
        if isinstance(dv, (bool, np.bool_)) or not isinstance(dv, (int, float, np.integer, np.floating)):
            raise InputError(f"{key}.delta must be a number > 0 (a TOML number, not {type(dv).__name__}), "
                             f"got {dv!r}")
        d = check_positive(f"{key}.delta", dv)
        _check_inside(f"{key}.points", pts, width, height)
        fp = tab.get("face_pressure")
        pressure = None if fp is None else parse_scalar(fp, f"{key}.face_pressure", 2, (width, height))
        out.append({"points": pts, "curve": curve, "delta": d, "face_pressure": pressure, "friction": table_keys(tab)})
    return out


def read_file_tables(defects_file, tables) -> tuple[list | None, str]:
    """The defect tables of a scene and what to call them in messages: those of ``defects_file`` (a CSV
    or JSON file, :func:`dualfem.problems.defects_file.file_or_tables`) when it is set, else ``tables``
    (the ``[[defects]]`` key as given, None when not given). Both set: InputError."""
    tables, where = file_or_tables(defects_file, tables, 2)
    return tables, where or "[[defects]] tables"


def defects_label(defects: list[dict]) -> str:
    """A compact, JSON-like text of the defects (for ``QP.params``)."""
    return "[" + ", ".join(f"{{points: {np.round(d['points'], 12).tolist()}, curve: {d['curve']}, "
                           f"delta: {d['delta']:g}"
                           + (f", face_pressure: {d['face_pressure'].values[0]!r}" if d.get("face_pressure") else "")
                           + "}" for d in defects) + "]"
