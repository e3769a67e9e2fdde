"""Cutting a tetrahedral mesh along embedded defect surfaces: node doubling, normals, nodal areas.

A defect is a set of mesh triangles (a conforming surface). Its **front** is the set of nodes on
its boundary edges (edges of exactly one of its triangles); the front nodes stay single (the
defect is sealed there). Every other node of the surface (**interior**) is doubled: the original
node becomes the "-" copy (``lower``), a new node at the same place the "+" copy (``upper``).

Which tetrahedra take the "+" copy: around an interior node v, the tetrahedra containing v,
linked through their shared faces that contain v and are not defect triangles, form exactly two
connected groups (the surface cuts the star of v in two). A group is "+" when its tetrahedra's
centroids lie on the side of the nodal normal n_v (the sum over the group of
(centroid - x_v) . n_v / |centroid - x_v| is positive), and the other group must come out "-".
Refused (``CutError``, an InputError naming the defect and the node) when: an edge belongs to
more than two triangles of a defect, a node's star does not split into exactly two groups, both
groups fall on the same side, or a tetrahedron would be "+" for one node of a defect and "-" for
another. After the renumbering :func:`check_cut` verifies that no tetrahedron touches both copies
of a node and that every doubled node has tetrahedra on both sides.

Normals and weights: each defect triangle's normal is oriented like the defect's own "+" normal
at the triangle's centroid (:meth:`.geometry.Surface.normal_at`); the nodal normal is the
area-weighted average of its triangles' normals, normalised; the nodal area ``weight`` is a
third of the area of each triangle at the node (lumped: integral over the defect of phi ~
sum_j w_j phi_j for phi vanishing on the front).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from dualfem.errors import InputError

from .._interface import DoubledNodes, cut_faults, double_nodes
from .geometry import Surface

_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])     # face k of a tetrahedron: without corner k


class CutError(InputError):
    """The mesh cannot be cut along a defect (it does not carry the surface as two-sided faces)."""


@dataclass
class Cut3(DoubledNodes):
    """The doubled mesh. ``points`` (3, n_nodes), ``tets`` (4, n_tets); per constrained node j (m of them,
    defect by defect): ``lower``/``upper`` node ids, ``defect_id``, ``normals`` (3, m) unit "+" normals,
    ``weights`` (m,) nodal areas; ``front`` (k,) the front nodes of every defect and ``front_id`` (k,) theirs;
    ``area`` (n_defects,) each defect's meshed area; ``faces`` (3, n_faces) the defects' surface triangles as
    node ids of the "-" face (the original nodes: the front single, the "+" copy of node ``lower[j]`` is
    ``upper[j]``), for output (VTK, figures)."""

    tets: np.ndarray
    front: np.ndarray
    front_id: np.ndarray
    area: np.ndarray
    faces: np.ndarray | None = None


def _surface_nodes(points: np.ndarray, faces: np.ndarray, surf: Surface, k: int):
    """(interior nodes, front nodes, nodal normals (3, i), nodal areas (i,), meshed area) of one defect."""
    f = faces.astype(np.int64)
    e = np.sort(np.hstack([f[[0, 1]], f[[1, 2]], f[[2, 0]]]), axis=0)
    _, inv, cnt = np.unique(e[0] * points.shape[1] + e[1], return_inverse=True, return_counts=True)
    if cnt.max() > 2:
        raise CutError(f"defects[{k}]: the mesh of the surface is not a manifold (an edge of {cnt.max()} triangles)")
    front = np.unique(e[:, cnt[inv] == 1])
    P = points[:, f]                                                   # (3, 3, nt)
    cr = np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T)        # (nt, 3): 2 x area x unit normal
    ref = surf.normal_at(P.mean(axis=1).T)
    cr[(cr * ref).sum(axis=1) < 0] *= -1
    area = 0.5 * np.linalg.norm(cr, axis=1)
    nodes = np.unique(f)
    interior = np.setdiff1d(nodes, front, assume_unique=True)
    if interior.size == 0:
        raise CutError(f"defects[{k}]: the mesh is too coarse, no node lies strictly inside the defect; "
                       f"decrease mesh_size or tip_size")
    slot = np.full(points.shape[1], -1, np.int64)
    slot[interior] = np.arange(interior.size)
    nrm = np.zeros((interior.size, 3))
    w = np.zeros(interior.size)
    for c in range(3):
        s = slot[f[c]]
        ok = s >= 0
        np.add.at(nrm, s[ok], cr[ok])
        np.add.at(w, s[ok], area[ok] / 3)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return interior, front, nrm.T, w, float(area.sum())


def cut(points: np.ndarray, tets: np.ndarray, faces: list[np.ndarray], surfaces: list[Surface]) -> Cut3:
    """Double the interior nodes of every defect (see the module docstring)."""
    nn = points.shape[1]
    if not surfaces:            # an uncracked body: nothing doubled, no contact pairs
        none = np.zeros(0, np.int64)
        return Cut3(points=points, tets=tets.astype(np.int64, copy=True), lower=none, upper=none, defect_id=none,
                    normals=np.zeros((3, 0)), weights=np.zeros(0), front=none, front_id=none, area=np.zeros(0),
                    faces=np.zeros((3, 0), np.int64))
    parts = [_surface_nodes(points, f, s, k) for k, (f, s) in enumerate(zip(faces, surfaces))]
    lower = np.concatenate([p[0] for p in parts])
    ids = np.concatenate([np.full(p[0].size, k) for k, p in enumerate(parts)])
    front = np.concatenate([p[1] for p in parts])
    owner = np.concatenate([lower, front])
    if np.unique(owner).size != owner.size:
        raise CutError("two defects share mesh nodes: defects must not touch")
    normals = np.hstack([p[2] for p in parts])
    slot = np.full(nn, -1, np.int64)
    slot[lower] = np.arange(lower.size)
    plus = _sides(points, tets, slot, normals, ids, np.hstack(faces), nn)
    out = tets.astype(np.int64, copy=True)
    inc_t, inc_c = np.nonzero(slot[out.T] >= 0)
    doubled, upper = double_nodes(points, lower)
    js = slot[out[inc_c, inc_t]]
    out[inc_c[plus], inc_t[plus]] = upper[js[plus]]
    c = Cut3(points=doubled, tets=out, lower=lower, upper=upper, defect_id=ids,
             normals=normals, weights=np.concatenate([p[3] for p in parts]), front=front,
             front_id=np.concatenate([np.full(p[1].size, k) for k, p in enumerate(parts)]),
             area=np.array([p[4] for p in parts]), faces=np.hstack(faces).astype(np.int64))
    check_cut(c)
    return c


def _sides(points, tets, slot, normals, ids, defect_faces, nn) -> np.ndarray:
    """For each (tetrahedron, corner) at an interior node, in ``np.nonzero(slot[tets.T] >= 0)`` order: "+"?"""
    T = tets.astype(np.int64)
    inc_t, inc_c = np.nonzero(slot[T.T] >= 0)
    v = T[inc_c, inc_t]
    j = slot[v]
    key = inc_t * nn + v                                        # one key per incidence
    order = np.argsort(key)
    skey = key[order]
    # faces shared by two tetrahedra of the stars, not on a defect
    star = np.unique(inc_t)
    F = np.sort(T[:, star][_FACES].transpose(2, 0, 1).reshape(-1, 3), axis=1)     # (4 ns, 3)
    owner_t = np.repeat(star, 4)
    fk = (F[:, 0] * nn + F[:, 1]) * nn + F[:, 2]
    dk = np.sort(defect_faces.astype(np.int64).T, axis=1)
    dk = (dk[:, 0] * nn + dk[:, 1]) * nn + dk[:, 2]
    o = np.argsort(fk, kind="stable")
    same = np.flatnonzero(fk[o][1:] == fk[o][:-1])
    a, b = o[same], o[same + 1]
    keep = ~np.isin(fk[a], dk)
    a, b = a[keep], b[keep]
    rows, cols = [], []
    for c in range(3):
        vv = F[a, c]
        ok = slot[vv] >= 0
        ia = order[np.searchsorted(skey, owner_t[a[ok]] * nn + vv[ok])]
        ib = order[np.searchsorted(skey, owner_t[b[ok]] * nn + vv[ok])]
        rows.append(ia)
        cols.append(ib)
    r, c_ = np.concatenate(rows), np.concatenate(cols)
    G = sp.coo_matrix((np.ones(r.size), (r, c_)), shape=(key.size, key.size))
    ncomp, comp = connected_components(G, directed=False)
    # exactly two groups per node
    pair = np.unique(j * ncomp + comp)
    per_node = np.bincount(pair // ncomp, minlength=normals.shape[1])
    bad = np.flatnonzero(per_node != 2)
    if bad.size:
        k = int(bad[0])
        raise CutError(f"defects[{int(ids[k])}]: the tetrahedra around the doubled node at "
                       f"{np.round(points[:, np.flatnonzero(slot == k)[0]], 6).tolist()} form {per_node[k]} groups "
                       f"across the surface (2 needed): the mesh does not carry the defect as a two-sided surface")
    cen = points[:, T[:, inc_t]].mean(axis=1)                   # (3, n_inc)
    d = cen - points[:, v]
    s = (d * normals[:, j]).sum(axis=0) / np.linalg.norm(d, axis=0)
    vote = np.bincount(comp, weights=s, minlength=ncomp)
    plus_comp = vote > 0
    # each node: one group "+" and the other "-"
    n_plus = np.bincount(pair // ncomp, weights=plus_comp[pair % ncomp].astype(float), minlength=normals.shape[1])
    wrong = np.flatnonzero(n_plus != 1)
    if wrong.size:
        k = int(wrong[0])
        raise CutError(f"defects[{int(ids[k])}]: both groups of tetrahedra around the doubled node at "
                       f"{np.round(points[:, np.flatnonzero(slot == k)[0]], 6).tolist()} lie on the same side of its "
                       f"normal: the mesh is too coarse for the surface's curvature; decrease mesh_size or tip_size")
    plus = plus_comp[comp]
    # one side per tetrahedron and defect
    tk = inc_t * (int(ids.max()) + 1) + ids[j]
    o = np.argsort(tk, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(tk[o])) + 1]
    p = plus[o].astype(np.int8)
    if np.any(np.minimum.reduceat(p, starts) != np.maximum.reduceat(p, starts)):
        raise CutError("a tetrahedron lies on the '+' side of one node and the '-' side of another of the same "
                       "defect: the mesh is too coarse for the surface; decrease mesh_size or tip_size")
    return plus


def check_cut(c: Cut3) -> None:
    """No tetrahedron touches both copies of a node; every doubled node has tetrahedra on both sides."""
    n0 = c.points.shape[1] - c.upper.size
    both, lonely = cut_faults(c.points.shape[1], c.tets, c.lower, c.upper)
    if both:
        raise CutError("a tetrahedron touches both copies of a doubled node")
    if lonely.size or c.upper.size and c.upper.min() < n0:
        j = int(lonely[0]) if lonely.size else 0
        raise CutError(f"defects[{int(c.defect_id[j])}]: the doubled node at "
                       f"{np.round(c.points[:, c.lower[j]], 6).tolist()} has tetrahedra on one side only")
