"""Fill-reducing orderings of the QP's unknowns with a chosen set (the local unknowns) last.

Used by the backends that take an external order (SuperLU; CHOLMOD for its Schur complement):
with the local unknowns I ordered last, the trailing blocks of the factor give the Schur
complement onto I directly. Moved here from :mod:`dualfem.numerics.linalg` (which re-exports them).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

if TYPE_CHECKING:
    from dualfem.core.qp import QP

#: unknowns per leaf of the nested dissection
_LEAF = 64


# ----------------------------------------------------------------------------- ordering
def nested_dissection(adj: sp.csr_matrix, leaf: int = _LEAF) -> np.ndarray:
    """Fill-reducing elimination order of a symmetric sparsity graph (level-set separators).

    Each part is split by a middle breadth-first level set seen from a pseudo-peripheral
    vertex; the two halves are ordered recursively, the separator last. Works on any mesh graph.
    """
    adj = sp.csr_matrix(adj)
    adj = (adj + adj.T).tocsr()
    adj.setdiag(0)
    adj.eliminate_zeros()
    adj.data[:] = 1.0
    out: list[np.ndarray] = []

    def rec(part: np.ndarray, sub: sp.csr_matrix) -> None:
        if part.size <= leaf:
            out.append(part)
            return
        ncomp, lab = csgraph.connected_components(sub, directed=False)
        if ncomp > 1:
            for c in range(ncomp):
                idx = np.flatnonzero(lab == c)
                rec(part[idx], sub[idx][:, idx])
            return
        dist = csgraph.breadth_first_order(sub, 0, directed=False, return_predecessors=False)
        far = dist[-1]
        lev = _levels(sub, far)
        lev = _levels(sub, int(np.argmax(lev)))
        counts = np.bincount(lev)
        cum = np.cumsum(counts)
        mid = int(np.searchsorted(cum, part.size / 2))
        mid = min(max(mid, 1), len(counts) - 2) if len(counts) >= 3 else None
        if mid is None:
            out.append(part)
            return
        a = np.flatnonzero(lev < mid)
        b = np.flatnonzero(lev > mid)
        s = np.flatnonzero(lev == mid)
        rec(part[a], sub[a][:, a])
        rec(part[b], sub[b][:, b])
        out.append(part[s])

    n = adj.shape[0]
    rec(np.arange(n), adj)
    perm = np.concatenate(out) if out else np.arange(0)
    assert perm.size == n
    return perm


def geometric_nested_dissection(coords: np.ndarray, adj: sp.spmatrix, leaf: int = _LEAF) -> np.ndarray:
    """Fill-reducing order from node coordinates: recursive median bisection, all parts at once.

    Each part is cut at the median of its longer coordinate extent; the vertex separator is the
    set of nodes on the upper side with a neighbour on the lower side (on a structured mesh, one
    grid line: the shortest possible separator). Parts are processed level by level with
    vectorized numpy, so the cost is O(n log n) with no per-part Python overhead.
    """
    n = coords.shape[1]
    if n == 0:
        return np.zeros(0, np.int64)
    adj = sp.coo_matrix(adj)
    ei, ej = adj.row, adj.col
    keep = ei != ej
    ei, ej = np.r_[ei[keep], ej[keep]], np.r_[ej[keep], ei[keep]]
    part = np.zeros(n, np.int64)        # current part id; -1 once a node's position is final
    code = np.zeros(n, np.int64)        # base-3 path: 0 = lower half, 1 = upper half, 2 = separator
    depth = np.zeros(n, np.int64)
    d = 0
    while True:
        act = np.flatnonzero(part >= 0)
        if act.size == 0:
            break
        sizes = np.bincount(part[act])
        small = sizes[part[act]] <= leaf
        part[act[small]] = -1                   # leaves: final, internal order = index order
        act = act[~small]
        if act.size == 0:
            break
        # longer extent of each part's bounding box, then the median along it
        pid = part[act]
        order = np.argsort(pid, kind="stable")
        a_sorted, p_sorted = act[order], pid[order]
        starts = np.flatnonzero(np.r_[True, p_sorted[1:] != p_sorted[:-1]])
        ext = [np.maximum.reduceat(coords[k, a_sorted], starts) - np.minimum.reduceat(coords[k, a_sorted], starts)
               for k in range(coords.shape[0])]
        axis_of = np.argmax(np.vstack(ext), axis=0)              # per part (in 'starts' order)
        uniq = p_sorted[starts]
        axis_map = np.zeros(part.max() + 1, np.int64)
        axis_map[uniq] = axis_of
        c = coords[axis_map[pid], act]
        o2 = np.lexsort((c, pid))
        a2, p2, c2 = act[o2], pid[o2], c[o2]
        st2 = np.flatnonzero(np.r_[True, p2[1:] != p2[:-1]])
        cnt = np.diff(np.r_[st2, a2.size])
        med = np.zeros(part.max() + 1)
        med[p2[st2]] = c2[st2 + cnt // 2]
        upper = np.zeros(n, bool)
        upper[act] = c >= med[pid]
        # separator: upper-side nodes adjacent to a lower-side node of the same part
        same = (part[ei] == part[ej]) & (part[ei] >= 0)
        lower_i = same & ~upper[ei] & upper[ej]
        sep = np.zeros(n, bool)
        sep[ej[lower_i]] = True
        sep &= part >= 0
        digit = np.where(sep, 2, np.where(upper, 1, 0))
        code[act] = code[act] * 3 + digit[act]
        depth[act] += 1
        newpart = part.copy()
        newpart[act] = 2 * part[act] + (digit[act] == 1)
        newpart[sep] = -1
        # compact the part ids
        live = newpart >= 0
        present = np.zeros(2 * int(part.max()) + 2, bool)
        present[newpart[live]] = True
        newpart[live] = (np.cumsum(present) - 1)[newpart[live]]
        part = newpart
        d += 1
        if d > 60:
            raise RuntimeError("geometric nested dissection did not terminate")
    key = code * (3 ** (depth.max() - depth))
    return np.argsort(key, kind="stable")


def _levels(g: sp.csr_matrix, src: int) -> np.ndarray:
    d = csgraph.shortest_path(g, method="D", unweighted=True, indices=src)
    return d.astype(np.int64)


def _node_groups(qp: QP) -> np.ndarray | None:
    """(k, n_nodes) array of the unknowns of each mesh node, if the QP carries a geometry."""
    if qp.geometry is None:
        return None
    nd = qp.geometry.node_dofs
    keep = np.all(nd >= 0, axis=0)
    return nd[:, keep]


def ordering(qp: QP, local: np.ndarray) -> np.ndarray:
    """Order of all unknowns: nested dissection of the non-local ones, then ``local`` last."""
    n = qp.n
    is_local = np.zeros(n, bool)
    is_local[local] = True
    groups = _node_groups(qp)
    pattern = qp.K_fixed.tocsr()
    if groups is not None and np.all(is_local[groups].all(axis=0) | ~is_local[groups].any(axis=0)) \
            and np.unique(groups).size == groups.size and groups.size == n:
        # compress to the node graph (all components of a node together)
        node_of = np.empty(n, np.int64)
        node_of[groups.ravel()] = np.tile(np.arange(groups.shape[1]), groups.shape[0])
        nn = groups.shape[1]
        P = sp.csr_matrix((np.ones(n), (node_of, np.arange(n))), shape=(nn, n))
        G = (P @ (pattern != 0).astype(float) @ P.T).tocsr()
        rest_nodes = np.flatnonzero(~is_local[groups[0]])
        Gr = G[rest_nodes][:, rest_nodes]
        geo = qp.geometry
        if geo is not None:
            xy = geo.nodes[:, np.all(geo.node_dofs >= 0, axis=0)][:, rest_nodes]
            order_nodes = rest_nodes[geometric_nested_dissection(xy, Gr)]
        else:
            order_nodes = rest_nodes[nested_dissection(Gr)]
        rest = groups[:, order_nodes].T.ravel()
    else:
        rest_idx = np.flatnonzero(~is_local)
        rest = rest_idx[nested_dissection(pattern[rest_idx][:, rest_idx])]
    return np.concatenate([rest, np.asarray(local, np.int64)])


def pattern_ordering(A: sp.spmatrix, local: np.ndarray) -> np.ndarray:
    """Order of all unknowns of ``A`` from its pattern alone: nested dissection of the rest, ``local`` last."""
    n = A.shape[0]
    local = np.asarray(local, np.int64)
    is_local = np.zeros(n, bool)
    is_local[local] = True
    rest_idx = np.flatnonzero(~is_local)
    A = sp.csr_matrix(A)
    rest = rest_idx[nested_dissection(A[rest_idx][:, rest_idx])]
    return np.concatenate([rest, local])
