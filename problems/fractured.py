"""A body with many random straight cracks: the thin-defect scene (:mod:`.thin_defect`) with its
``[[defects]]`` drawn by a reproducible generator (``dualfem solve fractured --set cracks=400``).

Scene keys (lengths in the body's unit, angles in degrees), beside those of ``thin_defect``
(``load`` = "f1" here, ``load_scale``, ``delta`` (every crack), ``E``, ``nu``, ``plane``, ``width``,
``height``, ``mesh_size``, ``tip_size``, ``N``, ``rotate_deg``; ``mesh``, ``defect`` and ``defects`` are
not keys of this problem). The mesh is gmsh's Frontal-Delaunay mesh without its smoothing pass (the
scene files' algorithm; the pass would cost 40 % more for a minimum gamma quality of 0.62 instead of
0.44, mean 0.98 either way) at twice ``mesh_size`` and ``tip_size``, every triangle then split into four
(:func:`dualfem.problems.gmsh_mesh.refine_uniformly`): elements of size ``mesh_size``, about 7 times
faster than meshing at ``mesh_size`` (400 cracks at mesh_size 0.003: 0.9 s instead of 5-7 s), with 5 %
more nodes. Keys:

* ``cracks`` (default 50): how many cracks, an integer in [1, 100000].
* ``crack_length`` (default 0.025): a number, or a range ``[min, max]`` (each crack's length drawn
  uniformly in it); > 0, and shorter than the longest crack that fits in ``region`` at an allowed
  angle with ``min_gap`` from the body's boundary.
* ``crack_angle`` (default ``[0, 180]``): the angle of each crack's direction, from its first point to
  its last, counter-clockwise from the x axis, in degrees: a number or a range ``[min, max]`` in
  [-360, 360] (drawn uniformly). The angle also sets the crack's normal (the direction turned by
  +90 degrees) and so its "+" face: 0 and 180 give the same segment with opposite normals.
* ``min_gap`` (default 0 = 2 x ``mesh_size``): the smallest distance between two cracks (exact
  segment-to-segment distance) and between a crack and the body's boundary; 0 (the default) or at
  least a quarter of the element size near the cracks, min(mesh_size, tip_size).
  Two element sizes leave at least one layer of elements between neighbouring cracks; 3 would leave
  room for only about 350 cracks of the default length at the default mesh_size (random sequential
  addition jams there), 2 for about 620.
* ``seed`` (default 0): the seed of numpy's ``default_rng`` (PCG64), an integer in [0, 2**63 - 1].
* ``region`` (default the whole body): ``[[x0, y0], [x1, y1]]``, the box every crack lies in (both
  ends), inside the body: 0 <= x0 < x1 <= width, 0 <= y0 < y1 <= height.
* ``mesh_size`` = ``tip_size`` = 0.01 by default (``tip_size`` < ``mesh_size`` refines around the
  2 x ``cracks`` tips).
* ``defects_file`` (default none): the cracks of a CSV or JSON file (:mod:`dualfem.problems.defects_file`,
  relative to the scene file) instead of the generator's, polylines only; then ``cracks``,
  ``crack_length``, ``crack_angle``, ``min_gap``, ``seed`` and ``region`` must not be given. The
  generator's cracks written by ``write_defects(path, random_cracks(...), 2)`` read back to the very
  same QP (with ``min_gap`` = the scene's).
* ``size_growth`` (default 0.3): the element size's slope away from a tip (thin_defect's key).
* ``face_pressure`` (default none): a pressure on both faces of every crack, a number or an expression
  in x, y (stress units; > 0 pushes the faces apart: docs/loads.md). The supports and loads keys of
  ``thin_defect`` (``[[boundary]]``, ``body_force``, ``remote_stress``) apply as they do there.

From the command line a range or the region is one value: ``--set crack_length=[0.01,0.04]``,
``--set region=[[0.2,0.2],[0.8,0.8]]`` (or ``0.01,0.04``).

Placement (:func:`random_cracks`): random sequential addition. Candidates are drawn in order from one
random stream (per candidate, in this order: the length, the angle, the centre's x, its y; the centre
uniform in the part of the region where a crack of that length and angle fits with ``min_gap`` from the
body's boundary); a candidate is accepted when its exact distance to every crack accepted before it is
>= ``min_gap``, else rejected. Candidates are tested in batches (numpy;
:func:`dualfem.problems._segments.near_segment_pairs`: a uniform grid hashing the cracks' midpoints,
cells as wide as two conflicting cracks' midpoints can be apart, so only neighbouring cells are
compared: 2,000 cracks place in under 0.1 s), with the same outcome as one at a time. After 200 x
``cracks`` candidates without placing them all the scene is refused (an
:class:`~dualfem.errors.InputError` naming ``cracks``, how many were placed, and what to change); so is,
at once, a count beyond the packing bound (the cracks' neighbourhoods of radius ``min_gap / 2`` cannot
overlap: ``cracks x (length x min_gap + pi min_gap^2 / 4)`` must not exceed the region's area grown by
``min_gap / 2``).

Reproducibility: the same keys give the same cracks on any machine (the PCG64 stream is
platform-independent; the end points are rounded to 12 decimals of max(width, height), which absorbs
the last-bit differences of sin and cos between math libraries). The list is
``random_cracks(...)``, in the format of ``[[defects]]`` tables (it can be written to a scene file).
"""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from dualfem.errors import InputError, check_int, check_positive
from dualfem.registry import register_problem

from ._boundary import parse_scalar
from ._placement import first_fit
from ._segments import near_segment_pairs
from .thin_defect import ThinDefect
from .thin_defect.geometry import parse_defects, read_file_tables

#: largest crack count accepted
MAX_CRACKS = 100_000
#: candidates drawn per crack asked for before giving up
ATTEMPTS_PER_CRACK = 200
#: default min_gap in element sizes
GAP_IN_MESH_SIZES = 2.0
#: smallest min_gap in element sizes (min(mesh_size, tip_size)): closer cracks force slivers between them
MIN_GAP_IN_ELEMENTS = 0.25
#: crack_length and crack_angle when not given
DEFAULT_LENGTH = 0.025
DEFAULT_ANGLE = (0.0, 180.0)
_DECIMALS = 12            # end points rounded to this many decimals of max(width, height)


# --------------------------------------------------------------------------- parsing the keys
def _values(key: str, value: Any, form: str) -> Any:
    """A number or nested list from a scene value; a string (``--set``) is read as JSON or as
    comma-separated numbers."""
    if isinstance(value, str):
        text = value.strip()
        try:
            return json.loads(text)
        except ValueError:
            pass
        try:
            return [float(s) for s in text.replace(";", ",").replace(" ", ",").strip("[]()").split(",") if s]
        except ValueError:
            raise InputError(f"{key} must be {form}, got {value!r}") from None
    return value


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)) \
        and math.isfinite(float(v))


def _range(key: str, value: Any, form: str) -> tuple[float, float]:
    """A number x as (x, x), or a [min, max] pair of finite numbers with min <= max."""
    v = _values(key, value, form)
    if _is_number(v):
        return float(v), float(v)
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 1 and _is_number(v[0]):
        return float(v[0]), float(v[0])
    if not (isinstance(v, (list, tuple, np.ndarray)) and len(v) == 2 and all(_is_number(x) for x in v)):
        raise InputError(f"{key} must be {form}, got {value!r}")
    lo, hi = float(v[0]), float(v[1])
    if lo > hi:
        raise InputError(f"{key} = [{lo:g}, {hi:g}]: the range's min must not exceed its max ({form})")
    return lo, hi


def parse_length(value: Any) -> tuple[float, float]:
    form = "a length > 0 or a range [min, max] of lengths > 0"
    lo, hi = _range("crack_length", value, form)
    if lo <= 0:
        raise InputError(f"crack_length must be {form}, got {value!r}")
    return lo, hi


def parse_angle(value: Any) -> tuple[float, float]:
    form = "an angle in degrees or a range [min, max] of angles, each in [-360, 360]"
    lo, hi = _range("crack_angle", value, form)
    if lo < -360 or hi > 360:
        raise InputError(f"crack_angle must be {form}, got {value!r}")
    return lo, hi


def parse_region(value: Any, width: float, height: float) -> np.ndarray:
    """``[[x0, y0], [x1, y1]]`` inside the body (0, width) x (0, height) as a (2, 2) array;
    None or [] = the whole body."""
    form = "[[x0, y0], [x1, y1]] with 0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height"
    v = _values("region", value, form)
    if v is None or (isinstance(v, (list, tuple)) and len(v) == 0):
        return np.array([[0.0, 0.0], [width, height]])
    flat = v
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 2 and all(
            isinstance(p, (list, tuple, np.ndarray)) for p in v):
        flat = [x for p in v for x in p]
    if not (isinstance(flat, (list, tuple, np.ndarray)) and len(flat) == 4 and all(_is_number(x) for x in flat)):
        raise InputError(f"region must be {form}, got {value!r}")
    (x0, y0), (x1, y1) = np.asarray(flat, dtype=float).reshape(2, 2)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise InputError(f"region must be {form} (width = {width:g}, height = {height:g}), got {value!r}")
    return np.array([[x0, y0], [x1, y1]])


# --------------------------------------------------------------------------- placement
def _conflicts(A: np.ndarray, B: np.ndarray | None, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) of cracks A[i], B[j] (i < j within A when B is None) closer than ``gap``."""
    i, j, d = near_segment_pairs(A, B, gap)
    near = d < gap
    return i[near], j[near]


def random_cracks(cracks: int = 50, crack_length: Any = DEFAULT_LENGTH, crack_angle: Any = DEFAULT_ANGLE,
                  min_gap: float = 0.02, seed: int = 0, region: Any = None, width: float = 1.0,
                  height: float = 1.0) -> list[dict]:
    """``cracks`` disjoint straight cracks as ``[[defects]]`` tables ``{"points": [[x0, y0], [x1, y1]],
    "curve": "polyline"}`` (random sequential addition, see the module docstring; same arguments,
    same cracks), in placement order. The defaults are the scene's (min_gap: 2 x its mesh_size 0.01).
    ``crack_length``, ``crack_angle``: a number or [min, max]; ``region``: [[x0, y0], [x1, y1]] or None
    (the body (0, width) x (0, height)). InputError naming the key on a bad argument, and naming
    ``cracks`` when the set cannot be placed."""
    seg = _place(cracks, crack_length, crack_angle, min_gap, seed, region, width, height)
    return [{"points": s.tolist(), "curve": "polyline"} for s in seg]


def _check_args(cracks, crack_length, crack_angle, min_gap, seed, region, width, height):
    width, height = check_positive("width", width), check_positive("height", height)
    n = check_int("cracks", cracks, 1, MAX_CRACKS)
    lengths, angles = parse_length(crack_length), parse_angle(crack_angle)
    gap = check_positive("min_gap", min_gap)
    seed = check_int("seed", seed, 0, 2 ** 63 - 1)
    box = parse_region(region, width, height)
    # where a crack may lie: the region, at least min_gap from the body's boundary
    lo = np.maximum(box[0], gap)
    hi = np.minimum(box[1], np.array([width, height]) - gap)
    if np.any(hi <= lo):
        raise InputError(f"min_gap = {gap:g} leaves no room in the region {box.tolist()}: every crack keeps "
                         f"min_gap from the body's boundary; make min_gap smaller than "
                         f"{max(0.0, 0.5 * float(np.min(box[1] - box[0]))):.3g} or the region larger")
    fit = _longest_fit(hi - lo, angles)
    if lengths[1] >= fit:
        raise InputError(f"crack_length must be > 0 and shorter than {fit:.4g}, the longest crack that fits "
                         f"in the region {box.tolist()} at an allowed crack_angle {list(angles)} with "
                         f"min_gap = {gap:g} from the body's boundary; got {crack_length!r}")
    return n, lengths, angles, gap, seed, box, lo, hi, width, height


def _longest_fit(size: np.ndarray, angles: tuple[float, float]) -> float:
    """The longest segment at an angle in the range that fits in a box of this size."""
    a = np.radians(np.linspace(angles[0], angles[1], 3601))
    with np.errstate(divide="ignore"):
        fx = np.where(np.abs(np.cos(a)) > 1e-15, size[0] / np.abs(np.cos(a)), np.inf)
        fy = np.where(np.abs(np.sin(a)) > 1e-15, size[1] / np.abs(np.sin(a)), np.inf)
    return float(np.max(np.minimum(fx, fy)))


def _place(cracks, crack_length, crack_angle, min_gap, seed, region, width, height) -> np.ndarray:
    """The cracks' end points (n, 2, 2), in placement order."""
    n, (l0, l1), (a0, a1), gap, seed, box, lo, hi, width, height = _check_args(
        cracks, crack_length, crack_angle, min_gap, seed, region, width, height)
    # a packing bound: the cracks' neighbourhoods of radius min_gap / 2 are disjoint and lie in the region
    # grown by min_gap / 2 (area >= l0 min_gap + pi min_gap^2 / 4 each); beyond it no attempt can succeed
    room = float(np.prod(hi - lo + gap))
    most = int(room / (l0 * gap + math.pi * gap ** 2 / 4))
    if n > most:
        raise InputError(f"cracks = {n}: at most {most:,} cracks of length >= {l0:g} fit {gap:g} apart (min_gap) in "
                         f"the region {box.tolist()}, whatever their places; ask for fewer cracks, a smaller "
                         f"crack_length or min_gap, or a larger region")
    scale = max(width, height)
    rng = np.random.default_rng(seed)
    placed = np.zeros((0, 2, 2))
    budget = ATTEMPTS_PER_CRACK * n
    drawn = 0
    while len(placed) < n and drawn < budget:
        # batch size: about twice the candidates the remaining cracks need at the acceptance rate so far
        # (the outcome does not depend on it: the stream and the order of the tests are the same)
        rate = max(len(placed) / drawn, 1e-3) if drawn else 1.0
        b = int(min(budget - drawn, 50_000, max(64, 2 * (n - len(placed)) / rate)))
        u = rng.random((b, 4))
        drawn += b
        length = l0 + (l1 - l0) * u[:, 0]
        ang = np.radians(a0 + (a1 - a0) * u[:, 1])
        half = 0.5 * length[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)      # (b, 2)
        clo, chi = lo + np.abs(half), hi - np.abs(half)
        fits = np.all(chi >= clo, axis=1)
        centre = clo + (chi - clo) * u[:, 2:]
        seg = np.stack([centre - half, centre + half], axis=1)
        seg = np.round(seg / scale, _DECIMALS) * scale
        seg[..., 0] = np.clip(seg[..., 0], lo[0], hi[0])          # rounding never leaves the box
        seg[..., 1] = np.clip(seg[..., 1], lo[1], hi[1])
        ok = fits.copy()
        i, _ = _conflicts(seg, placed, gap)
        ok[i] = False
        cand = np.flatnonzero(ok)                                  # the candidates clear of the placed cracks
        i, j = _conflicts(seg[cand], None, gap)                    # i < j: j conflicts with an earlier i
        placed = np.concatenate([placed, seg[cand[first_fit(i, j, len(cand), n - len(placed))]]])
    if len(placed) < n:
        raise InputError(f"cracks = {n}: only {len(placed)} cracks could be placed in {budget:,} attempts "
                         f"(crack_length {l0:g}..{l1:g}, min_gap {gap:g}, region {box.tolist()}); ask for fewer "
                         f"cracks, a smaller crack_length or min_gap, or a larger region")
    return placed


# --------------------------------------------------------------------------- the problem plugin
def _dim(value: Any) -> int | None:
    """2 or 3 from a scene value (an integer, or its text from ``--set``); None for anything else."""
    if isinstance(value, bool):
        return None
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return int(f) if f in (2.0, 3.0) else None


_OWN = ("cracks", "crack_length", "crack_angle", "min_gap", "seed", "region")
_HIDDEN = ("mesh", "defect", "defects")


@register_problem
class Fractured(ThinDefect):
    """A body with many random straight cracks (thin defects), gmsh mesh; see the module docstring."""

    name = "fractured"
    description = "2D elastic body with many random non-intersecting straight cracks (gmsh mesh)"
    scene_default = False       # not inherited: scene files naming no problem stay thin-defect scenes
    unit_map = None             # crack_length, min_gap, region have no unit map yet: no units axis
    defaults = {
        **{k: v for k, v in ThinDefect.defaults.items() if k not in _HIDDEN},
        "dim": 2,                    # 3: the 3D body with random disks (problems/three_d/fractured.py)
        "load": "f1",
        "mesh_size": 0.01,
        "tip_size": 0.01,
        "cracks": 50,
        "crack_length": None,        # None: DEFAULT_LENGTH (a non-number default: a range is allowed)
        "crack_angle": None,         # None: DEFAULT_ANGLE
        "min_gap": 0.0,
        "seed": 0,
        "region": None,              # None: the whole body
        "face_pressure": None,       # None: no pressure on the cracks' faces
    }
    presets = {"fractured": {}}
    update_keys = (*ThinDefect.update_keys, "face_pressure")
    #: the gmsh algorithm (a key of dualfem.problems.gmsh_mesh.ALGORITHMS) and the uniform refinements
    #: after it (mesh_with_defects's refine)
    gmsh_algorithm = "frontal_unsmoothed"
    gmsh_refine = 1

    def __new__(cls, **params: Any):
        """``dim = 3`` (a number or, from ``--set``, text) makes the 3D fractured body instead
        (:class:`dualfem.problems.three_d.fractured.Fractured3D`, not a subclass: its own keys)."""
        dim = _dim(params.get("dim", 2))
        if dim is None:
            raise InputError(f"dim must be 2 or 3 for the fractured problem, got {params['dim']!r}")
        if cls is Fractured and dim == 3:
            from .three_d.fractured import Fractured3D

            return Fractured3D(**params)
        return super().__new__(cls)

    def validate(self) -> None:
        p = self.params
        # what with_params starts from: the keys the scene gave (the defaults follow; a given generator key
        # is refused beside defects_file)
        self._user = {k: p[k] for k in getattr(self, "given", p)}
        p.pop("dim")
        if p["defects_file"]:
            self._validate_file()
            return
        p.update(mesh="gmsh", defects=(), defect=ThinDefect.defaults["defect"])    # thin_defect's own keys
        n = check_int("cracks", p["cracks"], 1, MAX_CRACKS)
        self._check_keys(n)                      # the thin_defect keys and the mesh size, before placing
        h = p["mesh_size"] or min(p["width"], p["height"]) / p["N"]
        gap = check_positive("min_gap", p["min_gap"], allow_zero=True) or GAP_IN_MESH_SIZES * h
        finest = min(h, p["tip_size"] or h)
        if gap < MIN_GAP_IN_ELEMENTS * finest:          # closer cracks would force slivers between them
            raise InputError(f"min_gap must be 0 (the default: {GAP_IN_MESH_SIZES:g} x mesh_size) or >= "
                             f"{MIN_GAP_IN_ELEMENTS:g} x the element size near the cracks (min(mesh_size, "
                             f"tip_size) = {finest:g}): >= {MIN_GAP_IN_ELEMENTS * finest:g}, got {p['min_gap']!r}")
        length = DEFAULT_LENGTH if p["crack_length"] is None else p["crack_length"]
        angle = DEFAULT_ANGLE if p["crack_angle"] is None else p["crack_angle"]
        seg = _place(n, length, angle, gap, p["seed"], p["region"], p["width"], p["height"])
        # the values used (QP.params shows them): ranges as [min, max], the region as a box
        lo, hi = parse_length(length)
        p["crack_length"] = lo if lo == hi else [lo, hi]
        lo, hi = parse_angle(angle)
        p["crack_angle"] = lo if lo == hi else [lo, hi]
        p["min_gap"], p["cracks"] = gap, n
        p["region"] = parse_region(p["region"], p["width"], p["height"]).tolist()
        self.crack_points = seg                  # (cracks, 2, 2): first and last point of each crack
        fp = p["face_pressure"]
        if isinstance(fp, str) and not fp.strip():
            fp = None
        pressure = None if fp is None else parse_scalar(fp, "face_pressure", 2, (p["width"], p["height"]))
        self._defects = [{"points": s, "curve": "polyline", "delta": p["delta"], "face_pressure": pressure}
                         for s in seg]
        self._check_defects_and_load()

    def _validate_file(self) -> None:
        """The cracks of ``defects_file`` (:mod:`dualfem.problems.defects_file`) instead of the generator's: the
        same mesher, the file's defects checked as ``[[defects]]`` tables (polylines only: the mesh is refined
        uniformly); the generator's keys must not be given."""
        p = self.params
        own = sorted(set(self.given) & set(_OWN))
        if own:
            raise InputError(f"defects_file gives the cracks; the generator's key {own[0]!r} does not apply with it "
                             f"(drop it, or drop defects_file)")
        tables, where = read_file_tables(p["defects_file"], None)
        p.update(mesh="gmsh", defects=None, defect=ThinDefect.defaults["defect"])
        self._check_keys(len(tables))
        fp = p["face_pressure"]
        if isinstance(fp, str) and not fp.strip():
            fp = None
        try:
            self._defects = parse_defects(tables, p["defect"], p["delta"], p["width"], p["height"], "gmsh")
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        splines = [k for k, d in enumerate(self._defects) if d["curve"] == "spline" and len(d["points"]) > 2]
        if splines:
            raise InputError(f"{where}: defects[{splines[0]}] is a spline; the fractured problem's mesh (refined "
                             f"uniformly) needs polylines: use the thin_defect problem (mesh = 'gmsh') for splines")
        pressure = None if fp is None else parse_scalar(fp, "face_pressure", 2, (p["width"], p["height"]))
        for d in self._defects:                   # the scene's face_pressure on every crack without its own
            if d["face_pressure"] is None:
                d["face_pressure"] = pressure
        p["cracks"] = len(self._defects)
        for k in ("crack_length", "crack_angle", "min_gap", "seed", "region"):
            p[k] = None
        self.crack_points = [d["points"] for d in self._defects]
        self._check_defects_and_load()

    def _gmsh_options(self) -> dict:
        # meshed at twice the sizes, then every triangle split in four (see gmsh_mesh.ALGORITHMS); the
        # generator placed the cracks min_gap apart, the mesher checks it again (on a grid), for every tip
        return {"algorithm": self.gmsh_algorithm, "refine": self.gmsh_refine, "max_samples": 2 * MAX_CRACKS}

    def with_params(self, **changes: Any) -> Fractured:
        new = type(self)(**{**self._user, **changes})
        if self._shares_with(new, changes):
            new.shared = self.shared
        return new

    def build(self):
        qp = super().build()
        for k in _HIDDEN:                        # provenance: this problem's keys (cracks, seed, ...), not the list
            qp.params.pop(k, None)
        if self.params["defects_file"]:          # the cracks of a file: its name and count, no generator keys
            for k in ("crack_length", "crack_angle", "min_gap", "seed", "region"):
                qp.params.pop(k, None)
        if self.params["face_pressure"] is None:
            qp.params.pop("face_pressure", None)
        qp.name = qp.name.replace("thin_defect", "fractured", 1)
        return qp
