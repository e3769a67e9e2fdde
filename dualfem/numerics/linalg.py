"""Sparse linear algebra shared by the solvers: factor once what never changes.

The thin-defect QP has all of its nonlinearity (the contact constraint) and all of its
parameter dependence (the 1/delta interface term) on a few *local* unknowns I (the doubled
defect nodes): ``K = K_fixed + K_param`` with ``K_param`` supported on I x I and ``B`` on I.
So the QP reduces exactly to the local unknowns:

    x_R = K_RR^-1 (F_R - K_RI x_I)                       (R = the other unknowns)
    Pi(x) = 1/2 x_I' S x_I - g' x_I + c0,    S = S_fixed + K_param[I, I],
    S_fixed = K_II - K_IR K_RR^-1 K_RI       (dense, |I| x |I|, |I| = 4 m for the defect)

:class:`FixedFactor` factorizes ``K_fixed`` once with a backend of :mod:`dualfem.numerics.factor`
(PARDISO computes S_fixed itself; SuperLU/CHOLMOD order I *last* and read S_fixed from the
trailing blocks of the factors, no extra solves). It is kept by the :class:`FactorStore` that
``QP.store`` names (the owner's: a :class:`dualfem.workspace.Workspace` shares one across every
delta, load case and solver of its mesh; a QP built alone gets a private one), keyed by
``K_fixed``, I and the backend. No factorization is kept by the module.

:class:`LocalReduction` is what solvers use: ``S``, ``g``, ``B_I`` (dense), ``full(x_I)`` to
recover all of x, ``c0`` (energy constant), ``k_solve`` (K^-1 r for the whole K), ``k_quad``
(r'K^-1 r and (K^-1 r)_I, for the certificate) and ``dual()`` (the Delassus matrix
D = B K^-1 B' and the gaps b0 at zero contact force). Solves are split at I (the backends'
``forward`` / ``backward`` halves, each half a solve with PARDISO): ``full`` is a backward half
(the forward half of F is delta-free and remembered), ``k_quad`` a forward half.
"""
from __future__ import annotations

import hashlib
import time
import weakref
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as dla
import scipy.sparse as sp

from dualfem.core.qp import QP
from dualfem.numerics.factor import Backend, Factorization, Forward
from dualfem.numerics.factor import choose as choose_backend
from dualfem.numerics.factor.ordering import geometric_nested_dissection, nested_dissection, ordering  # noqa: F401
from dualfem.numerics.threads import ensure_threads


def _hash(*arrays: np.ndarray) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(memoryview(np.ascontiguousarray(a)).cast("B"))      # no copy of contiguous arrays
    return h.hexdigest()


def _frozen(a) -> bool:
    """True if ``a`` and every array it is a view of are read-only (its content cannot change)."""
    if not isinstance(a, np.ndarray):
        return False
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return a is None


def freeze(*arrays: np.ndarray) -> None:
    """Make arrays (and the arrays they are views of) read-only: a :class:`FactorStore` then knows them by
    identity instead of hashing their contents on every look-up."""
    for a in arrays:
        chain = []
        while isinstance(a, np.ndarray):
            chain.append(a)
            a = a.base
        for b in reversed(chain):               # the base first: a view of a read-only base stays read-only
            b.flags.writeable = False


def _root(a: np.ndarray) -> np.ndarray:
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a


# --------------------------------------------------------------------------- factor
@dataclass
class FixedFactor:
    """Factorization of ``K_fixed`` (by the chosen backend) and its Schur complement onto the local unknowns."""

    n: int
    local: np.ndarray
    fact: Factorization
    S_fixed: np.ndarray
    time_s: dict = field(default_factory=dict)
    #: the forward half of K_fixed^-1 F by a hash of F (delta-free: shared by every delta of a sweep),
    #: the last two loads
    loads: OrderedDict = field(default_factory=OrderedDict)

    def forward_load(self, F: np.ndarray) -> Forward:
        """``forward(F)``, remembered for the last two load vectors."""
        key = _hash(F)
        fwd = self.loads.get(key)
        if fwd is None:
            fwd = self.forward(F)
            freeze(fwd.g, fwd.state)          # shared by every reduction of this load: read-only
            self.loads[key] = fwd
            while len(self.loads) > 2:
                self.loads.popitem(last=False)
        return fwd

    @property
    def backend(self) -> str:
        """Name of the factorization backend (superlu, pardiso, cholmod)."""
        return self.fact.backend

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K_fixed^-1 b (b of shape (n,) or (n, k))."""
        return self.fact.solve(b)

    def forward(self, b: np.ndarray) -> Forward:
        """The forward half of K_fixed^-1 b, split at the local unknowns (see
        :class:`dualfem.numerics.factor.Forward`): half a solve with PARDISO."""
        return self.fact.forward(b)

    def backward(self, fwd: Forward, xI: np.ndarray) -> np.ndarray:
        """x with x_I = xI and x_R = K_RR^-1 (b_R - K_RI xI), b the vector of ``fwd``: the other half."""
        return self.fact.backward(fwd, xI)


class FactorStore:
    """The factorizations of ``K_fixed`` that one owner reuses (LRU, ``size`` entries): an ordinary object.

    A QP names the store that owns its factorizations in ``QP.store``: a
    :class:`dualfem.workspace.Workspace` gives every QP it builds its own store, so every delta, load
    case and solver of the workspace reuses one factorization; a QP built elsewhere gets a private store
    on first use (:func:`store_of`), shared by the solvers and the certificate that work on it.

    Entries are keyed by (K_fixed, local unknowns, backend). Read-only ("frozen", :func:`freeze`)
    arrays, such as the delta-free stiffness a workspace's QPs share, are known by identity: the memory
    they view (root array, address, shape, strides), so another view of it finds the entry, and the
    store keeps those roots, so their ids cannot be reused while the entry lives; no hashing. Any
    other array is known by a SHA-1 of its contents, computed on every look-up, so a K_fixed changed
    in place gets a new factorization. ``factorizations`` counts the factorizations made for this store
    (:meth:`clear` does not reset it).
    """

    def __init__(self, size: int = 4):
        self.size = int(size)
        self.factorizations = 0
        self._d: OrderedDict[str, FixedFactor] = OrderedDict()
        #: key of frozen arrays -> their roots, kept alive so that their ids stay theirs while the key is used
        self._known: dict[str, list[np.ndarray]] = {}

    def key(self, arrays: tuple[np.ndarray, ...], tag: str) -> str:
        """The key of ``arrays`` plus ``tag``: identity of frozen memory, else a hash of the contents."""
        if not all(_frozen(a) for a in arrays):
            return "sha1:" + _hash(*arrays) + tag
        roots = [_root(a) for a in arrays]
        k = "frozen:" + repr(tuple((id(r), a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str)
                                   for r, a in zip(roots, arrays))) + tag
        self._known.setdefault(k, roots)
        return k

    def get(self, key: str) -> FixedFactor | None:
        ff = self._d.get(key)
        if ff is not None:
            self._d.move_to_end(key)
        return ff

    def put(self, key: str, ff: FixedFactor) -> None:
        self._d[key] = ff
        while len(self._d) > self.size:
            self._d.popitem(last=False)
        self._forget_unused()

    def _forget_unused(self) -> None:
        for k in [k for k in self._known if k not in self._d]:
            del self._known[k]

    def clear(self) -> None:
        """Forget every factorization (cold timings, memory); their memory is released when no solver holds
        them any more."""
        self._d.clear()
        self._known.clear()

    def __len__(self) -> int:
        return len(self._d)


def store_of(qp: QP) -> FactorStore:
    """The :class:`FactorStore` that owns ``qp``'s factorizations: ``qp.store``, set to a private new
    one when it is None."""
    store = qp.store
    if store is None:
        store = qp.store = FactorStore()
    if not isinstance(store, FactorStore):
        raise TypeError(f"QP.store must be a dualfem.numerics.linalg.FactorStore or None, got {type(store).__name__}")
    return store


def _stored(store: FactorStore, key: str, make) -> FixedFactor:
    """The store's entry ``key``, else ``make()`` put there and counted as one factorization of the store."""
    ff = store.get(key)
    if ff is None:
        ff = make()
        store.put(key, ff)
        store.factorizations += 1
    return ff


def factor_fixed(qp: QP, factor: str | Backend | None = None, store: FactorStore | None = None) -> FixedFactor:
    """Factorize ``qp.K_fixed`` with its Schur complement onto ``qp.local_dofs``, once per store.

    ``factor``: backend name or object (default: :func:`dualfem.numerics.factor.choose`, i.e.
    ``--factor`` / ``DUALFEM_FACTOR`` / the fastest installed); ``store``: default the QP's own
    (:func:`store_of`).
    """
    backend = choose_backend(factor)
    ensure_threads()
    store = store_of(qp) if store is None else store
    local = np.asarray(qp.local_dofs, np.int64)
    Kf = qp.K_fixed if qp.K_fixed.format in ("csr", "csc") else qp.K_fixed.tocsr()
    key = store.key((Kf.indptr, Kf.indices, Kf.data, local), f":{Kf.format}:{backend.name}")

    def make() -> FixedFactor:
        K = Kf.tocsr()
        t0 = time.perf_counter()
        ref = weakref.ref(qp)         # the factorization must not keep the QP alive (QP -> store -> factor)
        fact = backend.make(local, order=lambda: ordering(ref(), local))
        fact.analyze(K)
        t1 = time.perf_counter()
        fact.factorize(K)
        t2 = time.perf_counter()
        S = fact.schur()
        t3 = time.perf_counter()
        return FixedFactor(n=K.shape[0], local=local, fact=fact, S_fixed=S,
                           time_s={"ordering": t1 - t0, "factorize": t2 - t1, "schur": t3 - t2})

    return _stored(store, key, make)


def factor_whole(qp: QP, factor: str | Backend | None = None, store: FactorStore | None = None) -> Factorization:
    """The factorization of the whole K (no Schur set: the matrix-free dual operator's), once per store."""
    backend = choose_backend(factor)
    ensure_threads()
    store = store_of(qp) if store is None else store
    K = qp.K if qp.K.format in ("csr", "csc") else qp.K.tocsr()
    key = store.key((K.indptr, K.indices, K.data), f":{K.format}:whole:{backend.name}")

    def make() -> FixedFactor:
        t0 = time.perf_counter()     # on the elastic part's pattern: the same K, its node blocks kept
        fact = backend.factor(on_fixed_pattern(K, qp.local.K_fixed if qp.local is not None else None))
        return FixedFactor(n=K.shape[0], local=np.zeros(0, np.int64), fact=fact, S_fixed=np.zeros((0, 0)),
                           time_s={"factorize": time.perf_counter() - t0})

    return _stored(store, key, make).fact


def on_fixed_pattern(K: sp.spmatrix, K_fixed: sp.spmatrix | None) -> sp.csr_matrix:
    """K with the stored pattern of ``K_fixed`` added as explicit zeros (the same matrix, CSR).

    scipy's sum K_el + interface term drops the entries that cancel exactly (on the structured mesh
    the x-x and y-y couplings across each triangle's diagonal), so the two unknowns of a node stop
    having identical rows and a supernodal factorization (PARDISO) loses its 2 x 2 node blocks: on
    K_el's pattern the same K factors in 0.75-0.80 of the CPU time (benchmarks/results/floor_gap).
    Without ``K_fixed`` (or of another shape) K itself, as CSR."""
    K = K.tocsr()
    if K_fixed is None or K_fixed.shape != K.shape:
        return K
    Kf = K_fixed.tocoo()
    Kc = K.tocoo()
    U = sp.coo_matrix((np.concatenate([Kc.data, np.zeros(Kf.nnz)]),
                       (np.concatenate([Kc.row, Kf.row]), np.concatenate([Kc.col, Kf.col]))), shape=K.shape)
    out = U.tocsr()                      # duplicates summed; the explicit zeros kept
    out.sort_indices()
    return out


def sparse_factor(A: sp.spmatrix, factor: str | Backend | None = None) -> Factorization:
    """Factorization of a whole SPD sparse matrix by the chosen backend (no Schur set, not cached)."""
    ensure_threads()
    return choose_backend(factor).factor(A)


# ------------------------------------------------------------------------ reduction
class LocalReduction:
    """Exact reduction of a QP onto its local unknowns I (see module docstring).

    Attributes: ``I`` (indices into x), ``S`` (dense Schur complement of K onto I, includes the
    parameter part), ``g`` (reduced load), ``BI`` (dense ``B[:, I]``), ``c0`` (energy constant:
    ``Pi(full(xI)) = 1/2 xI'S xI - g'xI + c0``), ``factor`` (the shared :class:`FixedFactor`).
    ``factor=`` names the backend (default: the process-wide choice), ``store=`` the
    :class:`FactorStore` (default: the QP's own, :func:`store_of`).
    """

    def __init__(self, qp: QP, factor: str | Backend | None = None, store: FactorStore | None = None):
        self.qp = qp
        t0 = time.perf_counter()
        self.factor = ff = factor_fixed(qp, factor, store)
        t1 = time.perf_counter()
        I = ff.local
        self.I = I
        self.S = ff.S_fixed + _local_param_block(qp, I)
        self.S = 0.5 * (self.S + self.S.T)
        self.BI = qp.B[:, I].toarray()
        self.time_s = {"factor": t1 - t0, "reduce": time.perf_counter() - t1}
        self._S_cho = None
        self._dual = None
        self._D: np.ndarray | None = None
        self._V: np.ndarray | None = None
        self._load: tuple[Forward, float] | None = None
        self._last_forward: tuple[np.ndarray, Forward] | None = None

    def _reduced_load(self) -> tuple[Forward, float]:
        """(forward half of K_fixed^-1 F, c0), computed on first use (half a solve with PARDISO, shared
        by every delta of a sweep)."""
        if self._load is None:
            fwd = self.factor.forward_load(self.qp.F)
            self._load = (fwd, -0.5 * fwd.q)          # Pi(full(0)) = -1/2 F_R' K_RR^-1 F_R
        return self._load

    @property
    def g(self) -> np.ndarray:
        """Reduced load on the local unknowns: F_I - K_IR K_RR^-1 F_R."""
        return self._reduced_load()[0].g

    @property
    def c0(self) -> float:
        """Energy constant: Pi(full(xI)) = 1/2 xI'S xI - g'xI + c0."""
        return self._reduced_load()[1]

    def full(self, xI: np.ndarray) -> np.ndarray:
        """All unknowns x from the local ones: x_R = K_RR^-1 (F_R - K_RI xI), the backward half of a
        solve (the forward half of F is remembered)."""
        return self.factor.backward(self._reduced_load()[0], xI)

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

    def half_delassus(self) -> np.ndarray:
        """V = L^-1 B_I' (|I| x m; S = L L', L = ``S_cho[0]``), computed once: D = V'V."""
        if self._V is None:
            self._V = dla.solve_triangular(self.S_cho[0], self.BI.T, lower=True, check_finite=False)
        return self._V

    def delassus(self) -> np.ndarray:
        """The Delassus matrix D = B K^-1 B' = V'V (dense m x m, symmetric positive definite;
        one triangular solve with m right-hand sides and a symmetric product), computed once."""
        if self._D is None:
            V = self.half_delassus()
            self._D = V.T @ V
        return self._D

    def dual(self) -> tuple[np.ndarray, np.ndarray]:
        """(D, b0) of the reduced dual LCP: :meth:`delassus` and b0 = B K^-1 F, the gaps B x at
        mu = 0. The gaps at contact forces mu are ``D mu + b0``."""
        if self._dual is None:
            self._dual = (self.delassus(), self.BI @ dla.cho_solve(self.S_cho, self.g))
        return self._dual

    def _k_parts(self, r: np.ndarray) -> tuple[Forward, np.ndarray]:
        """(forward half of K_fixed^-1 r, z_I = (K^-1 r)_I = S^-1 g): half a solve with PARDISO.

        Since K and K_fixed differ on I x I only, the forward half of K_fixed serves K: the reduced
        right-hand side g of r is the same, and S replaces S_fixed. The last (r, forward) pair is
        remembered: a refinement step that is not taken (see :meth:`refine`) leaves x unchanged,
        and the certificate then asks for the very same r.
        """
        last = self._last_forward
        if last is not None and np.array_equal(last[0], r):
            fwd = last[1]
        else:
            fwd = self.factor.forward(r)
            self._last_forward = (np.array(r), fwd)
        return fwd, dla.cho_solve(self.S_cho, fwd.g)

    def k_quad(self, r: np.ndarray) -> tuple[float, np.ndarray]:
        """(r'K^-1 r, (K^-1 r)[I]) from the forward half of one solve (no K^-1 r is formed):
        r'K^-1 r = r_R' K_RR^-1 r_R + g' S^-1 g, a sum of two non-negative terms. Used by the
        a-posteriori certificate, which needs only these."""
        fwd, zI = self._k_parts(r)
        return _quad(fwd, zI), zI

    def refine(self, x: np.ndarray, mu: np.ndarray, A: np.ndarray, skip_below: float = 0.0,
               Kx: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """One exact refinement step of the KKT system on the active set A, in one solve.

        The step of :func:`dualfem.numerics.certify.refinement_step`: ``K dx - B_A' dmu_A = -r``,
        ``B_A dx = -B_A x``, r = Kx - F - B'mu from the full-space K. The forward half of the solve
        with r gives z_I = (K^-1 r)_I (:meth:`_k_parts`); dmu_A from the Delassus block;
        dx_I = -z_I + S^-1 B_I' dmu (since (K^-1)_II = S^-1); the backward half completes
        dx = K^-1 (-r + B'dmu) from dx_I (B'dmu lives on I, so the forward half of -r serves; the
        step is solved from the residual, as iterative refinement must be). Before the backward
        half the size of the step is known exactly,
        |dx|_K^2 = r'K^-1 r - 2 (B K^-1 r)'dmu + dmu'D dmu; when |dx|_K <= skip_below |x|_K the
        step is not taken and None is returned (x is then accurate to that size, and its forward
        half is remembered for the certificate). Returns (x + dx, mu + dmu). ``Kx``: the product
        K x, if known.
        """
        qp = self.qp
        Kx = qp.K @ x if Kx is None else Kx
        r = Kx - qp.F - qp.B.T @ mu
        fwd, zI = self._k_parts(r)
        dmu = np.zeros_like(mu, dtype=float)
        D = self.delassus() if A.any() else None
        if D is not None:
            dmu[A] = dla.solve(D[np.ix_(A, A)], -(qp.B[A] @ x - self.BI[A] @ zI), assume_a="pos")
        if skip_below > 0:
            Bz = self.BI @ zI
            size = step_size(_quad(fwd, zI), Bz, dmu, D @ dmu if D is not None else np.zeros_like(dmu))
            if size <= skip_below * np.sqrt(max(float(x @ Kx), 0.0)):
                return None
        dxI = -zI + dla.cho_solve(self.S_cho, self.BI.T @ dmu)
        dx = self.factor.backward(Forward(fwd.q, -fwd.g, -fwd.state), dxI)
        return x + dx, mu + dmu

    def k_solve(self, r: np.ndarray) -> np.ndarray:
        """K^-1 r for the whole K: the forward half with K_fixed, z_I = S^-1 g, the backward half
        (one solve with PARDISO, two with the generic split)."""
        fwd, zI = self._k_parts(r)
        return self.factor.backward(fwd, zI)


def _quad(fwd: Forward, zI: np.ndarray) -> float:
    """r'K^-1 r = r_R' K_RR^-1 r_R + g' S^-1 g from the forward half of r and z_I = S^-1 g."""
    return fwd.q + float(fwd.g @ zI)


def step_size(rKr: float, Bz: np.ndarray, dmu: np.ndarray, Ddmu: np.ndarray) -> float:
    """|dx|_K of the exact refinement step on an active set, without forming dx: with z = K^-1 r
    (r = Kx - F - B'mu) and the multiplier step dmu, dx = -z + K^-1 B'dmu, so
    |dx|_K^2 = r'K^-1 r - 2 (Bz)'dmu + dmu'D dmu (``Ddmu`` = D dmu; rounding can make it < 0: 0)."""
    return float(np.sqrt(max(rKr - 2.0 * float(Bz @ dmu) + float(dmu @ Ddmu), 0.0)))


def _local_param_block(qp: QP, I: np.ndarray) -> np.ndarray:
    """Dense ``(K - K_fixed)[I, I]``; ValueError if K - K_fixed has an entry outside I x I.

    When K and K_fixed share their sparsity pattern (the problem layer's case) the difference is
    taken on the stored values, without forming another n x n sparse matrix.
    """
    K, Kf = qp.K, qp.K_fixed
    if K.format not in ("csr", "csc") or Kf.format != K.format:
        K, Kf = K.tocsr(), Kf.tocsr()
    is_local = np.zeros(qp.n, bool)
    is_local[I] = True
    if K.nnz == Kf.nnz and np.array_equal(K.indptr, Kf.indptr) and np.array_equal(K.indices, Kf.indices) \
            and K.has_canonical_format and Kf.has_canonical_format:      # cheap tests first
        nz = np.flatnonzero(K.data != Kf.data)
        major = np.searchsorted(K.indptr, nz, side="right") - 1      # rows of CSR, columns of CSC
        ij = (major, K.indices[nz]) if K.format == "csr" else (K.indices[nz], major)
        Kp = sp.csr_matrix((K.data[nz] - Kf.data[nz], ij), shape=K.shape)
    else:
        Kp = (K - Kf).tocsr()
    Kp.eliminate_zeros()
    coo = Kp.tocoo()
    if np.any(~(is_local[coo.row] & is_local[coo.col])):
        raise ValueError("K - K_fixed must be supported on local_dofs x local_dofs")
    return Kp[I][:, I].toarray()


#: dense Schur complement onto more local unknowns than this is refused (memory ~ 8 n^2 bytes)
MAX_LOCAL = 12000


def too_many_local(qp: QP, limit: int = MAX_LOCAL) -> str | None:
    """Skip reason for solvers that form the dense reduced matrix, or None if it fits."""
    nI = int(np.asarray(qp.local_dofs).size)
    if nI > limit:
        return f"{nI} local unknowns: the dense reduced matrix would exceed {limit}^2"
    return None
