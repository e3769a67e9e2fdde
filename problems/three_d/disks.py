"""Random non-intersecting disks in a box: the generator of the 3D ``fractured`` scene.

Lengths in the box's unit, angles in degrees; every disk lies in ``region`` (a sub-box of the body
(0, width) x (0, depth) x (0, height)) and at least ``min_gap`` from the body's boundary and from
every other disk.

* ``cracks``: how many disks, an integer in [1, :data:`MAX_DISKS`].
* ``crack_radius``: a number, or a range ``[min, max]`` (each radius drawn uniformly in it), > 0.
* ``crack_normal`` ([nx, ny, nz], any non-zero length) and ``crack_normal_spread`` (degrees in
  [0, 90]): each disk's "+" unit normal is drawn uniformly (by area) on the cone of directions within
  ``crack_normal_spread`` of ``crack_normal``: 0 gives parallel disks, 90 every orientation (the
  normals fill the hemisphere around ``crack_normal``, which sets the "+" faces).
* ``region``: ``[[x0, y0, z0], [x1, y1, z1]]`` inside the body, None = the whole body.
* ``seed``: numpy's ``default_rng`` (PCG64) seed, an integer in [0, 2**63 - 1].

Placement: random sequential addition. Per candidate, in this order, one random stream gives the
radius, the normal's polar angle, its azimuth, and the centre's x, y, z (the centre uniform in the
part of the region where a disk of that radius and normal fits: a disk reaches
r sqrt(1 - n_k^2) from its centre along axis k). A candidate is accepted when it keeps ``min_gap``
from every disk accepted before it, else rejected; candidates are tested in batches with the same
outcome as one at a time. After :data:`ATTEMPTS_PER_DISK` x ``cracks`` candidates without placing
them all, InputError naming ``cracks`` and how many were placed; at once, beyond a packing bound
(the disks' neighbourhoods of radius min_gap / 2 are disjoint, each of volume >= pi r^2 min_gap +
4/3 pi (min_gap / 2)^3, in the region grown by min_gap / 2), InputError saying how many fit at most.

The distance test: the distance between two disjoint disks is attained at a rim point of one of them
(two disks that intersect have a rim point of one inside the other), and the distance of a point to a
disk is exact (sqrt(h^2 + max(rho - r, 0)^2), h its height over the disk's plane, rho its distance
from the centre in that plane). Each rim is sampled at :data:`RIM_SAMPLES` points; the distance along
a rim is 1-Lipschitz, so a pair is accepted only when the sampled minimum minus half the sample
spacing (pi r / RIM_SAMPLES) is >= min_gap: an accepted pair is surely min_gap apart (a pair between
min_gap and min_gap + 0.07 r apart may be rejected).

Reproducibility: the same arguments give the same disks on any machine (PCG64 is platform-independent;
centres and normals are rounded to 12 decimals, which absorbs the last-bit differences of sin and cos).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from dualfem.errors import InputError, check_int, check_positive

from .._placement import first_fit

#: largest disk count accepted (the mesh size guard refuses most large counts before meshing)
MAX_DISKS = 20_000
#: candidates drawn per disk asked for before giving up
ATTEMPTS_PER_DISK = 200
#: samples on each rim for the distance test
RIM_SAMPLES = 48
_DECIMALS = 12
_FORM_REGION = "[[x0, y0, z0], [x1, y1, z1]] with 0 <= x0 < x1 <= width, 0 <= y0 < y1 <= depth, 0 <= z0 < z1 <= height"


# --------------------------------------------------------------------------- parsing the keys
def _number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)) \
        and math.isfinite(float(v))


def _values(key: str, value: Any, form: str) -> Any:
    """A scene value; a string (``--set``) is read as JSON or as comma-separated numbers."""
    from ..fractured import _values as values_2d

    return values_2d(key, value, form)


def parse_radius(value: Any) -> tuple[float, float]:
    """``crack_radius``: a number r as (r, r) or a [min, max] pair, 0 < min <= max."""
    form = "a radius > 0 or a range [min, max] of radii > 0"
    v = _values("crack_radius", value, form)
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 1:
        v = v[0]
    if _number(v):
        lo = hi = float(v)
    elif isinstance(v, (list, tuple, np.ndarray)) and len(v) == 2 and all(_number(x) for x in v):
        lo, hi = float(v[0]), float(v[1])
    else:
        raise InputError(f"crack_radius must be {form}, got {value!r}")
    if not 0 < lo <= hi:
        raise InputError(f"crack_radius must be {form} (min <= max), got {value!r}")
    return lo, hi


def parse_normal(value: Any, spread: Any) -> tuple[np.ndarray, float]:
    """(``crack_normal`` as a unit vector, ``crack_normal_spread`` in degrees in [0, 90])."""
    form = "3 numbers [nx, ny, nz], not all zero"
    v = _values("crack_normal", value, form)
    if not (isinstance(v, (list, tuple, np.ndarray)) and len(v) == 3 and all(_number(x) for x in v)):
        raise InputError(f"crack_normal must be {form}, got {value!r}")
    n = np.asarray(v, dtype=float)
    if not np.linalg.norm(n) > 0:
        raise InputError(f"crack_normal must be {form}, got {value!r}")
    if not _number(spread) or not 0 <= float(spread) <= 90:
        raise InputError(f"crack_normal_spread must be an angle in degrees in [0, 90] (0: every disk normal to "
                         f"crack_normal; 90: any orientation), got {spread!r}")
    return n / np.linalg.norm(n), float(spread)


def parse_region(value: Any, box: tuple[float, float, float]) -> np.ndarray:
    """``region`` inside the body as a (2, 3) array [[x0, y0, z0], [x1, y1, z1]]; None or [] = the body."""
    v = _values("region", value, _FORM_REGION)
    L = np.asarray(box, dtype=float)
    if v is None or (isinstance(v, (list, tuple)) and len(v) == 0):
        return np.stack([np.zeros(3), L])
    flat = v
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 2 and all(
            isinstance(p, (list, tuple, np.ndarray)) for p in v):
        flat = [x for p in v for x in p]
    if not (isinstance(flat, (list, tuple, np.ndarray)) and len(flat) == 6 and all(_number(x) for x in flat)):
        raise InputError(f"region must be {_FORM_REGION}, got {value!r}")
    r = np.asarray(flat, dtype=float).reshape(2, 3)
    if not (np.all(0 <= r[0]) and np.all(r[0] < r[1]) and np.all(r[1] <= L)):
        raise InputError(f"region must be {_FORM_REGION} (width, depth, height = {', '.join(f'{b:g}' for b in L)}), "
                         f"got {value!r}")
    return r


# --------------------------------------------------------------------------- geometry
def _frames(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane orthonormal vectors (k, 3), (k, 3) of unit normals n (k, 3)."""
    pick = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    e1 = pick - (pick * n).sum(axis=1, keepdims=True) * n
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(n, e1)


def _rims(c: np.ndarray, n: np.ndarray, r: np.ndarray) -> np.ndarray:
    """RIM_SAMPLES points (k, S, 3) on each rim."""
    e1, e2 = _frames(n)
    t = np.linspace(0, 2 * np.pi, RIM_SAMPLES, endpoint=False)
    ring = np.cos(t)[None, :, None] * e1[:, None] + np.sin(t)[None, :, None] * e2[:, None]      # (k, S, 3)
    return c[:, None] + r[:, None, None] * ring


def _point_disk(P: np.ndarray, c: np.ndarray, n: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Exact distances (k, S) of points P (k, S, 3) to disks (c, n, r) (k, 3), (k, 3), (k,)."""
    d = P - c[:, None]
    h = (d * n[:, None]).sum(axis=2)
    rho = np.linalg.norm(d - h[..., None] * n[:, None], axis=2)
    return np.hypot(h, np.maximum(rho - r[:, None], 0.0))


def pair_clear(A: tuple, B: tuple, gap: float) -> np.ndarray:
    """For disk pairs A[k], B[k] (each (centres, normals, radii)): True where they are surely >= ``gap``
    apart (rim samples, minus the Lipschitz slack pi r / RIM_SAMPLES; see the module docstring)."""
    (ca, na, ra), (cb, nb, rb) = A, B
    dab = _point_disk(_rims(ca, na, ra), cb, nb, rb).min(axis=1) - np.pi * ra / RIM_SAMPLES
    dba = _point_disk(_rims(cb, nb, rb), ca, na, ra).min(axis=1) - np.pi * rb / RIM_SAMPLES
    return np.minimum(dab, dba) >= gap


def _conflicts(cand: tuple, placed: tuple | None, gap: float, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j): candidate i conflicts with placed disk j (or with candidate j > i when ``placed`` is
    None). Only pairs whose centres are within ``reach`` (2 max radius + gap) are tested."""
    from scipy.spatial import cKDTree

    ta = cKDTree(cand[0])
    if placed is None:
        pairs = ta.query_pairs(reach, output_type="ndarray")
        i, j = (pairs[:, 0], pairs[:, 1]) if len(pairs) else (np.zeros(0, int), np.zeros(0, int))
    else:
        if len(placed[0]) == 0:
            return np.zeros(0, int), np.zeros(0, int)
        m = ta.sparse_distance_matrix(cKDTree(placed[0]), reach, output_type="ndarray")
        i, j = m["i"].astype(int), m["j"].astype(int)
    if i.size == 0:
        return i, j
    sub = placed if placed is not None else cand
    ok = pair_clear(tuple(a[i] for a in cand), tuple(a[j] for a in sub), gap)
    return i[~ok], j[~ok]


# --------------------------------------------------------------------------- placement
def _draw(u: np.ndarray, radius, axis: np.ndarray, spread: float, lo: np.ndarray, hi: np.ndarray, scale: float):
    """Candidates (centres, normals, radii, fits) from uniform numbers u (b, 6)."""
    r = radius[0] + (radius[1] - radius[0]) * u[:, 0]
    cos_t = 1 - u[:, 1] * (1 - math.cos(math.radians(spread)))
    sin_t = np.sqrt(np.maximum(0.0, 1 - cos_t ** 2))
    phi = 2 * np.pi * u[:, 2]
    e1, e2 = _frames(axis[None])
    n = cos_t[:, None] * axis + sin_t[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    n = np.round(n, _DECIMALS)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    half = r[:, None] * np.sqrt(np.maximum(0.0, 1 - n ** 2))           # reach of the disk along each axis
    clo, chi = lo + half, hi - half
    fits = np.all(chi >= clo, axis=1)
    c = clo + (chi - clo) * u[:, 3:]
    c = np.clip(np.round(c / scale, _DECIMALS) * scale, clo, np.maximum(clo, chi))
    return c, n, r, fits


def place_disks(cracks: int, crack_radius: Any, crack_normal: Any, crack_normal_spread: Any, min_gap: float,
                seed: int, region: Any, box: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (n, 3), unit normals (n, 3), radii (n,)) of ``cracks`` disks, in placement order (see the
    module docstring); InputError naming the key on a bad argument or when they cannot be placed."""
    n_want = check_int("cracks", cracks, 1, MAX_DISKS)
    radius = parse_radius(crack_radius)
    axis, spread = parse_normal(crack_normal, crack_normal_spread)
    gap = check_positive("min_gap", min_gap)
    seed = check_int("seed", seed, 0, 2 ** 63 - 1)
    reg = parse_region(region, box)
    L = np.asarray(box, dtype=float)
    lo, hi = np.maximum(reg[0], gap), np.minimum(reg[1], L - gap)
    # the widest a disk of the smallest radius can be along each axis at an allowed normal: it must fit
    # (along axis k a disk reaches r sin(angle of its normal to e_k); the smallest angle in the cone)
    tilt = np.maximum(0.0, np.arccos(np.minimum(1.0, np.abs(axis))) - math.radians(spread))
    reach_min = radius[0] * np.sin(tilt)
    if np.any(hi - lo <= 0) or np.any(hi - lo < 2 * reach_min):
        raise InputError(f"crack_radius = {crack_radius!r}: no disk fits in the region {reg.tolist()} with min_gap = "
                         f"{gap:g} from the body's boundary; make crack_radius or min_gap smaller or the region larger")
    room = float(np.prod(hi - lo + gap))
    most = int(room / (math.pi * radius[0] ** 2 * gap + math.pi * gap ** 3 / 6))
    if n_want > most:
        raise InputError(f"cracks = {n_want}: at most {most:,} disks of radius >= {radius[0]:g} fit {gap:g} apart "
                         f"(min_gap) in the region {reg.tolist()}, whatever their places; ask for fewer cracks, a "
                         f"smaller crack_radius or min_gap, or a larger region")
    rng = np.random.default_rng(seed)
    scale = float(L.max())
    reach = 2 * radius[1] + gap
    C, N, R = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    budget, drawn = ATTEMPTS_PER_DISK * n_want, 0
    while len(R) < n_want and drawn < budget:
        rate = max(len(R) / drawn, 1e-3) if drawn else 1.0
        b = int(min(budget - drawn, 20_000, max(64, 2 * (n_want - len(R)) / rate)))
        c, n, r, fits = _draw(rng.random((b, 6)), radius, axis, spread, lo, hi, scale)
        drawn += b
        ok = fits.copy()
        i, _ = _conflicts((c, n, r), (C, N, R), gap, reach)
        ok[i] = False
        cand = np.flatnonzero(ok)
        i, j = _conflicts((c[cand], n[cand], r[cand]), None, gap, reach)      # i < j: j conflicts with earlier i
        take = cand[first_fit(i, j, len(cand), n_want - len(R))]
        C, N, R = np.concatenate([C, c[take]]), np.concatenate([N, n[take]]), np.concatenate([R, r[take]])
    if len(R) < n_want:
        raise InputError(f"cracks = {n_want}: only {len(R)} disks could be placed in {budget:,} attempts "
                         f"(crack_radius {radius[0]:g}..{radius[1]:g}, min_gap {gap:g}, region {reg.tolist()}); ask "
                         f"for at most {len(R)} cracks, a smaller crack_radius or min_gap, or a larger region")
    return C, N, R


def random_disks(cracks: int = 50, crack_radius: Any = 0.05, crack_normal: Any = (0.0, 0.0, 1.0),
                 crack_normal_spread: float = 90.0, min_gap: float = 0.04, seed: int = 0, region: Any = None,
                 box: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> list[dict]:
    """``cracks`` disjoint disks as 3D ``[[defects]]`` tables ``{"shape": "disk", "center", "normal",
    "radius"}`` (same arguments, same disks; see the module docstring)."""
    C, N, R = place_disks(cracks, crack_radius, crack_normal, crack_normal_spread, min_gap, seed, region, box)
    return [{"shape": "disk", "center": c.tolist(), "normal": n.tolist(), "radius": float(r)}
            for c, n, r in zip(C, N, R)]
