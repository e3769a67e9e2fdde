"""Preconditioners of the dual operator D = B K^-1 B' for the dual solvers (FETI-style), none with a K-solve.

* :func:`jacobi_scaling`: ``s = diag(D)^-1/2`` for the change of variables ``mu = S nu``
  (``S = diag(s)``): the scaled operator ``S D S`` has a unit diagonal and the bounds ``nu >= 0``
  stay exactly the bounds ``mu >= 0`` (S is diagonal and positive). diag(D) is the operator's
  (:meth:`~dualfem.numerics.dual_operator.DualOperator.diagonal`: exact when dense, a calibrated
  estimate when matrix-free).
* :func:`lumped_inverse`: FETI's lumped preconditioner ``M^-1 = W B K B' W``, ``W = diag(B B')^-1``
  (sparse m x m).
* :func:`dirichlet_inverse`: FETI's Dirichlet preconditioner ``M^-1 = W B S_loc B' W`` with S_loc the
  Schur complements of K onto each crack's unknowns from a layer of elements around it (sparse,
  one dense block per crack).

Why the Dirichlet one: with nodal forces, D's large eigenvalues are the modes smooth along a crack
(a force spread over a crack of length L opens it by ~ L/h times a nodal force's opening), so
cond(D) ~ L/h. K itself (lumped) is spectrally a constant on the crack and does not see that; the
exact Schur complement S of K onto the crack does (the conditions measured: docs/measurements.md). A
layer of r rings recovers the modes shorter than ~r h.

The approximate inverses are used "in face" (:class:`FacePreconditioner`): only the rows and
columns of the free set F act, ``z_F = (M^-1)_FF r_F``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: the preconditioner names of the ``precond`` parameter of mprgp
PRECONDS = ("none", "jacobi", "lumped", "dirichlet")
#: at most this many rows per dense block: a larger cluster (a long crack, a network of touching cracks)
#: is cut into pieces of consecutive rows (memory ~ 8 (4 MAX_BLOCK)^2 bytes per block)
MAX_BLOCK = 512
#: a crack's layer (with the crack) up to this many unknowns is factorized dense, a larger one by a sparse LU
DENSE_LAYER = 1500


def jacobi_scaling(op) -> np.ndarray:
    """``s = diag(D)^-1/2`` (m,) from the operator's diagonal (non-positive entries: the mean)."""
    d = np.asarray(op.diagonal(), float)
    pos = d[d > 0]
    d = np.where(d > 0, d, pos.mean() if pos.size else 1.0)
    return 1.0 / np.sqrt(d)


def lumped_inverse(qp) -> sp.csr_matrix:
    """``W B K B' W`` with ``W = diag(B B')^-1`` (sparse m x m, symmetric positive semidefinite)."""
    B = qp.B.tocsr(copy=True)          # own arrays: scipy may sort them in place (the runner's QP is read-only)
    K = qp.K.tocsr(copy=True)
    bb = np.asarray(B.multiply(B).sum(axis=1)).ravel()
    w = np.where(bb > 0, 1.0 / np.where(bb > 0, bb, 1.0), 0.0)
    W = sp.diags(w)
    M = (W @ (B @ K @ B.T) @ W).tocsr()
    return ((M + M.T) * 0.5).tocsr()


class FacePreconditioner:
    """``z = P_F M^-1 P_F r``: a sparse approximate inverse M^-1 (m x m) applied on the free set F
    only (zero elsewhere); the restriction to F of an SPD matrix is SPD, so CG on the face stays CG.
    The face's submatrix is cached while F does not change (CG steps).
    """

    def __init__(self, Minv: sp.csr_matrix):
        self.Minv = Minv.tocsr()
        self._free: np.ndarray | None = None
        self._sub: sp.csr_matrix | None = None
        self._idx: np.ndarray | None = None

    def __call__(self, r: np.ndarray, free: np.ndarray) -> np.ndarray:
        if self._free is None or not np.array_equal(free, self._free):
            self._free = free.copy()
            self._idx = np.flatnonzero(free)
            self._sub = self.Minv[self._idx][:, self._idx].tocsr()
        z = np.zeros_like(r)
        z[self._idx] = self._sub @ r[self._idx]
        return z


def _gather(A: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(local row, column, value) of the entries of the rows ``rows`` of A (CSR), in numpy only."""
    starts, ends = A.indptr[rows], A.indptr[rows + 1]
    lens = ends - starts
    idx = np.arange(lens.sum()) - np.repeat(np.cumsum(lens) - lens, lens) + np.repeat(starts, lens)
    return np.repeat(np.arange(rows.size), lens), A.indices[idx], A.data[idx]


def _grow(K: sp.csr_matrix, seed: np.ndarray, layers: int) -> np.ndarray:
    """The unknowns within ``layers`` steps of ``seed`` in the graph of K (sorted)."""
    region = np.unique(seed)
    front = region
    for _ in range(layers):
        if front.size == 0:
            break
        new = np.setdiff1d(np.unique(_gather(K, front)[1]), region, assume_unique=True)
        region = np.union1d(region, new)
        front = new
    return region


def defect_clusters(qp) -> tuple[int, np.ndarray]:
    """(count, label per row of B): the rows coupled through K (B K B' != 0), i.e. one cluster per crack."""
    import scipy.sparse.csgraph as csg

    B = qp.B.tocsr(copy=True)          # own arrays: scipy may sort them in place (the runner's QP is read-only)
    G = (abs(B) @ abs(qp.K.tocsr(copy=True)) @ abs(B).T).tocsr()
    return csg.connected_components(G, directed=False)


def dirichlet_by_default(qp) -> bool:
    """Whether a solver's ``precond="auto"`` takes :func:`dirichlet_inverse`: in 2D (a crack's layers hold a
    few hundred unknowns), not in 3D, where a surface's element layers make the local Schur complements
    large (their cost: docs/measurements.md): there the solvers take a diagonal preconditioner."""
    return qp.geometry is None or qp.geometry.dim != 3


def dirichlet_inverse(qp, layers: int = 4) -> sp.csr_matrix:
    """``W B S_loc B' W``: FETI's Dirichlet preconditioner with local Schur complements (sparse m x m).

    Per cluster c of defect rows (:func:`defect_clusters`: one per crack), I_c = the unknowns its rows
    of B act on and R_c = the other unknowns within ``layers`` rings of elements (graph steps of K)
    around them, clamped outside: ``S_c = K_cc - K_cR K_RR^-1 K_Rc`` (dense: a few hundred unknowns per
    crack), ``M_c = W_c B_c S_c B_c' W_c``; M^-1 is the block-diagonal sum of the
    M_c. As the layer widens S_c tends to the exact Schur complement of K onto the crack, with which
    ``W B S B' W`` inverts D on the crack (cond(M D) close to 1: docs/measurements.md);
    a layer of r rings catches the modes along the crack shorter than about r elements, so
    cond(M D) ~ crack length / (r h) instead of crack length / h. W = diag(B B')^-1. A cluster of
    more than :data:`MAX_BLOCK` rows is cut into pieces of consecutive rows (each its own block).
    """
    from dualfem.numerics.threads import dense_threads

    B = qp.B.tocsr(copy=True)          # own arrays: scipy may sort them in place (the runner's QP is read-only)
    K = qp.K.tocsr(copy=True)
    bb = np.asarray(B.multiply(B).sum(axis=1)).ravel()
    w = np.where(bb > 0, 1.0 / np.where(bb > 0, bb, 1.0), 0.0)
    ncl, lab = defect_clusters(qp)
    pos = np.full(K.shape[0], -1, np.int64)
    order = np.argsort(lab, kind="stable")
    starts = np.searchsorted(lab[order], np.arange(ncl + 1))
    rows, cols, vals = [], [], []
    with dense_threads():                 # small dense blocks: one BLAS thread (threads.py)
        for c in range(ncl):
            r = order[starts[c]:starts[c + 1]]
            for k in range(0, r.size, MAX_BLOCK):     # a long crack or a crack network: pieces
                _dirichlet_block(B, K, w, r[k:k + MAX_BLOCK], int(layers), pos, rows, cols, vals)
    m = B.shape[0]
    if not rows:
        return sp.csr_matrix((m, m))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, m))


def _dirichlet_block(B, K, w, r, layers, pos, rows, cols, vals) -> None:
    """M_c of :func:`dirichlet_inverse` for the rows r of one cluster, appended as COO triplets."""
    import scipy.linalg as sla

    br, bc, bv = _gather(B, r)
    Ic = np.unique(bc)
    U = _grow(K, Ic, int(layers))
    pos[U] = np.arange(U.size)
    kr, kc, kv = _gather(K, U)
    kc = pos[kc]
    keep = kc >= 0
    pos[U] = -1
    pos[Ic] = np.arange(Ic.size)
    Bd = np.zeros((r.size, Ic.size))
    np.add.at(Bd, (br, pos[bc]), bv)
    Bd *= w[r][:, None]
    inI = pos[U] >= 0
    pos[Ic] = -1
    i_loc, r_loc = np.flatnonzero(inI), np.flatnonzero(~inI)     # U is sorted and so is Ic: same order
    if U.size <= DENSE_LAYER:
        KU = np.zeros((U.size, U.size))
        np.add.at(KU, (kr[keep], kc[keep]), kv[keep])
        S = KU[np.ix_(i_loc, i_loc)]
        if r_loc.size:
            KRI = KU[np.ix_(r_loc, i_loc)]
            S = S - KRI.T @ sla.solve(KU[np.ix_(r_loc, r_loc)], KRI, assume_a="pos", check_finite=False)
    else:                                 # a long crack: its layer is large, a sparse LU is cheaper
        import scipy.sparse.linalg as spla

        KU = sp.csr_matrix((kv[keep], (kr[keep], kc[keep])), shape=(U.size, U.size))
        S = KU[i_loc][:, i_loc].toarray()
        if r_loc.size:
            KRI = KU[r_loc][:, i_loc].toarray()
            S = S - KRI.T @ spla.splu(KU[r_loc][:, r_loc].tocsc()).solve(KRI)
    Mc = Bd @ (0.5 * (S + S.T)) @ Bd.T
    rows.append(np.repeat(r, r.size))
    cols.append(np.tile(r, r.size))
    vals.append(0.5 * (Mc + Mc.T).ravel())
