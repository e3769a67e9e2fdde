"""Supports and loads of a body from a file, by named group: ``[[boundary]]`` tables ``{group, support,
traction}``, ``body_force``, ``remote_stress`` (the same meanings, units and signs as the box scenes'
keys, :mod:`dualfem.problems._boundary`, with a group of the file's boundary elements in place of a side).

* ``group``: a group of boundary elements of the file (lines in 2D, triangles in 3D, on the body's
  boundary); ``support`` = ``clamp`` (every component), ``roller`` (the normal component: the group must
  be plane with a coordinate axis as normal), ``free``; ``traction`` = dim numbers or expressions in x,
  y (, z): force per area on the group.
* ``remote_stress`` (dim x dim): sigma.n on the **outer boundary** (the connected part of the boundary
  with the largest extent) except where a group has a support or a traction of its own; holes and
  cavities stay traction-free, so a plate with a hole under ``remote_stress`` is Kirsch's problem.
* ``body_force``: force per volume over the body.
* No support at all, or one that leaves rigid-body motions free: those motions are removed at extreme
  nodes (never a doubled node) and the loads must be in equilibrium, else InputError
  (:func:`dualfem.problems._boundary.check_balance_of`).

A scene of a body from a file must give its loads (one of these keys): there is no default load.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from dualfem.errors import InputError

from .. import _boundary as bd
from .._load_spec import SUPPORTS, Field, _json, _parse_stress, parse_field
from .body import BodyMesh, cell_faces, face_index

TABLE_KEYS = ("group", "support", "traction")


@dataclass(frozen=True)
class GroupSide:
    """One ``[[boundary]]`` table of a body from a file."""

    group: str
    support: str = "free"
    traction: Field | None = None


@dataclass(frozen=True)
class GroupLoads:
    """The supports and loads of a body from a file (module docstring)."""

    dim: int
    sides: tuple[GroupSide, ...] = ()
    body_force: Field | None = None
    remote_stress: tuple[tuple[float, ...], ...] | None = None

    def label(self) -> str:
        parts = [f"{{group: {s.group}, support: {s.support}" + (f", traction: {s.traction.label()}" if s.traction
                                                                 else "") + "}" for s in self.sides]
        out = f"boundary: [{', '.join(parts)}]"
        if self.body_force is not None:
            out += f", body_force: {self.body_force.label()}"
        if self.remote_stress is not None:
            out += f", remote_stress: {[list(r) for r in self.remote_stress]}"
        return out


def parse(params: dict, dim: int, box: tuple[float, ...]) -> GroupLoads:
    """The keys as a :class:`GroupLoads`; InputError naming the key (also when no load is given at all)."""
    tables = _json("boundary", params.get("boundary"), "a list of tables")
    bf, rs = params.get("body_force"), params.get("remote_stress")
    bf = None if isinstance(bf, str) and not bf.strip() else bf
    rs = None if isinstance(rs, str) and not rs.strip() else rs
    tables = [] if tables is None else tables
    if not isinstance(tables, (list, tuple)):
        raise InputError(f"boundary must be a list of tables ([[boundary]] in TOML) with group, support and/or "
                         f"traction; got {tables!r}")
    if not tables and bf is None and rs is None:
        raise InputError("a body from a file needs its supports and loads: [[boundary]] tables (group = ..., "
                         "support = clamp | roller | free, traction = [...]), body_force or remote_stress")
    sides: list[GroupSide] = []
    for k, tab in enumerate(tables):
        key = f"boundary[{k}]"
        if not isinstance(tab, dict):
            raise InputError(f"{key} must be a table with group, support and/or traction, got {tab!r}")
        if "side" in tab:
            raise InputError(f"{key}.side: a body from a file has no box sides; name a group of the file "
                             f"(group = \"...\")")
        unknown = sorted(set(tab) - set(TABLE_KEYS))
        if unknown:
            raise InputError(f"{key}: unknown key {unknown[0]!r}; allowed: {', '.join(TABLE_KEYS)}")
        group = tab.get("group")
        if not isinstance(group, str) or not group:
            raise InputError(f"{key}.group must be the name of a group of the file, got {group!r}")
        if any(s.group == group for s in sides):
            raise InputError(f"{key}.group = {group!r} is given twice; each group at most once")
        if "support" not in tab and "traction" not in tab:
            raise InputError(f"{key} (group {group}) needs a support ({', '.join(SUPPORTS)}) and/or a traction")
        support = tab.get("support", "free")
        if support not in SUPPORTS:
            raise InputError(f"{key}.support must be one of {', '.join(SUPPORTS)}, got {support!r}")
        traction = None
        if "traction" in tab:
            if support == "clamp":
                raise InputError(f"{key}: a clamped group carries no traction; drop traction or use roller or free")
            traction = parse_field(tab["traction"], f"{key}.traction", dim, dim, box, None)
        sides.append(GroupSide(group, support, traction))
    stress = None if rs is None else _parse_stress(rs, dim)
    body = None if bf is None else parse_field(bf, "body_force", dim, dim, box, None)
    return GroupLoads(dim, tuple(sides), body, stress)


@dataclass
class Boundary:
    """The boundary facets of the uncut mesh: ``cell`` and ``corner`` (the facet leaves out that vertex of that
    cell), ``nodes`` (nf, dim) sorted node ids (uncut numbering), ``outer`` (nf,) on the outer boundary."""

    cell: np.ndarray
    corner: np.ndarray
    nodes: np.ndarray
    outer: np.ndarray

    def find(self, body: BodyMesh, name: str, key: str) -> np.ndarray:
        """Indices of the boundary facets of group ``name``; InputError when it is not a group of boundary
        elements of the file."""
        g = body.group(name, key)
        if g.dim != body.dim - 1 or (g.elements < 0).any():
            want = "curve (line elements)" if body.dim == 2 else "surface (triangles)"
            raise InputError(f"{key} = {name!r} must be a {want} of the body's boundary; it is a group of "
                             f"{g.dim}D elements" + (" with nodes outside the body" if (g.elements < 0).any() else ""))
        D = np.sort(g.elements.T, axis=1)
        _, inv, _ = face_index(np.vstack([self.nodes, D]))
        nb = self.nodes.shape[0]
        pos = np.full(int(inv.max()) + 1, -1, np.int64)
        pos[inv[:nb]] = np.arange(nb)
        idx = pos[inv[nb:]]
        if (idx < 0).any():
            raise InputError(f"{key} = {name!r}: {int((idx < 0).sum())} of its elements are not on the body's "
                             f"boundary")
        return idx


def boundary(body: BodyMesh) -> Boundary:
    """The boundary facets of the body (faces of one cell) and which are on the outer boundary."""
    F, _ = cell_faces(body.cells)
    _, inv, cnt = face_index(F)
    one = np.flatnonzero(cnt[inv] == 1)
    nc = body.cells.shape[1]
    nodes = F[one]
    nf, dim = nodes.shape
    A = sp.coo_matrix((np.ones(nodes.size), (np.repeat(np.arange(nf), dim), nodes.ravel())),
                      shape=(nf, body.points.shape[1])).tocsr()
    _, comp = connected_components(A @ A.T, directed=False)
    ext = [np.ptp(body.points[:, np.unique(nodes[comp == c])], axis=1).max() for c in range(comp.max() + 1)]
    return Boundary(one % nc, one // nc, nodes, comp == int(np.argmax(ext)))


def facets_after_cut(b: Boundary, cells: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The boundary facets ``idx`` as node ids (dim, k) of the cut mesh (a facet at a doubled mouth node uses
    the copy of its own cell)."""
    nv = cells.shape[0]
    keep = np.array([[j for j in range(nv) if j != i] for i in range(nv)])     # (nv, nv - 1)
    return cells[keep[b.corner[idx]].T, b.cell[idx]]


def outward_normals(points: np.ndarray, cells: np.ndarray, b: Boundary, idx: np.ndarray,
                    facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit outward normals (dim, k), measures (k,)) of boundary facets (dim, k) of cut cells."""
    P = points[:, facets]                                           # (dim, dim, k)
    opp = points[:, cells[b.corner[idx], b.cell[idx]]]
    if points.shape[0] == 2:
        e = P[:, 1] - P[:, 0]
        n = np.vstack([e[1], -e[0]])
    else:
        n = np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T).T
    meas = np.linalg.norm(n, axis=0)
    n = n / meas
    n *= np.where(((opp - P[:, 0]) * n).sum(axis=0) > 0, -1.0, 1.0)
    return n, meas if points.shape[0] == 2 else 0.5 * meas


def support_mask(loads: GroupLoads, body: BodyMesh, b: Boundary, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Fixed components (dim, n) of the cut mesh's nodes: clamps and rollers of the groups (before the rigid-body
    completion)."""
    dim = body.dim
    mask = np.zeros((dim, points.shape[1]), bool)
    for k, s in enumerate(loads.sides):
        if s.support == "free":
            continue
        key = f"boundary[{k}].group"
        idx = b.find(body, s.group, key)
        f = facets_after_cut(b, cells, idx)
        ids = np.unique(f)
        if s.support == "clamp":
            mask[:, ids] = True
            continue
        n, _ = outward_normals(points, cells, b, idx, f)
        axis = int(np.argmax(np.abs(n[:, 0])))
        if np.abs(np.abs(n[axis]) - 1).max() > 1e-9:
            raise InputError(f"{key} = {s.group!r}: a roller fixes the normal component, so its group must be plane "
                             f"with a coordinate axis (x, y{', z' if dim == 3 else ''}) as normal; use a clamp")
        mask[axis, ids] = True
    return mask


def nodal_forces(loads: GroupLoads, body: BodyMesh, b: Boundary, points: np.ndarray, cells: np.ndarray,
                 scale: float) -> np.ndarray:
    """Consistent P1 nodal forces (dim, n) on the cut mesh: the groups' tractions, the remote stress on the outer
    boundary (module docstring), the body force; times ``scale``."""
    dim, n = points.shape
    F = np.zeros((dim, n))
    taken = np.zeros(b.nodes.shape[0], bool)
    with np.errstate(all="ignore"):
        for k, s in enumerate(loads.sides):
            idx = b.find(body, s.group, f"boundary[{k}].group")
            if s.support != "free" or s.traction is not None:
                taken[idx] = True
            if s.traction is not None:
                bd.integrate(F, points, facets_after_cut(b, cells, idx), s.traction, scale, f"on group {s.group!r}")
        if loads.remote_stress is not None:
            idx = np.flatnonzero(b.outer & ~taken)
            f = facets_after_cut(b, cells, idx)
            nrm, meas = outward_normals(points, cells, b, idx, f)
            t = np.array(loads.remote_stress) @ nrm * (scale * meas / dim)     # (dim, k): each node's share
            for c in range(dim):
                F[c] += np.bincount(f.ravel(), weights=np.tile(t[c], dim), minlength=n)
        if loads.body_force is not None:
            bd.integrate(F, points, cells, loads.body_force, scale, "in the body")
    return F
