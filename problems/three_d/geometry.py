"""Defect surfaces of a 3D scene (``[[defects]]`` tables with ``shape``): parsing, checks, sampling.

Every length is in the scene's length unit, every point in the reference (unrotated) frame of the
box (0, width) x (0, depth) x (0, height). Keys per shape below (all required); every table may
also hold ``delta`` (the fracture parameter of that defect; default the scene's) and ``face_pressure``
(stress units, a number or an expression in x, y, z: a pressure pushing both faces apart,
:func:`dualfem.problems._boundary.face_pressure_forces`).

* ``shape = "disk"``: ``center`` [x, y, z], ``normal`` [nx, ny, nz] (any non-zero length),
  ``radius``. The "+" face is the side ``normal`` points to.
* ``shape = "ellipse"``: ``center``, ``normal``, ``axes`` = [a, b] (the two semi-axes), ``direction``
  = [dx, dy, dz] (the in-plane direction of the semi-axis ``a``; its component along ``normal``
  is removed, so it must not be parallel to it). "+" face: the side ``normal`` points to.
* ``shape = "polygon"``: ``points`` = [[x, y, z], ...], k >= 3 vertices of a simple planar polygon
  (every vertex within 1e-9 x its size of the plane, no two edges crossing). Its normal follows the
  right-hand rule: the vertices run counter-clockwise seen from the "+" side (Newell's normal).
* ``shape = "cap"`` (a spherical cap, less than or equal to a hemisphere): ``center`` (the centre of
  the sphere), ``axis`` (the direction from the centre to the cap's apex), ``curvature_radius`` R
  and ``radius`` (the opening radius of its rim circle, 0 < radius <= R). The normal points away
  from the sphere's centre: the "+" face is the convex (outer) side.

Checks before meshing: the keys and their types, every defect strictly inside the box (its exact
extent: :func:`parse_defects`), and no two defects intersecting or closer than the element size at
their fronts (:func:`check_apart`, on sampled surfaces).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dualfem.errors import InputError

from .._friction_keys import KEYS as FRICTION_KEYS
from .._friction_keys import table_keys
from ..defects_file import MAX_DEFECTS

SHAPES = ("disk", "ellipse", "polygon", "cap")
#: vertices of one polygon (its sampling and edge checks are bounded by it). The number of defects is
#: bounded by the mesh they need (the tetrahedron estimate of :mod:`.mesh`, checked before meshing: their
#: fronts' refined tubes) and, as in a defects file, by MAX_DEFECTS tables read at all
MAX_POINTS = 256
_KEYS = {"disk": ("center", "normal", "radius"), "ellipse": ("center", "normal", "axes", "direction"),
         "polygon": ("points",), "cap": ("center", "axis", "curvature_radius", "radius")}


@dataclass
class Surface:
    """One parsed defect: ``shape``, ``delta`` and the shape's numbers (see the module docstring).

    ``center`` (3,), ``normal`` (3,) unit ("+" side; for a cap the axis towards the apex), ``e1``, ``e2``
    (3,): an orthonormal in-plane frame (for an ellipse e1 is along the semi-axis ``a``); ``a``, ``b``:
    semi-axes (a disk: a = b = radius; a cap: a = b = opening radius); ``R``: a cap's curvature radius;
    ``points`` (k, 3): a polygon's vertices.
    """

    shape: str
    delta: float
    center: np.ndarray
    normal: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    a: float = 0.0
    b: float = 0.0
    R: float = 0.0
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    face_pressure: object = None
    friction: dict = field(default_factory=dict)

    @property
    def half_angle(self) -> float:
        """A cap's half opening angle seen from the sphere's centre (radians)."""
        return math.asin(min(1.0, self.a / self.R))

    def size(self) -> float:
        """Its diameter-like size (length): the largest distance between two of its points, about."""
        if self.shape == "polygon":
            P = self.points
            return float(np.linalg.norm(P[:, None] - P[None], axis=-1).max())
        return 2 * max(self.a, self.b)

    def front_length(self) -> float:
        """Length of the front (the rim curve)."""
        if self.shape == "polygon":
            return float(np.linalg.norm(np.diff(np.vstack([self.points, self.points[:1]]), axis=0), axis=1).sum())
        a, b = self.a, self.b
        h = ((a - b) / (a + b)) ** 2
        return math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))    # Ramanujan

    def area(self) -> float:
        if self.shape == "polygon":
            P = self.points - self.points[0]
            return 0.5 * float(np.linalg.norm(np.cross(P[1:-1], P[2:]).sum(axis=0)))
        if self.shape == "cap":
            return 2 * math.pi * self.R ** 2 * (1 - math.cos(self.half_angle))
        return math.pi * self.a * self.b

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """(lowest, highest) coordinates (3,) of the surface, exact."""
        if self.shape == "polygon":
            return self.points.min(axis=0), self.points.max(axis=0)
        rim_c = self.center + (self.R * math.cos(self.half_angle) * self.normal if self.shape == "cap" else 0.0)
        half = np.sqrt((self.a * self.e1) ** 2 + (self.b * self.e2) ** 2)
        lo, hi = rim_c - half, rim_c + half
        if self.shape == "cap":      # the sphere's extreme point along +-e_k, if it lies on the cap
            for k in range(3):
                for s in (-1.0, 1.0):
                    if s * self.normal[k] >= math.cos(self.half_angle) - 1e-15:
                        if s > 0:
                            hi[k] = self.center[k] + self.R
                        else:
                            lo[k] = self.center[k] - self.R
            apex = self.center + self.R * self.normal
            lo, hi = np.minimum(lo, apex), np.maximum(hi, apex)
        return lo, hi

    def sample(self, spacing: float) -> np.ndarray:
        """Points (k, 3) on the surface, rim included, no two neighbours farther apart than ``spacing``."""
        if self.shape == "polygon":
            return _sample_polygon(self, spacing)
        if self.shape == "cap":
            th0 = self.half_angle
            nr = max(2, math.ceil(self.R * th0 / spacing) + 1)
            nt = max(8, math.ceil(2 * math.pi * self.a / spacing) + 1)
            th = np.linspace(0.0, th0, nr)[:, None]
            ph = np.linspace(0.0, 2 * math.pi, nt, endpoint=False)[None]
            u = (np.sin(th) * np.cos(ph))[..., None] * self.e1 + (np.sin(th) * np.sin(ph))[..., None] * self.e2 \
                + np.cos(th)[..., None] * self.normal
            return (self.center + self.R * u).reshape(-1, 3)
        nr = max(2, math.ceil(max(self.a, self.b) / spacing) + 1)
        nt = max(8, math.ceil(2 * math.pi * max(self.a, self.b) / spacing) + 1)
        r = np.linspace(0.0, 1.0, nr)[:, None]
        ph = np.linspace(0.0, 2 * math.pi, nt, endpoint=False)[None]
        pts = self.center + (self.a * r * np.cos(ph))[..., None] * self.e1 \
            + (self.b * r * np.sin(ph))[..., None] * self.e2
        return pts.reshape(-1, 3)

    def normal_at(self, X: np.ndarray) -> np.ndarray:
        """The "+" unit normal (k, 3) at points X (k, 3) on (or near) the surface."""
        if self.shape == "cap":
            d = X - self.center
            return d / np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.normal, X.shape)


# --------------------------------------------------------------------------------------- parsing
def _number(key: str, value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{key} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{key} must be finite, got {value!r}")
    return v


def _positive(key: str, value) -> float:
    v = _number(key, value)
    if v <= 0:
        raise InputError(f"{key} must be > 0, got {value!r}")
    return v


def _vector(key: str, value, unit: bool = False) -> np.ndarray:
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3:
        raise InputError(f"{key} must be 3 numbers [x, y, z], got {value!r}")
    v = np.array([_number(key, c) for c in value])
    if unit:
        n = float(np.linalg.norm(v))
        if not n > 0:
            raise InputError(f"{key} must be a non-zero vector [x, y, z], got {value!r}")
        v = v / n
    return v


def _frame(n: np.ndarray, d: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(e1, e2) with (e1, e2, n) a right-handed orthonormal frame; e1 along d's in-plane part if given."""
    if d is None:
        d = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = d - (d @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def parse_surface(i: int, table, default_delta: float) -> Surface:
    """One ``[[defects]]`` table as a :class:`Surface`; InputError naming ``defects[i].KEY`` otherwise."""
    if not isinstance(table, dict) or "shape" not in table:
        raise InputError(f"defects[{i}] must be a table with 'shape' ({', '.join(SHAPES)}) and its keys, got {table!r}")
    shape = table["shape"]
    if shape not in SHAPES:
        raise InputError(f"defects[{i}].shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    allowed = {"shape", "delta", "face_pressure", *FRICTION_KEYS, *_KEYS[shape]}
    extra = sorted(set(table) - allowed)
    if extra:
        raise InputError(f"defects[{i}]: unknown key {extra[0]!r} for shape {shape!r}; allowed: "
                         f"{', '.join(sorted(allowed))}")
    missing = [k for k in _KEYS[shape] if k not in table]
    if missing:
        raise InputError(f"defects[{i}]: shape {shape!r} needs {', '.join(_KEYS[shape])}; {missing[0]!r} is missing")
    key = f"defects[{i}]."
    delta = _positive(key + "delta", table.get("delta", default_delta))
    s = _parse_shape(i, table, shape, delta)
    s.face_pressure = table.get("face_pressure")
    s.friction = table_keys(table)
    return s


def _parse_shape(i: int, table: dict, shape: str, delta: float) -> Surface:
    key = f"defects[{i}]."
    if shape == "polygon":
        return _parse_polygon(i, table["points"], delta)
    c = _vector(key + "center", table["center"])
    if shape == "cap":
        n = _vector(key + "axis", table["axis"], unit=True)
        R = _positive(key + "curvature_radius", table["curvature_radius"])
        r = _positive(key + "radius", table["radius"])
        if r > R:
            raise InputError(f"{key}radius (the opening radius, {r:g}) must be in (0, curvature_radius] = (0, {R:g}]: "
                             f"a cap is at most a hemisphere")
        return Surface("cap", delta, c, n, *_frame(n), a=r, b=r, R=R)
    n = _vector(key + "normal", table["normal"], unit=True)
    if shape == "disk":
        r = _positive(key + "radius", table["radius"])
        return Surface("disk", delta, c, n, *_frame(n), a=r, b=r)
    axes = table["axes"]
    if not isinstance(axes, (list, tuple)) or len(axes) != 2:
        raise InputError(f"{key}axes must be two semi-axes [a, b], got {axes!r}")
    a, b = _positive(key + "axes", axes[0]), _positive(key + "axes", axes[1])
    d = _vector(key + "direction", table["direction"], unit=True)
    if abs(d @ n) > 1 - 1e-9:
        raise InputError(f"{key}direction must not be parallel to {key}normal (it gives the in-plane direction of "
                         f"the semi-axis a), got {table['direction']!r}")
    return Surface("ellipse", delta, c, n, *_frame(n, d), a=a, b=b)


def _parse_polygon(i: int, value, delta: float) -> Surface:
    key = f"defects[{i}].points"
    if not isinstance(value, (list, tuple)) or not 3 <= len(value) <= MAX_POINTS:
        raise InputError(f"{key} must be 3 to {MAX_POINTS} vertices [[x, y, z], ...], got {value!r}")
    P = np.array([_vector(f"{key}[{k}]", p) for k, p in enumerate(value)])
    c = P.mean(axis=0)
    nrm = np.zeros(3)
    for k in range(len(P)):           # Newell's normal: right-hand rule around the vertices
        p, q = P[k], P[(k + 1) % len(P)]
        nrm += np.array([(p[1] - q[1]) * (p[2] + q[2]), (p[2] - q[2]) * (p[0] + q[0]), (p[0] - q[0]) * (p[1] + q[1])])
    size = float(np.linalg.norm(P[:, None] - P[None], axis=-1).max())
    if not np.linalg.norm(nrm) > 1e-12 * size ** 2:
        raise InputError(f"{key}: the vertices are collinear or enclose no area")
    n = nrm / np.linalg.norm(nrm)
    off = np.abs((P - c) @ n).max()
    if off > 1e-9 * size:
        raise InputError(f"{key}: the polygon must be planar; a vertex lies {off:.3g} off its plane "
                         f"(allowed: 1e-9 x its size = {1e-9 * size:.3g})")
    e1, e2 = _frame(n, P[0] - c if np.linalg.norm(P[0] - c) > 0 else None)
    Q = np.stack([(P - c) @ e1, (P - c) @ e2], axis=1)
    _check_simple(key, Q, 1e-9 * size)
    P = c + np.outer(Q[:, 0], e1) + np.outer(Q[:, 1], e2)     # projected exactly onto its plane
    return Surface("polygon", delta, c, n, e1, e2, points=P)


def _check_simple(key: str, Q: np.ndarray, tol: float) -> None:
    """A simple polygon (k, 2): distinct vertices, no two non-adjacent edges within ``tol``."""
    from .._segments import segment_distances

    k = len(Q)
    E = np.stack([Q, np.roll(Q, -1, axis=0)], axis=1)         # (k, 2, 2)
    if np.linalg.norm(E[:, 1] - E[:, 0], axis=1).min() <= tol:
        raise InputError(f"{key}: two consecutive vertices coincide")
    ia, ib = np.triu_indices(k, 2)
    keep = ~((ia == 0) & (ib == k - 1))
    ia, ib = ia[keep], ib[keep]
    if ia.size:
        dist, _ = segment_distances(E[ia, 0], E[ia, 1], E[ib, 0], E[ib, 1])
        if dist.min() <= tol:
            j = int(np.argmin(dist))
            raise InputError(f"{key}: edges {ia[j]} and {ib[j]} cross or touch: the polygon must be simple")
    d, d_prev = E[:, 1] - E[:, 0], np.roll(E[:, 1] - E[:, 0], 1, axis=0)
    turn = d_prev[:, 0] * d[:, 1] - d_prev[:, 1] * d[:, 0]
    fold = (np.abs(turn) <= 1e-12 * np.linalg.norm(d, axis=1) * np.linalg.norm(d_prev, axis=1)) \
        & ((d_prev * d).sum(axis=1) < 0)
    if fold.any():
        raise InputError(f"{key}: the polygon folds back on itself at vertex {int(np.argmax(fold))}")


def _sample_polygon(s: Surface, spacing: float) -> np.ndarray:
    """Points on the polygon: a grid over its bounding box kept inside it (even-odd rule), and its edges."""
    c, e1, e2 = s.center, s.e1, s.e2
    Q = np.stack([(s.points - c) @ e1, (s.points - c) @ e2], axis=1)
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    nx = max(2, math.ceil((hi[0] - lo[0]) / spacing) + 1)
    ny = max(2, math.ceil((hi[1] - lo[1]) / spacing) + 1)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], nx), np.linspace(lo[1], hi[1], ny))
    G = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inside = np.zeros(len(G), bool)
    for a, b in zip(Q, np.roll(Q, -1, axis=0)):
        crosses = (a[1] > G[:, 1]) != (b[1] > G[:, 1])
        with np.errstate(all="ignore"):
            xc = a[0] + (G[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        inside ^= crosses & (G[:, 0] < xc)
    edges = []
    for a, b in zip(Q, np.roll(Q, -1, axis=0)):
        k = max(2, math.ceil(np.linalg.norm(b - a) / spacing) + 1)
        t = np.linspace(0, 1, k)[:, None]
        edges.append(a + t * (b - a))
    Z = np.vstack([G[inside], *edges])
    return c + np.outer(Z[:, 0], e1) + np.outer(Z[:, 1], e2)


def parse_defects(tables, default_delta: float, box: tuple[float, float, float]) -> list[Surface]:
    """Every ``[[defects]]`` table parsed and checked to lie strictly inside the box (its exact extent)."""
    if not isinstance(tables, (list, tuple)) or not tables:
        raise InputError(f"defects must be [[defects]] tables (shape = disk, ellipse, polygon or cap), got {tables!r}")
    if len(tables) > MAX_DEFECTS:
        raise InputError(f"defects: at most {MAX_DEFECTS:,} defects in a 3D scene, got {len(tables):,}")
    surfaces = [parse_surface(i, t, default_delta) for i, t in enumerate(tables)]
    L = np.asarray(box, dtype=float)
    tol = 1e-9 * float(L.max())
    for i, s in enumerate(surfaces):
        lo, hi = s.extent()
        if lo.min() <= tol or np.any(hi >= L - tol):
            raise InputError(f"defects[{i}] ({s.shape}) is not strictly inside the box (0, {L[0]:g}) x (0, {L[1]:g}) x "
                             f"(0, {L[2]:g}): it reaches from {np.round(lo, 6).tolist()} to {np.round(hi, 6).tolist()}")
    return surfaces


def _plane_clear(s: Surface, t: Surface, limit: float) -> bool:
    """Whether the planar surface ``t`` lies wholly at distance >= ``limit`` from the plane of the planar
    surface ``s`` (then the two are at least ``limit`` apart). False for a cap (not planar)."""
    if "cap" in (s.shape, t.shape):
        return False
    if t.shape == "polygon":
        h = (t.points - s.center) @ s.normal
        lo, hi = float(h.min()), float(h.max())
    else:
        mid = float((t.center - s.center) @ s.normal)
        half = math.hypot(t.a * float(t.e1 @ s.normal), t.b * float(t.e2 @ s.normal))
        lo, hi = mid - half, mid + half
    return lo >= limit or hi <= -limit


def candidate_pairs(surfaces: list[Surface], limit: float) -> np.ndarray:
    """Index pairs (i, j), i < j, of surfaces whose exact bounding boxes come closer than ``limit``
    (a k-d tree of the boxes' centres: near-linear in the number of surfaces), in lexicographic order."""
    from scipy.spatial import cKDTree

    ext = np.array([np.concatenate(s.extent()) for s in surfaces])      # (n, 6): lo, hi
    lo, hi = ext[:, :3], ext[:, 3:]
    centre, half = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo, axis=1)
    pairs = cKDTree(centre).query_pairs(2 * float(half.max()) + limit, output_type="ndarray")
    if not len(pairs):
        return pairs.reshape(0, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    gap = np.maximum(0.0, np.maximum(lo[j] - hi[i], lo[i] - hi[j]))
    near = np.linalg.norm(gap, axis=1) < limit
    keep = pairs[near]
    return keep[np.lexsort((keep[:, 1], keep[:, 0]))]


def check_apart(surfaces: list[Surface], gap: float) -> None:
    """No two defects intersecting or closer than max(``gap``, 2 x the sampling step): each surface is
    sampled with a step of max(gap / 2, its size / 64) (rim included) and the nearest samples of every
    pair compared (a k-d tree). ``gap``: the element size at the defect fronts.

    Only pairs that can fail are sampled: those whose bounding boxes come closer than the limit
    (:func:`candidate_pairs`) and, for two planar surfaces, neither lies wholly beyond the limit from the
    other's plane (the true distance is then at least the limit, and the sampled distance never smaller:
    the outcome is that of comparing every pair, at a near-linear cost)."""
    if len(surfaces) < 2:
        return
    from scipy.spatial import cKDTree

    spacing = max(0.5 * gap, max(s.size() for s in surfaces) / 64)      # bounded sample counts
    limit = max(gap, 2 * spacing)
    clouds: dict[int, np.ndarray] = {}
    trees: dict[int, cKDTree] = {}
    for i, j in candidate_pairs(surfaces, limit).tolist():
        if _plane_clear(surfaces[i], surfaces[j], limit) or _plane_clear(surfaces[j], surfaces[i], limit):
            continue
        for k in (i, j):
            if k not in clouds:
                clouds[k] = surfaces[k].sample(spacing)
        if i not in trees:
            trees[i] = cKDTree(clouds[i])
        d, _ = trees[i].query(clouds[j])
        if d.min() < limit:
            where = clouds[j][int(np.argmin(d))]
            raise InputError(f"defects[{i}] and defects[{j}] intersect or come closer than {limit:.3g} (the "
                             f"element size at the defect front, or the check's sampling step x 2) near "
                             f"{np.round(where, 6).tolist()}: move them apart")
