"""Tetrahedral meshes of the box with the defect surfaces embedded (gmsh, OpenCASCADE kernel).

The box (0, width) x (0, depth) x (0, height) and each defect surface are built with gmsh's OCC
kernel (``addBox``; ``addDisk`` for disks and ellipses; a plane surface through a polygon's
vertices; a cap cut from ``addSphere``), then ``occ.fragment`` makes the surfaces internal faces
of the volume, so the tetrahedral mesh conforms to them: every defect is a set of mesh
triangles. Element size ``mesh_size``, and ``tip_size`` near the defect fronts (their rim curves):
a Distance/Threshold field, ``tip_size`` within ``tip_size`` of a front, growing linearly with
slope ``grade`` (the scene key ``size_growth``, default ``GRADE``) to ``mesh_size``; optionally
``surface_size`` near the defect surfaces themselves
(the same kind of field on their distance; where both apply, the smaller size).

Size control before anything is meshed: :func:`estimate_tetrahedra` (regular tetrahedra of the
local size, the fronts' refined tubes added) must stay below :data:`MAX_TETRAHEDRA`
(:func:`check_size`, InputError naming mesh_size or tip_size and the allowed range).

gmsh runs single-threaded with fixed options and prints nothing: the same input gives the same arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualfem.errors import InputError, MissingDependency

from ..gmsh_mesh import background_sizes
from .geometry import Surface

MAX_TETRAHEDRA = 4_000_000
GRADE = 0.3                                  # growth of the element size per unit distance from a front
_TET_PER_VOLUME = 6 * math.sqrt(2)           # regular tetrahedra of edge h per h^3 of volume
#: gmsh's meshes hold about this many times the regular-tetrahedron count; 1.0 keeps the estimate
#: conservative (measured: the estimate is 1.5-1.8 x the actual count, penny and three_d scenes)
_FILL = 1.0
_OPTIONS = {
    "General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1, "Mesh.MaxNumThreads1D": 1,
    "Mesh.MaxNumThreads2D": 1, "Mesh.MaxNumThreads3D": 1, "Mesh.RandomSeed": 1, "Mesh.Algorithm": 6,
    "Mesh.Algorithm3D": 1, "Mesh.ElementOrder": 1, "Mesh.Optimize": 1, "Mesh.MeshSizeFromPoints": 0,
    "Mesh.MeshSizeFromCurvature": 0, "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeMin": 0.0,
}


@dataclass
class BoxMesh:
    """``points`` (3, n), ``tets`` (4, nt) positively oriented, ``faces[d]`` (3, k_d): the triangles of defect d."""

    points: np.ndarray
    tets: np.ndarray
    faces: list[np.ndarray]


def _tube(mesh_size: float, tip_size: float, grade: float = GRADE) -> tuple[float, float]:
    return tip_size, tip_size + (mesh_size - tip_size) / grade


def _refined(mesh_size: float, size: float, shape: str, grade: float = GRADE) -> float:
    """Extra tetrahedra (over the count at mesh_size) per unit length of a front (``shape = "tube"``) or per
    unit area of one side of a surface (``"slab"``), refined to ``size`` growing with slope ``grade``."""
    d0, d1 = _tube(mesh_size, size, grade)
    r = np.linspace(d0, d1, 401)
    s = size + (mesh_size - size) * (r - d0) / (d1 - d0)
    f = (2 * np.pi * r if shape == "tube" else 1.0) * (1 / s ** 3 - 1 / mesh_size ** 3)
    grow = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(r)))
    near = (np.pi * d0 ** 2 if shape == "tube" else d0) * (1 / size ** 3 - 1 / mesh_size ** 3)
    return _FILL * _TET_PER_VOLUME * (grow + near)


def estimate_tetrahedra(box, mesh_size: float, tip_size: float | None, front_length: float,
                        surface_size: float | None = None, area: float = 0.0, grade: float = GRADE) -> int:
    """About how many tetrahedra: the volume over regular tetrahedra of size ``mesh_size``, plus a tube of
    refined elements (size ``tip_size`` growing to ``mesh_size``) around fronts of total length
    ``front_length`` and slabs (size ``surface_size``) on both sides of defects of total ``area``.
    Overflow-safe (capped at 1e30)."""
    with np.errstate(all="ignore"):
        vol = float(np.prod(np.asarray(box, dtype=float)))
        count = _FILL * _TET_PER_VOLUME * vol / mesh_size ** 3
        if tip_size is not None and tip_size < mesh_size and front_length > 0:
            count += front_length * _refined(mesh_size, tip_size, "tube", grade)
        if surface_size is not None and surface_size < mesh_size and area > 0:
            count += 2 * area * _refined(mesh_size, surface_size, "slab", grade)
    return int(count) if count < 1e30 else int(1e30)


def check_size(box, mesh_size: float, tip_size: float | None, front_length: float, label: str,
               surface_size: float | None = None, area: float = 0.0, grade: float = GRADE) -> int:
    """The estimated tetrahedron count, or InputError naming mesh_size, tip_size or surface_size and its
    allowed range (the first of them, in this order, that makes the count exceed MAX_TETRAHEDRA). The
    fronts' total length is what many defects add: this is also the guard on their number."""
    est = estimate_tetrahedra(box, mesh_size, tip_size, front_length, surface_size, area, grade)
    if est <= MAX_TETRAHEDRA:
        return est
    vol = float(np.prod(box))
    lo = (_FILL * _TET_PER_VOLUME * vol / MAX_TETRAHEDRA) ** (1 / 3)
    n = f"{est:,}" if est < 1e15 else f"{est:.3g}"
    if estimate_tetrahedra(box, mesh_size, None, 0.0) > MAX_TETRAHEDRA:
        raise InputError(f"{label} gives about {n} tetrahedra (limit {MAX_TETRAHEDRA:,}) on the "
                         f"{' x '.join(f'{b:g}' for b in box)} box: mesh_size must be >= {lo:.3g}")
    tip_too = estimate_tetrahedra(box, mesh_size, tip_size, front_length, grade=grade) > MAX_TETRAHEDRA
    name, given = ("tip_size", tip_size) if tip_too else ("surface_size", surface_size)

    def count(size: float) -> int:
        return estimate_tetrahedra(box, mesh_size, size, front_length, grade=grade) if tip_too else \
            estimate_tetrahedra(box, mesh_size, tip_size, front_length, size, area, grade)

    a, b = math.log(given or mesh_size), math.log(mesh_size)
    for _ in range(60):
        mid = 0.5 * (a + b)
        if count(math.exp(mid)) > MAX_TETRAHEDRA:
            a = mid
        else:
            b = mid
    raise InputError(f"{label}, {name}={given:g} gives about {n} tetrahedra (limit {MAX_TETRAHEDRA:,}; defect "
                     f"fronts {front_length:.4g} long, size_growth={grade:g}): {name} must be in "
                     f"[{math.exp(b):.3g}, {mesh_size:g}], or use fewer or smaller defects or a larger size_growth")


def _import_gmsh():
    try:
        import gmsh
    except ImportError:
        raise MissingDependency("3D scenes need gmsh: pip install 'dualfem[gmsh]'") from None
    return gmsh


def _surface(gmsh, s: Surface) -> int:
    """The OCC surface tag of one defect."""
    occ = gmsh.model.occ
    if s.shape in ("disk", "ellipse"):
        a, b, e1 = s.a, s.b, s.e1
        if b > a:                         # gmsh wants rx >= ry: swap the axes, turn the frame
            a, b, e1 = b, a, s.e2
        return occ.addDisk(*s.center, a, b, zAxis=list(s.normal), xAxis=list(e1))
    if s.shape == "polygon":
        pts = [occ.addPoint(*p) for p in s.points]
        lines = [occ.addLine(p, q) for p, q in zip(pts, pts[1:] + pts[:1])]
        return occ.addPlaneSurface([occ.addCurveLoop(lines)])
    th = s.half_angle                     # a cap: the sphere above latitude pi/2 - th around +z, then moved
    vol = occ.addSphere(0.0, 0.0, 0.0, s.R, angle1=math.pi / 2 - th, angle2=math.pi / 2)
    occ.synchronize()
    bnd = gmsh.model.getBoundary([(3, vol)], oriented=False)
    caps = [t for _, t in bnd if gmsh.model.getType(2, t) == "Sphere"]
    occ.remove([(3, vol)])
    occ.remove([(2, t) for _, t in bnd if t not in caps], recursive=True)
    if len(caps) != 1:
        raise RuntimeError(f"gmsh made {len(caps)} spherical faces for a cap")
    z = np.array([0.0, 0.0, 1.0])
    ax = np.cross(z, s.normal)
    ang = math.atan2(float(np.linalg.norm(ax)), float(z @ s.normal))
    if np.linalg.norm(ax) > 1e-14:
        occ.rotate([(2, caps[0])], 0, 0, 0, *ax, ang)
    elif s.normal[2] < 0:
        occ.rotate([(2, caps[0])], 0, 0, 0, 1, 0, 0, math.pi)
    occ.translate([(2, caps[0])], *s.center)
    return caps[0]


def mesh_box(box, surfaces: list[Surface], mesh_size: float, tip_size: float | None,
             surface_size: float | None = None, grade: float = GRADE,
             size_view: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             options: dict | None = None) -> BoxMesh:
    """The tetrahedral mesh of the box with every surface embedded (see the module docstring); ``grade``:
    the size fields' slope. ``size_view``: (points (3, n), tetrahedra (4, nt), sizes (nt,)) a per-tetrahedron
    size on an earlier mesh of the box, gmsh's background mesh in place of the size fields (adaptive
    refinement, :mod:`dualfem.problems.adaptive`; sizes above ``mesh_size`` are cut to it). ``options``: gmsh
    options set over the fixed ones (e.g. ``{"Mesh.Algorithm3D": 10}``, HXT)."""
    gmsh = _import_gmsh()
    owner = not gmsh.isInitialized()
    if owner:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        for k, v in {**_OPTIONS, **(options or {})}.items():
            gmsh.option.setNumber(k, v)
        gmsh.model.add("dualfem_three_d")
        occ = gmsh.model.occ
        vol = occ.addBox(0.0, 0.0, 0.0, *[float(b) for b in box])
        tags = [_surface(gmsh, s) for s in surfaces]
        # no defect (an uncracked body): nothing to embed, the box is meshed as it is
        _, omap = occ.fragment([(3, vol)], [(2, t) for t in tags]) if tags else (None, [[(3, vol)]])
        occ.synchronize()
        pieces = [[t for d, t in m if d == 2] for m in omap[1:]]
        if any(len(p) != 1 for p in pieces) or len(omap[0]) != 1:
            raise InputError("the defects must neither cut the box's sides nor each other (gmsh split a defect "
                             "surface or the volume)")
        front = sorted({abs(t) for p in pieces for _, t in gmsh.model.getBoundary([(2, p[0])], oriented=False)})
        if size_view is None:
            _fields(gmsh, mesh_size, tip_size, front, surface_size, [p[0] for p in pieces], grade)
        else:
            gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
            background_sizes(gmsh, size_view)
        try:
            gmsh.model.mesh.generate(3)
        except Exception as exc:  # noqa: BLE001 - gmsh raises a bare Exception with its last error message
            raise InputError(f"gmsh could not mesh the box with its defects (mesh_size={mesh_size:g}, tip_size="
                             f"{tip_size or mesh_size:g}): {exc}; try other sizes or move the defects apart") from None
        return _extract(gmsh, [p[0] for p in pieces])
    finally:
        if owner:
            gmsh.finalize()
        else:
            gmsh.model.remove()


def _fields(gmsh, mesh_size: float, tip_size: float | None, front: list[int],
            surface_size: float | None = None, surfaces: list[int] | None = None, grade: float = GRADE) -> None:
    """Size mesh_size; tip_size near the front curves and surface_size near the defect surfaces (each a
    Distance/Threshold pair; the smaller of them where both apply)."""
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
    fld = gmsh.model.mesh.field
    fields = []
    for size, kind, tags in ((tip_size, "CurvesList", front), (surface_size, "SurfacesList", surfaces or [])):
        if size is None or size >= mesh_size or not tags:
            continue
        d0, d1 = _tube(mesh_size, size, grade)
        dist = fld.add("Distance")
        fld.setNumbers(dist, kind, tags)
        fld.setNumber(dist, "Sampling", 200)
        thr = fld.add("Threshold")
        fld.setNumber(thr, "InField", dist)
        fld.setNumber(thr, "SizeMin", size)
        fld.setNumber(thr, "SizeMax", mesh_size)
        fld.setNumber(thr, "DistMin", d0)
        fld.setNumber(thr, "DistMax", d1)
        fields.append(thr)
    if len(fields) == 2:
        both = fld.add("Min")
        fld.setNumbers(both, "FieldsList", fields)
        fields = [both]
    if fields:
        fld.setAsBackgroundMesh(fields[0])


def _extract(gmsh, surface_tags: list[int]) -> BoxMesh:
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, dtype=np.int64)
    xyz = np.asarray(coords, dtype=float).reshape(-1, 3)
    _, conn = gmsh.model.mesh.getElementsByType(4)
    tet = np.asarray(conn, dtype=np.int64).reshape(-1, 4)
    used = np.zeros(int(max(tags.max(), tet.max())) + 1, bool)
    used[tet.ravel()] = True
    ids = np.flatnonzero(used)
    pos = np.full(used.size, -1, np.int64)
    pos[tags] = np.arange(tags.size)
    index = np.full(used.size, -1, np.int64)
    index[ids] = np.arange(ids.size)
    points = np.ascontiguousarray(xyz[pos[ids]].T)
    t = index[tet]
    p = points[:, t]                                        # (3, nt, 4)
    vol6 = np.einsum("ij,ij->j", np.cross((p[:, :, 1] - p[:, :, 0]).T, (p[:, :, 2] - p[:, :, 0]).T).T,
                     p[:, :, 3] - p[:, :, 0])
    t[vol6 < 0] = t[vol6 < 0][:, [0, 2, 1, 3]]
    faces = []
    for s in surface_tags:
        _, fc = gmsh.model.mesh.getElementsByType(2, s)
        f = index[np.asarray(fc, dtype=np.int64).reshape(-1, 3)]
        if f.size == 0 or (f < 0).any():
            raise RuntimeError(f"gmsh left defect surface {s} without triangles in the tetrahedral mesh")
        faces.append(np.ascontiguousarray(f.T))
    return BoxMesh(points, np.ascontiguousarray(t.T), faces)
