"""Sparse linear algebra shared by the solvers: factor once what never changes.

The thin-defect QP has all of its nonlinearity (the contact constraint) and all of its
parameter dependence (the 1/delta interface term) on a few *local* unknowns I (the doubled
defect nodes): ``K = K_fixed + K_param`` with ``K_param`` supported on I x I and ``B`` on I.
So the QP reduces exactly to the local unknowns:

    x_R = K_RR^-1 (F_R - K_RI x_I)                       (R = the other unknowns)
    Pi(x) = 1/2 x_I' S x_I - g' x_I + c0,    S = S_fixed + K_param[I, I],
    S_fixed = K_II - K_IR K_RR^-1 K_RI       (dense, |I| x |I|, |I| = 4 m for the defect)

:class:`FixedFactor` factorizes ``K_fixed`` once, with a nested-dissection ordering of R and the
unknowns I ordered *last*; then the trailing blocks of the LU factors give the Schur complement
directly, ``S_fixed = L_II U_II`` (no extra solves). It is cached by a hash of ``K_fixed`` and
I, so every delta, load case and solver that shares the mesh reuses it.

:class:`LocalReduction` is what solvers use: ``S``, ``g``, ``B_I`` (dense), ``full(x_I)`` to
recover all of x with one more solve, ``c0`` (energy constant), ``k_solve`` (K^-1 r for the whole
K) and ``dual()`` (the Delassus matrix D = B K^-1 B' and the gaps b0 at zero contact force).
"""
from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as dla
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as sla

from dualfem.core.qp import QP

#: unknowns per leaf of the nested dissection
_LEAF = 64
_CACHE: OrderedDict[str, FixedFactor] = OrderedDict()
_CACHE_SIZE = 4


def _hash(*arrays: np.ndarray) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


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
    """(k, n_nodes) array of the unknowns of each mesh node, if the QP carries ``node_dofs``."""
    nd = qp.maps.get("node_dofs")
    if nd is None:
        return None
    nd = np.asarray(nd)
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
        coords = qp.maps.get("nodes")
        if coords is not None and np.asarray(qp.maps.get("node_dofs")).shape[1] == np.asarray(coords).shape[1]:
            xy = np.asarray(coords, float)[:, np.all(np.asarray(qp.maps["node_dofs"]) >= 0, axis=0)][:, rest_nodes]
            order_nodes = rest_nodes[geometric_nested_dissection(xy, Gr)]
        else:
            order_nodes = rest_nodes[nested_dissection(Gr)]
        rest = groups[:, order_nodes].T.ravel()
    else:
        rest_idx = np.flatnonzero(~is_local)
        rest = rest_idx[nested_dissection(pattern[rest_idx][:, rest_idx])]
    return np.concatenate([rest, np.asarray(local, np.int64)])


# --------------------------------------------------------------------------- factor
@dataclass
class FixedFactor:
    """LU of ``K_fixed`` with the local unknowns last, and its Schur complement onto them."""

    n: int
    local: np.ndarray
    perm: np.ndarray
    lu: object
    S_fixed: np.ndarray
    time_s: dict = field(default_factory=dict)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K_fixed^-1 b."""
        pb = b[self.perm]
        y = self.lu.solve(pb)
        x = np.empty_like(y)
        x[self.perm] = y
        return x


def factor_fixed(qp: QP) -> FixedFactor:
    """Factorize ``qp.K_fixed`` with ``qp.local_dofs`` last (cached across QPs sharing them)."""
    local = np.asarray(qp.local_dofs, np.int64)
    Kf = qp.K_fixed.tocsc()
    key = _hash(Kf.indptr, Kf.indices, Kf.data, local)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    t0 = time.perf_counter()
    perm = ordering(qp, local)
    Kp = Kf[perm][:, perm].tocsc()
    t1 = time.perf_counter()
    lu = sla.splu(Kp, permc_spec="NATURAL", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
    t2 = time.perf_counter()
    n, nl = Kp.shape[0], local.size
    # the trailing nl columns must still be the local unknowns after SuperLU's postordering
    pc = lu.perm_c
    pr = lu.perm_r
    tail = np.sort(pc[n - nl:]) if nl else pc[:0]
    if nl and not (np.array_equal(tail, np.arange(n - nl, n)) and np.array_equal(pr[n - nl:], pc[n - nl:])):
        raise RuntimeError("SuperLU moved the local unknowns: cannot read the Schur complement")
    S = _trailing_schur(lu, n, nl)
    # SuperLU's perm_c may permute within the trailing block: map back to ``local`` order
    if nl:
        inv = np.empty(n, np.int64)
        inv[pc] = np.arange(n)          # position in factor of original (permuted-matrix) column
        pos = inv[np.arange(n - nl, n)] - (n - nl)
        S = S[np.ix_(pos, pos)]
    S = 0.5 * (S + S.T)
    t3 = time.perf_counter()
    ff = FixedFactor(n=n, local=local, perm=perm, lu=lu, S_fixed=S,
                     time_s={"ordering": t1 - t0, "factorize": t2 - t1, "schur": t3 - t2})
    _CACHE[key] = ff
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return ff


def _trailing_schur(lu, n: int, nl: int) -> np.ndarray:
    """L_II U_II from the trailing nl x nl blocks of SuperLU's factors."""
    if nl == 0:
        return np.zeros((0, 0))
    L = lu.L.tocsc()[:, n - nl:]
    L = L[n - nl:, :].toarray()
    U = lu.U.tocsc()[:, n - nl:]
    U = U[n - nl:, :].toarray()
    return L @ U


def clear_cache() -> None:
    """Forget every cached factorization."""
    _CACHE.clear()


# ------------------------------------------------------------------------ reduction
class LocalReduction:
    """Exact reduction of a QP onto its local unknowns I (see module docstring).

    Attributes: ``I`` (indices into x), ``S`` (dense Schur complement of K onto I, includes the
    parameter part), ``g`` (reduced load), ``BI`` (dense ``B[:, I]``), ``c0`` (energy constant:
    ``Pi(full(xI)) = 1/2 xI'S xI - g'xI + c0``), ``factor`` (the shared :class:`FixedFactor`).
    """

    def __init__(self, qp: QP):
        self.qp = qp
        t0 = time.perf_counter()
        self.factor = ff = factor_fixed(qp)
        t1 = time.perf_counter()
        I = ff.local
        self.I = I
        Kp = (qp.K - qp.K_fixed).tocoo()
        is_local = np.zeros(qp.n, bool)
        is_local[I] = True
        big = np.abs(Kp.data) > 0
        if np.any(big & ~(is_local[Kp.row] & is_local[Kp.col])):
            raise ValueError("K - K_fixed must be supported on local_dofs x local_dofs")
        Kp = Kp.tocsr()
        self.S = ff.S_fixed + Kp[I][:, I].toarray()
        self.S = 0.5 * (self.S + self.S.T)
        self.BI = qp.B[:, I].toarray()
        self.u_fixed = ff.solve(qp.F)                    # K_fixed^-1 F
        self.g = ff.S_fixed @ self.u_fixed[I]
        self.c0 = float(-0.5 * qp.F @ self.u_fixed + 0.5 * self.g @ self.u_fixed[I])
        self.time_s = {"factor": t1 - t0, "reduce": time.perf_counter() - t1}
        self._S_cho = None
        self._dual = None

    def full(self, xI: np.ndarray) -> np.ndarray:
        """All unknowns x from the local ones (one solve with the cached factor)."""
        e = np.zeros(self.qp.n)
        e[self.I] = self.factor.S_fixed @ xI - self.g
        return self.factor.solve(self.qp.F + e)

    def energy(self, xI: np.ndarray) -> float:
        """Pi of the full vector determined by xI."""
        return float(0.5 * xI @ (self.S @ xI) - self.g @ xI + self.c0)

    def norm2(self, xI: np.ndarray) -> float:
        """x'Kx of the full vector determined by xI (without forming it)."""
        return float(xI @ (self.S @ xI) - 2.0 * self.c0)

    @property
    def S_cho(self):
        """Dense Cholesky factor of S (computed once; ``scipy.linalg.cho_solve`` format)."""
        if self._S_cho is None:
            self._S_cho = dla.cho_factor(self.S, lower=True, check_finite=True)
        return self._S_cho

    def dual(self) -> tuple[np.ndarray, np.ndarray]:
        """(D, b0) of the reduced dual LCP, computed once: the Delassus matrix D = B K^-1 B'
        (dense m x m, symmetric positive definite) and b0 = B K^-1 F, the gaps B x at mu = 0.
        The gaps at contact forces mu are ``D mu + b0``."""
        if self._dual is None:
            D = self.BI @ dla.cho_solve(self.S_cho, self.BI.T)
            self._dual = (0.5 * (D + D.T), self.BI @ dla.cho_solve(self.S_cho, self.g))
        return self._dual

    def k_solve(self, r: np.ndarray) -> np.ndarray:
        """K^-1 r for the whole K (two solves with the cached factor of K_fixed).

        With K = K_fixed + K_param (K_param on I x I): u = K_fixed^-1 r, the local part solves
        ``S x_I = S_fixed u_I``, and x = K_fixed^-1 (r + e) with e_I = S_fixed x_I - S_fixed u_I.
        """
        ff = self.factor
        u = ff.solve(r)
        gI = ff.S_fixed @ u[self.I]
        xI = dla.cho_solve(self.S_cho, gI)
        e = np.zeros_like(r)
        e[self.I] = ff.S_fixed @ xI - gI
        return ff.solve(r + e)


#: dense Schur complement onto more local unknowns than this is refused (memory ~ 8 n^2 bytes)
MAX_LOCAL = 12000


def too_many_local(qp: QP, limit: int = MAX_LOCAL) -> str | None:
    """Skip reason for solvers that form the dense reduced matrix, or None if it fits."""
    nI = int(np.asarray(qp.local_dofs).size)
    if nI > limit:
        return f"{nI} local unknowns: the dense reduced matrix would exceed {limit}^2"
    return None
