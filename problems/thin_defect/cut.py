"""Cutting a triangle mesh along defect polylines: node doubling, normals, trapezoid weights.

A defect is an ordered list of mesh nodes (its first and last are the tips) joined by mesh
edges. Every node strictly inside a defect gets a copy at the same place; the original node
becomes the "-" (lower) face node, the copy the "+" (upper) face node, and the tips stay single.

Orientation rule: along a defect from its first to its last point, the normal nu is the tangent
turned by +90 degrees (counter-clockwise), i.e. it points to the left of the direction of travel;
the "+" face is the side nu points to. For the default horizontal defect (0.25, 0.5) -> (0.75,
0.5), nu = (0, 1) and "+" is the upper face. At a node the normal is the normalised average of
the unit normals of its two defect edges (kinks allowed).

A triangle at a doubled node v with defect neighbours p (before) and n (after) lies on the "+"
side iff the direction from v to its centroid lies in the counter-clockwise angular sector from
n - v to p - v; it then uses the copy of v. Each triangle's node ids are stored in ascending
order (as scikit-fem's ``MeshTri`` does). The trapezoid weight of node j is half the length of
its two defect edges: integral over the defect of phi ~ sum_j w_j phi_j for phi vanishing at the tips.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualfem.errors import InputError

from .._interface import DoubledNodes, double_nodes


@dataclass
class Cut(DoubledNodes):
    """The doubled mesh and the defect nodes, ordered defect by defect, first to last point.

    ``lower``/``upper`` (m,): node ids of the "-" / "+" copies; ``defect_id`` (m,): which defect;
    ``normals``/``tangents`` (2, m) unit vectors; ``weights`` (m,) trapezoid weights (length);
    ``s`` (m,) arc length from the defect's first point; ``tips`` (2 ndef,): first and last node
    of each defect; ``length`` (ndef,).
    """

    triangles: np.ndarray
    tangents: np.ndarray
    s: np.ndarray
    tips: np.ndarray
    length: np.ndarray


def _edge_geometry(p: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(p[:, nodes], axis=1)
    ln = np.hypot(d[0], d[1])
    return d / ln, ln


def cut(points: np.ndarray, triangles: np.ndarray, defects: list[np.ndarray], mesh_label: str = "the mesh") -> Cut:
    """Double the interior nodes of every defect polyline (see the module docstring).

    ``mesh_label`` names the mesh in error messages (e.g. ``"N=4"``).
    """
    nn = points.shape[1]
    if not defects:             # an uncracked body (defects = []): nothing doubled, no contact pairs
        none = np.zeros(0, np.int64)
        return Cut(points=points, triangles=np.sort(triangles, axis=0), lower=none, upper=none, defect_id=none,
                   normals=np.zeros((2, 0)), tangents=np.zeros((2, 0)), weights=np.zeros(0), s=np.zeros(0),
                   tips=none, length=np.zeros(0))
    seen = np.zeros(nn, dtype=np.int64) - 1
    lower, ids, nrm, tng, w, s, prev, nxt, tips, length = ([] for _ in range(10))
    for k, nodes in enumerate(defects):
        nodes = np.asarray(nodes, dtype=np.int64)
        if nodes.size < 3:
            raise InputError(f"{mesh_label} is too coarse: defect {k} spans a single mesh edge, so no node can be "
                             f"doubled; refine it (increase N or decrease mesh_size)")
        clash = seen[nodes] >= 0
        if np.any(clash):
            other = int(seen[nodes][clash][0])
            raise InputError(f"defects {other} and {k} touch (they share mesh nodes); defects must not touch or cross")
        seen[nodes] = k
        tau, ln = _edge_geometry(points, nodes)
        en = np.vstack([-tau[1], tau[0]])
        avg = en[:, :-1] + en[:, 1:]
        nrm.append(avg / np.hypot(avg[0], avg[1]))
        at = tau[:, :-1] + tau[:, 1:]
        tng.append(at / np.hypot(at[0], at[1]))
        w.append(0.5 * (ln[:-1] + ln[1:]))
        s.append(np.cumsum(ln)[:-1])
        lower.append(nodes[1:-1])
        prev.append(nodes[:-2])
        nxt.append(nodes[2:])
        ids.append(np.full(nodes.size - 2, k, dtype=np.int64))
        tips.append(nodes[[0, -1]])
        length.append(ln.sum())
    _check_edges(triangles, defects, seen >= 0)
    lower_a = np.concatenate(lower)
    doubled, upper_a = double_nodes(points, lower_a)
    t = _assign_sides(points, triangles, lower_a, upper_a, np.concatenate(prev), np.concatenate(nxt))
    return Cut(points=doubled, triangles=t, lower=lower_a, upper=upper_a,
               defect_id=np.concatenate(ids), normals=np.hstack(nrm), tangents=np.hstack(tng),
               weights=np.concatenate(w), s=np.concatenate(s), tips=np.concatenate(tips),
               length=np.array(length))


def _check_edges(t: np.ndarray, defects: list[np.ndarray], on_defect: np.ndarray) -> None:
    """Every pair of consecutive defect nodes must be a mesh edge (else the mesher is at fault)."""
    near = t[:, on_defect[t].any(axis=0)].astype(np.int64)
    nn = on_defect.size
    e = np.hstack([near[[0, 1]], near[[1, 2]], near[[2, 0]]])
    have = np.minimum(e[0], e[1]) * nn + np.maximum(e[0], e[1])
    nodes = [np.asarray(d, dtype=np.int64) for d in defects]
    a = np.concatenate([d[:-1] for d in nodes])
    b = np.concatenate([d[1:] for d in nodes])
    want = np.minimum(a, b) * nn + np.maximum(a, b)
    missing = ~np.isin(want, have)                      # one search for all defects
    if missing.any():
        k = int(np.repeat(np.arange(len(nodes)), [d.size - 1 for d in nodes])[np.argmax(missing)])
        raise ValueError(f"defect {k}: consecutive defect nodes are not joined by mesh edges "
                         f"(the mesh does not carry the defect)")


def _assign_sides(p, t, lower, upper, prev, nxt) -> np.ndarray:
    """Triangles with the doubled nodes on the "+" side renumbered to the copies."""
    nn = p.shape[1]
    slot = np.full(nn, -1, dtype=np.int64)
    slot[lower] = np.arange(lower.size)
    sl = slot[t]
    corner, tri = np.nonzero(sl >= 0)
    j = sl[corner, tri]
    v = p[:, lower[j]]
    cen = p[:, t[:, tri]].mean(axis=1)
    two_pi = 2 * np.pi

    def ang(d):
        return np.arctan2(d[1], d[0])

    a_n = ang(p[:, nxt[j]] - v)
    rel_d = np.mod(ang(cen - v) - a_n, two_pi)
    rel_p = np.mod(ang(p[:, prev[j]] - v) - a_n, two_pi)
    plus = rel_d < rel_p
    out = t.copy()
    out[corner[plus], tri[plus]] = upper[j[plus]]
    return np.sort(out, axis=0)  # node ids ascending per triangle, as scikit-fem's MeshTri stores them
