"""A body from a geometry file (``geometry_file``: a gmsh ``.geo`` script, or a ``.step``/``.stp``/``.brep`` CAD
file) meshed by gmsh into a :class:`~.body.BodyMesh`.

The body is the entities of the highest dimension (surfaces: 2D, flat in z = constant; volumes: 3D). Its
groups are the file's physical groups (``Physical Curve("crack1") = {5};`` in a ``.geo``; a CAD file has
none: merge it from a ``.geo`` that names them). Cracks must be embedded by the file itself (``Curve{..} In
Surface{..}``, ``Surface{..} In Volume{..}`` or ``BooleanFragments``), so that the mesh conforms to them.

Sizes: ``mesh_size`` > 0 caps the element size everywhere (0: the file's own sizes); ``tip_size`` > 0
refines to that size at the tips (2D: the end points of every defect curve) or fronts (3D: the boundary
curves of every defect surface), growing at slope :data:`GROWTH` up to ``mesh_size``. The element count
is estimated from the bounding box and the size before meshing (:func:`element_estimate`), and a count
beyond the box scenes' limits is refused then. Options: first order, no recombination, one thread,
seed 1 (reproducible).
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualfem.errors import InputError, MissingDependency

from ..gmsh_mesh import background_sizes
from .body import BodyMesh, Group, make_body

SUFFIXES = (".geo", ".step", ".stp", ".brep")
#: growth of the element size per unit distance from a tip/front (the box scenes' slope)
GROWTH = 0.3
_OPTIONS = {"General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1, "Mesh.RandomSeed": 1,
            "Mesh.ElementOrder": 1, "Mesh.RecombineAll": 0, "Mesh.MaxNumThreads1D": 1, "Mesh.MaxNumThreads2D": 1,
            "Mesh.MaxNumThreads3D": 1}
_GMSH_TYPES = {1: (1, 2), 2: (2, 3), 4: (3, 4), 15: (0, 1)}          # gmsh element type -> (dim, nodes)


@dataclass(frozen=True)
class GeometryInfo:
    """What a geometry file says before meshing: ``dim``, bounding box lengths ``box``, the largest size its
    points ask for (0: none), its physical groups (name -> dimension)."""

    dim: int
    box: tuple[float, ...]
    point_size: float
    groups: dict[str, int]


def _gmsh():
    try:
        import gmsh
    except ImportError:
        raise MissingDependency("bodies from geometry files need gmsh: pip install 'dualfem[gmsh]'") from None
    return gmsh


@contextmanager
def _opened(path: Path):
    """gmsh with the file opened in a fresh model (finalized afterwards, or the model removed)."""
    gmsh = _gmsh()
    owner = not gmsh.isInitialized()
    if owner:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        for k, v in _OPTIONS.items():
            gmsh.option.setNumber(k, v)
        gmsh.model.add("dualfem_file_body")
        try:
            gmsh.open(str(path)) if path.suffix.lower() == ".geo" else gmsh.merge(str(path))
        except Exception as exc:                         # noqa: BLE001 - gmsh raises a plain Exception
            raise InputError(f"geometry_file {path.name!r} cannot be read by gmsh: {exc}") from None
        gmsh.model.geo.synchronize()
        yield gmsh
    finally:
        if owner:
            gmsh.finalize()
        else:
            gmsh.model.remove()


def _info(gmsh, path: Path) -> GeometryInfo:
    dims = [d for d, _ in gmsh.model.getEntities()]
    dim = max(dims) if dims else -1
    if dim not in (2, 3):
        raise InputError(f"geometry_file {path.name!r}: no surface (2D) or volume (3D) to mesh")
    lo_hi = np.array(gmsh.model.getBoundingBox(-1, -1), dtype=float)
    lo, hi = lo_hi[:3], lo_hi[3:]
    if dim == 2 and hi[2] - lo[2] > 1e-9 * max(np.ptp([lo, hi], axis=0).max(), 1e-300):
        raise InputError(f"geometry_file {path.name!r}: 2D bodies lie in a plane z = constant; its surfaces do not")
    box = tuple(float(x) for x in (hi - lo)[:dim])
    sizes = [s for s in gmsh.model.mesh.getSizes(gmsh.model.getEntities(0)) if 0 < s < 1e21] \
        if gmsh.model.getEntities(0) else []
    groups = {gmsh.model.getPhysicalName(d, t) or str(t): d for d, t in gmsh.model.getPhysicalGroups()}
    return GeometryInfo(dim, box, float(max(sizes)) if sizes else 0.0, groups)


def inspect(path: Path) -> GeometryInfo:
    """The file's :class:`GeometryInfo`, without meshing."""
    with _opened(path) as gmsh:
        return _info(gmsh, path)


def mesh_geometry(path: Path, mesh_size: float, tip_size: float, defect_groups: list[str],
                  size_view: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> BodyMesh:
    """Mesh the file (module docstring); ``defect_groups`` name the groups whose tips/fronts ``tip_size``
    refines. ``size_view``: (points (dim, n), cells (dim + 1, nc), sizes (nc,)) a per-element size on an earlier
    mesh of the body, gmsh's background mesh in place of the tip field (adaptive refinement,
    :mod:`dualfem.problems.adaptive`)."""
    with _opened(path) as gmsh:
        info = _info(gmsh, path)
        dim = info.dim
        if mesh_size > 0:
            gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        if size_view is not None:
            _view(gmsh, size_view)
        elif tip_size > 0:
            _tip_field(gmsh, dim, tip_size, mesh_size or max(info.box), defect_groups)
        try:
            gmsh.model.mesh.generate(dim)
        except Exception as exc:                         # noqa: BLE001
            raise InputError(f"geometry_file {path.name!r}: gmsh could not mesh it: {exc}") from None
        return _extract(gmsh, dim, f"geometry_file {path.name!r}")


def _view(gmsh, view: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """A per-element size as gmsh's background mesh (:func:`dualfem.problems.gmsh_mesh.background_sizes`), the
    sizes of points and curves not taken from the geometry."""
    background_sizes(gmsh, view)
    for key in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(key, 0)


def _tip_field(gmsh, dim: int, tip: float, size: float, names: list[str]) -> None:
    """A size field: ``tip`` at the defects' tips (2D) or fronts (3D), growing at GROWTH to ``size``."""
    by_name = {gmsh.model.getPhysicalName(d, t): (d, t) for d, t in gmsh.model.getPhysicalGroups()}
    pts, curves = [], []
    for name in names:
        if name not in by_name or by_name[name][0] != dim - 1:
            continue
        ents = gmsh.model.getEntitiesForPhysicalGroup(*by_name[name])
        bnd = gmsh.model.getBoundary([(dim - 1, int(e)) for e in ents], combined=True, oriented=False)
        (pts if dim == 2 else curves).extend(int(t) for _, t in bnd)
    if not pts and not curves:
        return
    fld = gmsh.model.mesh.field
    dist = fld.add("Distance")
    if pts:
        fld.setNumbers(dist, "PointsList", pts)
    else:
        fld.setNumbers(dist, "CurvesList", curves)
        fld.setNumber(dist, "Sampling", 100)
    thr = fld.add("Threshold")
    fld.setNumber(thr, "InField", dist)
    fld.setNumber(thr, "SizeMin", tip)
    fld.setNumber(thr, "SizeMax", size)
    fld.setNumber(thr, "DistMin", tip)
    fld.setNumber(thr, "DistMax", tip + (size - tip) / GROWTH)
    if size < 1e21:
        mn = fld.add("MathEval")
        fld.setString(mn, "F", f"{size:.17g}")
        both = fld.add("Min")
        fld.setNumbers(both, "FieldsList", [thr, mn])
        thr = both
    fld.setAsBackgroundMesh(thr)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)


def _extract(gmsh, dim: int, source: str) -> BodyMesh:
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, dtype=np.int64)
    index = np.full(int(tags.max()) + 1, -1, np.int64)
    index[tags] = np.arange(tags.size)
    points = np.asarray(coords, dtype=float).reshape(-1, 3).T[:dim]
    cells = []
    for etype, _, enodes in zip(*gmsh.model.mesh.getElements(dim)):
        if int(etype) not in _GMSH_TYPES or _GMSH_TYPES[int(etype)][0] != dim:
            name = gmsh.model.mesh.getElementProperties(int(etype))[0]
            raise InputError(f"{source}: mixed or unsupported element type {name}; first-order "
                             f"{'triangles' if dim == 2 else 'tetrahedra'} only (no Recombine, no order 2)")
        cells.append(index[np.asarray(enodes, dtype=np.int64)].reshape(-1, dim + 1).T)
    groups: dict[str, Group] = {}
    for gd, gt in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(gd, gt) or str(gt)
        blocks = []
        for ent in gmsh.model.getEntitiesForPhysicalGroup(gd, gt):
            for etype, _, enodes in zip(*gmsh.model.mesh.getElements(gd, int(ent))):
                k = _GMSH_TYPES.get(int(etype), (None, 0))[1]
                if k == gd + 1:
                    blocks.append(index[np.asarray(enodes, dtype=np.int64)].reshape(-1, k).T)
        if blocks:
            groups[name] = Group(gd, np.hstack(blocks))
    return make_body(points, np.hstack(cells) if cells else np.zeros((dim + 1, 0), np.int64), groups, source)


def element_estimate(info: GeometryInfo, mesh_size: float) -> tuple[float, float]:
    """(about how many cells, the size used): the bounding box over ``mesh_size`` cubed (squared in 2D); with
    ``mesh_size = 0`` (the file's own sizes) over the largest size its points ask for: a lower estimate for a
    file that grades its sizes (what a file asks for is its author's to judge; the keys are bounded here)."""
    h = mesh_size if mesh_size > 0 else (info.point_size or max(info.box) / 10)
    per = 2 / math.sqrt(3) * 2 if info.dim == 2 else 6 * math.sqrt(2)
    return per * float(np.prod(info.box)) / h ** info.dim, h
