"""A defect group's elements put in order: a 2D curve as one chain of nodes, a 3D surface consistently oriented.

The "+" normal of a defect follows the file: in 2D the tangent from a line element's first node to its
second turned by +90 degrees (as the box scenes' polylines: the "+" face is on the left of the direction of
travel), in 3D the right-hand normal of a triangle (first, second, third node). Where the file's elements
disagree, the majority decides (a chain's direction; a surface's orientation, propagated across shared
edges). Refused (InputError naming the defect): a curve that branches, closes on itself or falls in
pieces; a surface with an edge of more than two triangles, one that cannot be oriented (a Moebius strip),
or one in pieces ("give each crack its own group").
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from dualfem.errors import InputError


def chain(lines: np.ndarray, what: str) -> np.ndarray:
    """The nodes of a curve's line elements (2, ne) as one ordered chain (ne + 1,), directed as most of the
    file's elements."""
    a, b = lines
    nodes, inv = np.unique(lines, return_inverse=True)
    inv = inv.reshape(2, -1)
    k = nodes.size
    deg = np.bincount(inv.ravel(), minlength=k)
    if deg.max() > 2:
        raise InputError(f"{what}: the curve branches at {_at(nodes[np.argmax(deg > 2)])}; one crack is one "
                         f"open curve (give each branch its own group)")
    A = sp.coo_matrix((np.ones(a.size), (inv[0], inv[1])), shape=(k, k))
    ncomp, _ = connected_components(A, directed=False)
    if ncomp > 1:
        raise InputError(f"{what}: the curve is {ncomp} separate pieces; give each crack its own group")
    if a.size != k - 1:
        raise InputError(f"{what}: the curve is closed; a crack is an open curve (a closed one cuts a piece out)")
    start = int(np.flatnonzero(deg == 1)[0])
    order = breadth_first_order(A, start, directed=False, return_predecessors=False)
    pos = np.empty(k, np.int64)
    pos[order] = np.arange(k)
    forward = np.count_nonzero(pos[inv[0]] < pos[inv[1]])
    out = nodes[order]
    return out if 2 * forward >= a.size else out[::-1]


def _at(node) -> str:
    return f"node {int(node)}"


def orient_surface(tris: np.ndarray, what: str) -> np.ndarray:
    """The triangles (3, nf) of a surface with two nodes swapped where needed so that all are oriented alike
    (neighbours run their shared edge in opposite directions), as most of the file's triangles are."""
    nf = tris.shape[1]
    d = np.hstack([tris[[0, 1]], tris[[1, 2]], tris[[2, 0]]])           # directed edges (2, 3 nf)
    owner = np.tile(np.arange(nf), 3)
    und = np.sort(d, axis=0)
    _, inv, cnt = np.unique(und, axis=1, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    if cnt.max() > 2:
        raise InputError(f"{what}: an edge is shared by {cnt.max()} triangles (the surface is not a manifold)")
    shared = np.flatnonzero(cnt[inv] == 2)
    o = shared[np.argsort(inv[shared], kind="stable")]
    i, j = o[0::2], o[1::2]
    same = (d[0, i] == d[0, j]).astype(np.int8)                         # same direction: one of them flips
    G = sp.coo_matrix((same.astype(float) + 1.0, (owner[i], owner[j])), shape=(nf, nf)).tocsr()
    ncomp, _ = connected_components(G, directed=False)
    if ncomp > 1:
        raise InputError(f"{what}: the surface is {ncomp} separate pieces; give each crack its own group")
    order, pred = breadth_first_order(G + G.T, 0, directed=False, return_predecessors=True)
    W = (G + G.T).tocsr()
    flip = np.zeros(nf, np.int8)
    for t in order[1:]:
        p = pred[t]
        flip[t] = flip[p] ^ (int(W[t, p]) - 1)
    if np.any((flip[owner[i]] ^ flip[owner[j]]) != same):
        raise InputError(f"{what}: the surface cannot be oriented (its triangles cannot all agree on a normal)")
    if 2 * np.count_nonzero(flip) > nf:
        flip ^= 1
    out = tris.copy()
    out[[0, 1]] = np.where(flip.astype(bool), tris[[1, 0]], tris[[0, 1]])
    return out
