"""Cutting a body mesh from a file along its defect groups, in 2D and 3D: which nodes are doubled, which
cells take the "+" copies, nodal normals and weights.

A defect is a group of facets of the mesh (lines in 2D, triangles in 3D), each an interior face of the
uncut mesh (shared by two cells). Which nodes are doubled follows from the mesh alone: around a node of
the defect, the cells containing it, linked through their shared faces that contain the node and are not
defect facets, form one group (a tip in 2D, a front node in 3D: the node stays single) or two (the
defect separates them: the node is doubled). So a crack that ends on the body's boundary is an edge
crack: its mouth nodes are doubled, its tips/front inside the body are not. More than two groups is
refused (the defect is not a two-sided curve or surface there).

Normals: the "+" normal of the file's element order (:mod:`.orient`); the nodal normal is the average
of the unit normals of a node's (at most two) defect edges in 2D (as the box scenes' cut,
:mod:`dualfem.problems.thin_defect.cut`), the area-weighted average of its defect triangles' normals in 3D
(as :mod:`dualfem.problems.three_d.cut`). The group of cells whose centroids lie on the normal's side
(summed, as in 3D) takes the "+" copy. Weights: half the length of the node's defect edges (2D,
trapezoid rule), a third of the area of its triangles (3D). Doubled nodes are ordered along the chain
(2D) or by node id (3D), defect by defect: the order of the box scenes, so a box scene written to a file
and read back gives the same QP.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from dualfem.errors import InputError

from .._interface import DoubledNodes, cut_faults, double_nodes
from .body import BodyMesh, cell_faces, face_index
from .orient import chain, orient_surface


@dataclass
class FileCut(DoubledNodes):
    """The doubled mesh: ``cells`` (dim + 1, nc) renumbered; per doubled node j the fields of
    :class:`~dualfem.problems._interface.DoubledNodes`; ``tangents`` (2, m) and ``s`` (m,) the unit tangent
    and arc length from the chain's first node (2D; None in 3D); ``front`` / ``front_id``: in 2D the two ends
    of each defect's chain, first then last (its tips; at an edge crack's mouth the mouth's "-" copy, a doubled
    node), in 3D the single nodes of each defect (its front); ``faces`` (3, nf) the defect triangles
    (3D, node ids of the "-" side; None in 2D)."""

    cells: np.ndarray
    front: np.ndarray
    front_id: np.ndarray
    tangents: np.ndarray | None = None
    s: np.ndarray | None = None
    faces: np.ndarray | None = None


def embedded(body: BodyMesh, facets: np.ndarray, what: str) -> None:
    """InputError unless every facet (dim, nf) is an interior face of the body's mesh."""
    dim = body.dim
    if facets.shape[0] != dim or facets.shape[1] == 0:
        raise InputError(f"{what}: a defect is a {'curve (line elements)' if dim == 2 else 'surface (triangles)'} "
                         f"in a {dim}D body")
    if (facets < 0).all():
        raise InputError(f"{what} is not embedded in the body: it shares no node with the body's mesh (mesh the "
                         f"crack inside the body: 'Curve/Surface {{..}} In Surface/Volume {{..}}' or a fragment)")
    if (facets < 0).any():
        raise InputError(f"{what} is not embedded in the body: some of its nodes are no node of the body's mesh")
    F, _ = cell_faces(body.cells)
    D = np.sort(facets.T, axis=1)
    _, inv, _ = face_index(np.vstack([F, D]))
    count = np.bincount(inv[:F.shape[0]], minlength=int(inv.max()) + 1)[inv[F.shape[0]:]]
    if (count == 0).any():
        raise InputError(f"{what} is not embedded in the body: {int((count == 0).sum())} of its elements are no "
                         f"faces of the body's mesh (the mesh does not conform to the crack)")
    if (count == 1).any():
        raise InputError(f"{what} lies (partly) on the body's boundary; a defect must be inside the body")


def _geometry_2d(points: np.ndarray, lines: np.ndarray, what: str):
    """(chain nodes, per node: unit normal avg, unit tangent avg, weight, arc length) of one 2D defect."""
    nodes = chain(lines, what)
    d = np.diff(points[:, nodes], axis=1)
    ln = np.hypot(d[0], d[1])
    tau = d / ln
    en = np.vstack([-tau[1], tau[0]])
    pad = np.zeros((2, 1))
    nrm = np.hstack([pad, en]) + np.hstack([en, pad])
    tng = np.hstack([pad, tau]) + np.hstack([tau, pad])
    w = 0.5 * (np.r_[0.0, ln] + np.r_[ln, 0.0])
    s = np.r_[0.0, np.cumsum(ln)]
    return nodes, nrm / np.hypot(*nrm), tng / np.hypot(*tng), w, s


def _geometry_3d(points: np.ndarray, tris: np.ndarray, what: str):
    """(node ids sorted, per node: area-weighted unit normal, a third of its triangles' area; oriented
    triangles) of one 3D defect."""
    tris = orient_surface(tris, what)
    P = points[:, tris]
    cr = np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T)            # (nf, 3)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    nodes, inv = np.unique(tris, return_inverse=True)
    inv = inv.reshape(tris.shape)
    nrm = np.zeros((nodes.size, 3))
    w = np.zeros(nodes.size)
    for c in range(3):
        np.add.at(nrm, inv[c], cr)
        np.add.at(w, inv[c], area / 3)
    return nodes, (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).T, w, tris


def cut(body: BodyMesh, defects: list[np.ndarray], names: list[str]) -> FileCut:
    """Double the nodes of every defect (facets (dim, nf) each, already :func:`embedded`); module docstring."""
    pts, cells, dim = body.points, body.cells, body.dim
    nn = pts.shape[1]
    if not defects:
        none = np.zeros(0, np.int64)
        return FileCut(points=pts, lower=none, upper=none, defect_id=none, normals=np.zeros((dim, 0)),
                       weights=np.zeros(0), cells=cells.copy(), front=none, front_id=none,
                       tangents=np.zeros((2, 0)) if dim == 2 else None, s=np.zeros(0) if dim == 2 else None,
                       faces=None if dim == 2 else np.zeros((3, 0), np.int64))
    owner = np.full(nn, -1, np.int64)
    geo = []
    for k, (f, name) in enumerate(zip(defects, names)):
        what = f"defects[{k}] (group {name!r})"
        g = _geometry_2d(pts, f, what) if dim == 2 else _geometry_3d(pts, f, what)
        clash = owner[g[0]] >= 0
        if clash.any():
            raise InputError(f"defects {int(owner[g[0]][clash][0])} and {k} touch (they share mesh nodes); defects "
                             f"must not touch or cross")
        owner[g[0]] = k
        geo.append(g)
    facets = np.hstack([g[3] if dim == 3 else f for g, f in zip(geo, defects)])
    nodes = np.concatenate([g[0] for g in geo])
    ids = np.concatenate([np.full(g[0].size, k) for k, g in enumerate(geo)])
    normals = np.hstack([g[1] for g in geo])
    inc_c, inc_t, j, comp, per = _stars(pts, cells, nodes, facets, names, ids)
    two = per == 2
    none = np.setdiff1d(np.arange(len(geo)), ids[two])
    if none.size:
        k = int(none[0])
        raise InputError(f"defects[{k}] (group {names[k]!r}): no node of it has cells on both sides (the mesh is "
                         f"too coarse: a crack needs a node strictly inside it); refine the mesh there")
    at = two[j]
    plus = _plus_side(pts, cells, inc_c[at], inc_t[at], j[at], comp[at], normals, ids, names, nodes)
    rank = np.cumsum(two) - 1
    lower = nodes[two]
    out = cells.copy()
    doubled, upper = double_nodes(pts, lower)
    jj = rank[j[at]]
    out[inc_c[at][plus], inc_t[at][plus]] = upper[jj[plus]]
    fr = ~two
    c = FileCut(points=doubled, lower=lower, upper=upper, defect_id=ids[two], normals=normals[:, two],
                weights=np.concatenate([g[3] if dim == 2 else g[2] for g in geo])[two], cells=out,
                front=nodes[fr], front_id=ids[fr])
    if dim == 2:              # the box scenes' convention: two ends per defect, first and last of its chain
        c.tangents = np.hstack([g[2] for g in geo])[:, two]
        c.s = np.concatenate([g[4] for g in geo])[two]
        c.front = np.concatenate([g[0][[0, -1]] for g in geo])
        c.front_id = np.repeat(np.arange(len(geo)), 2)
    else:
        c.faces = facets.astype(np.int64)
    _check(c, names)
    return c


def _stars(pts, cells, nodes, facets, names, ids):
    """The incidences (corner, cell) of the cells at the defect nodes (``np.nonzero`` order), each one's node
    (index into ``nodes``) and group (module docstring), and how many groups meet at each node (InputError
    for more than two)."""
    nn, nc = pts.shape[1], cells.shape[1]
    slot = np.full(nn, -1, np.int64)
    slot[nodes] = np.arange(nodes.size)
    inc_c, inc_t = np.nonzero(slot[cells] >= 0)
    key = inc_t * nn + cells[inc_c, inc_t]
    order = np.argsort(key)
    skey = key[order]
    F, _ = cell_faces(cells)
    D = np.sort(facets.T, axis=1)
    _, inv, _ = face_index(np.vstack([F, D]))
    nF = F.shape[0]
    is_defect = np.zeros(int(inv.max()) + 1, bool)
    is_defect[inv[nF:]] = True
    finv = inv[:nF]
    cnt = np.bincount(finv)
    sel = np.flatnonzero((cnt[finv] == 2) & ~is_defect[finv] & (slot[F] >= 0).any(axis=1))
    o = sel[np.argsort(finv[sel], kind="stable")]
    a, b = o[0::2], o[1::2]
    rows, cols = [], []
    for c in range(F.shape[1]):
        v = F[a, c]
        ok = slot[v] >= 0
        rows.append(order[np.searchsorted(skey, (a[ok] % nc) * nn + v[ok])])
        cols.append(order[np.searchsorted(skey, (b[ok] % nc) * nn + v[ok])])
    r, c_ = np.concatenate(rows), np.concatenate(cols)
    G = sp.coo_matrix((np.ones(r.size), (r, c_)), shape=(key.size, key.size))
    ncomp, comp = connected_components(G, directed=False)
    j = slot[cells[inc_c, inc_t]]
    pair = np.unique(j * ncomp + comp)
    per = np.bincount(pair // ncomp, minlength=nodes.size)
    bad = np.flatnonzero(per > 2)
    if bad.size:
        k = int(bad[0])
        raise InputError(f"defects[{int(ids[k])}] (group {names[int(ids[k])]!r}): the cells around its node at "
                         f"{np.round(pts[:, nodes[k]], 6).tolist()} form {per[k]} groups across it (at most 2: "
                         f"the defect must be a two-sided curve or surface)")
    return inc_c, inc_t, j, comp, per


def _plus_side(pts, cells, inc_c, inc_t, j, comp, normals, ids, names, nodes) -> np.ndarray:
    """For each incidence (corner, cell) at a doubled node: whether its group lies on the "+" side (its cells'
    centroids, summed, on the side the node's normal points to); InputError unless exactly one of the
    node's two groups does, or when a cell would be "+" for one node of a defect and "-" for another."""
    v = cells[inc_c, inc_t]
    d = pts[:, cells[:, inc_t]].mean(axis=1) - pts[:, v]
    s = (d * normals[:, j]).sum(axis=0) / np.linalg.norm(d, axis=0)
    ncomp = int(comp.max()) + 1 if comp.size else 0
    plus_comp = np.bincount(comp, weights=s, minlength=ncomp) > 0
    plus = plus_comp[comp]
    pair = np.unique(j * ncomp + comp)
    n_plus = np.bincount(pair // ncomp, weights=plus_comp[pair % ncomp].astype(float), minlength=nodes.size)
    wrong = np.flatnonzero((n_plus != 1) & (np.bincount(pair // ncomp, minlength=nodes.size) == 2))
    if wrong.size:
        k = int(wrong[0])
        raise InputError(f"defects[{int(ids[k])}] (group {names[int(ids[k])]!r}): both groups of cells around its "
                         f"node at {np.round(pts[:, nodes[k]], 6).tolist()} lie on the same side of its normal: "
                         f"the mesh is too coarse for the defect's curvature")
    tk = inc_t * (int(ids.max()) + 1) + ids[j]
    o = np.argsort(tk, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(tk[o])) + 1] if tk.size else np.zeros(0, np.int64)
    p = plus[o].astype(np.int8)
    if tk.size and np.any(np.minimum.reduceat(p, starts) != np.maximum.reduceat(p, starts)):
        raise InputError("a cell lies on the '+' side of one node and the '-' side of another of the same defect: "
                         "the mesh is too coarse for the defect; refine it there")
    return plus


def _check(c: FileCut, names: list[str]) -> None:
    """No cell touches both copies of a node; every doubled node has cells on both sides."""
    both, lonely = cut_faults(c.points.shape[1], c.cells, c.lower, c.upper)
    if both:
        raise InputError("a cell touches both copies of a doubled node: the mesh is too coarse at a defect")
    if lonely.size:
        j = int(lonely[0])
        raise InputError(f"defects[{int(c.defect_id[j])}] (group {names[int(c.defect_id[j])]!r}): the doubled node at "
                         f"{np.round(c.points[:, c.lower[j]], 6).tolist()} has cells on one side only")
