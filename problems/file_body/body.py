"""A body mesh read from a file, checked: P1 simplices, named groups of lower-dimensional elements.

:class:`BodyMesh` is what both readers give (:mod:`.read`: a mesh file through meshio; :mod:`.geometry`:
a CAD or ``.geo`` file meshed by gmsh) and what the cut and the supports read: ``points`` (dim, n) node
coordinates (unused nodes of the file dropped, the others in the file's order), ``cells`` (dim + 1, nc)
triangles (2D) or tetrahedra (3D), each positively oriented (counter-clockwise; right-handed), and
``groups``: name -> ``Group(dim, elements)`` with ``elements`` (k + 1, ne) node ids of the group's
simplices of dimension k (points, lines, triangles, tetrahedra) as the file orders them (a defect's "+"
normal follows that order: :mod:`.cut`).

:func:`check_body` refuses (InputError, one line each): no cells, degenerate cells (zero area/volume),
inverted cells (two cells across a shared face on the same side of it: the mesh folds over), a mesh in
several disconnected parts, a 2D mesh that is not flat (z not constant).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from dualfem.errors import InputError

#: the element types read, by meshio's names: (dimension, nodes)
P1_TYPES = {"vertex": (0, 1), "line": (1, 2), "triangle": (2, 3), "tetra": (3, 4)}
#: relative size below which a cell counts as degenerate (of h^dim, h the mean edge length)
DEGENERATE_RTOL = 1e-10


@dataclass(frozen=True)
class Group:
    """One named group of the file: its elements' dimension and node ids (dim + 1, ne)."""

    dim: int
    elements: np.ndarray


@dataclass
class BodyMesh:
    """A checked body mesh (see the module docstring); ``source`` names the file in messages."""

    points: np.ndarray
    cells: np.ndarray
    groups: dict[str, Group]
    source: str

    @property
    def dim(self) -> int:
        return int(self.points.shape[0])

    def group_list(self) -> str:
        """The file's groups as text: ``name (curve)``, ..."""
        kind = {0: "point", 1: "curve", 2: "surface", 3: "volume"}
        return ", ".join(f"{n!r} ({kind[g.dim]})" for n, g in sorted(self.groups.items())) or "none"

    def group(self, name: str, key: str) -> Group:
        """The group ``name`` (InputError naming the scene ``key`` and listing the file's groups)."""
        if not isinstance(name, str) or name not in self.groups:
            raise InputError(f"{key} = {name!r} is not a group of {self.source}; its groups: {self.group_list()}")
        return self.groups[name]


def signed_measure(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed area (2D) or volume (3D) of each cell (nc,)."""
    P = points[:, cells]                                   # (dim, dim + 1, nc)
    E = P[:, 1:] - P[:, :1]                                # (dim, dim, nc)
    if points.shape[0] == 2:
        return 0.5 * (E[0, 0] * E[1, 1] - E[0, 1] * E[1, 0])
    return np.einsum("ic,ic->c", E[:, 0], np.cross(E[:, 1].T, E[:, 2].T).T) / 6.0


def cell_faces(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All faces of the cells as sorted node ids ((dim + 1) nc, dim), face i of a cell leaving out its vertex
    i, and the opposite vertex of each face ((dim + 1) nc,); face f belongs to cell ``f % nc``."""
    nv = cells.shape[0]
    F = np.vstack([cells[[j for j in range(nv) if j != i]].T for i in range(nv)])
    opposite = np.concatenate([cells[i] for i in range(nv)])
    return np.sort(F, axis=1), opposite


def face_index(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the distinct faces (k, dim), each face's index among them, how many cells share each distinct face)."""
    uniq, inv, cnt = np.unique(F, axis=0, return_inverse=True, return_counts=True)
    return uniq, inv.ravel(), cnt


def orient(points: np.ndarray, cells: np.ndarray, source: str) -> np.ndarray:
    """The cells positively oriented (two vertices swapped where the file lists them the other way);
    InputError for degenerate ones."""
    vol = signed_measure(points, cells)
    edge = np.linalg.norm(points[:, cells[1]] - points[:, cells[0]], axis=0).mean()
    tiny = np.abs(vol) <= DEGENERATE_RTOL * edge ** points.shape[0]
    if tiny.any():
        k = int(np.argmax(tiny))
        raise InputError(f"{source}: {int(tiny.sum())} degenerate element(s) (zero area/volume), e.g. element {k} "
                         f"at {np.round(points[:, cells[:, k]].mean(axis=1), 6).tolist()}; repair the mesh")
    out = cells.copy()
    neg = vol < 0
    out[[0, 1]] = np.where(neg, cells[[1, 0]], cells[[0, 1]])
    return out


def check_body(points: np.ndarray, cells: np.ndarray, source: str) -> None:
    """The refusals of the module docstring (cells positively oriented already)."""
    nc = cells.shape[1]
    F, opposite = cell_faces(cells)
    _, inv, cnt = face_index(F)
    shared = np.flatnonzero(cnt[inv] == 2)
    o = shared[np.argsort(inv[shared], kind="stable")]
    a, b = o[0::2], o[1::2]                                  # the two cells' incidences of each interior face
    if a.size:
        base = points[:, F[a]]                               # (dim, a, dim)
        sa = _side(base, points[:, opposite[a]])
        sb = _side(base, points[:, opposite[b]])
        bad = sa * sb >= 0
        if bad.any():
            k = int(a[np.argmax(bad)] % nc)
            raise InputError(f"{source}: {int(bad.sum())} inverted element(s): two elements on the same side of "
                             f"their shared face (the mesh folds over), e.g. element {k} at "
                             f"{np.round(points[:, cells[:, k]].mean(axis=1), 6).tolist()}; repair the mesh")
        G = sp.coo_matrix((np.ones(a.size), (a % nc, b % nc)), shape=(nc, nc))
        parts, _ = connected_components(G, directed=False)
    else:
        parts = nc
    if parts > 1:
        raise InputError(f"{source}: the mesh is {parts} disconnected parts; one body per scene (or join them)")


def _side(base: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The signed side of points x (dim, k) of the line (2D) or plane (3D) through ``base`` (dim, k, dim)."""
    e = base[:, :, 1:] - base[:, :, :1]
    d = x - base[:, :, 0]
    if base.shape[0] == 2:
        return e[0, :, 0] * d[1] - e[1, :, 0] * d[0]
    n = np.cross(e[:, :, 0].T, e[:, :, 1].T).T
    return (n * d).sum(axis=0)


def make_body(points: np.ndarray, cells: np.ndarray, groups: dict[str, Group], source: str) -> BodyMesh:
    """A :class:`BodyMesh` from raw arrays (points (dim, n_file), cells and groups in the file's node ids):
    nodes in no cell dropped (the others renumbered in order; a group node outside the body is refused when
    the group is used), the cells oriented and checked."""
    if cells.shape[1] == 0:
        raise InputError(f"{source}: no triangles (2D) or tetrahedra (3D) in the file")
    used = np.zeros(points.shape[1], bool)
    used[cells.ravel()] = True
    new = np.cumsum(used) - 1
    new[~used] = -1
    pts = np.ascontiguousarray(points[:, used], dtype=float)
    if not np.all(np.isfinite(pts)):
        raise InputError(f"{source}: node coordinates must be finite")
    cells = orient(pts, new[cells].astype(np.int64), source)
    check_body(pts, cells, source)
    out = {name: Group(g.dim, new[g.elements]) for name, g in groups.items()}
    return BodyMesh(pts, cells, out, source)
