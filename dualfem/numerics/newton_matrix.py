"""Generalized Newton matrices ``H(c) = K + B' diag(c) B`` (c >= 0) on one fixed sparsity pattern.

The semismooth Newton methods on the primal contact problem (the paper's Uzawa inner loop, the
penalty method) solve with ``K + B' diag(c) B`` where c is a positive coefficient on the current
active set and 0 elsewhere (``r w_j`` for Uzawa, ``rho w_j`` for the penalty). Whatever the active
set, the matrix lives on the pattern of ``K + B'B``: the inactive rows are stored as explicit zeros.
So the fill-reducing ordering and the symbolic factorization (the backend's ``analyze``,
:mod:`dualfem.numerics.factor`) are done once, and each new set of coefficients costs one numeric
``factorize`` only (the :class:`~dualfem.numerics.factor.Factorization` API checks that the pattern
is the analyzed one).

Assembly is one sparse product: ``H.data = K on the pattern + M c`` with M (nnz(H) x m) holding the
products b_ja b_jb of each row j of B at the positions (a, b) of the pattern, so no sparse-sparse
product is formed per active set (and none could drop a zero and change the pattern).

Numeric factors are kept by coefficient vector (the active set and its coefficients) in ``keep``
slots, least recently used first out, so an active set met again is not refactorized. With PARDISO
the slots are MKL's ``maxfct`` factors of one analyzed structure (one handle, one analysis for all);
with another backend each slot is a Factorization of its own, analyzed when first used (SuperLU's
analysis is only an ordering). When the backend reports the factor's size at analysis (PARDISO),
``keep`` is lowered to what half the available memory holds. The counters
(``NewtonMatrix.counters``, a :class:`NewtonCounters`) say what was done: analyses, numeric factorizations, reuses of a
kept factor, solves, seconds per phase.

Without a factorization (``factor="amg"``, where none of K fits: 3D): each coefficient vector gets a
pyamg smoothed-aggregation hierarchy of H(c) (near-nullspace ``modes``: the rigid-body modes) kept in the
same slots, and H(c)^-1 rhs is AMG-preconditioned CG to the relative residual ``rtol``
(:class:`dualfem.numerics.amg.AmgKSolve`); ``counters.factorizations`` then counts hierarchies.

Memory: one factor of K + B'B per slot, about the size of K's (B couples only the unknowns of the two
faces of a defect node, which K's interface term couples already; docs/measurements.md) plus the pattern
and M.
"""
from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from dualfem.numerics.factor import Backend, Factorization, backend_class, registered
from dualfem.numerics.factor import choose as choose_backend
from dualfem.numerics.threads import ensure_threads

__all__ = ["NewtonMatrix", "NewtonCounters"]


@dataclass
class NewtonCounters:
    """Work done with a :class:`NewtonMatrix` (reported in the solvers' ``Solution.info``)."""

    analyses: int = 0          #: symbolic analyses (1 with PARDISO; one per slot used with other backends)
    factorizations: int = 0    #: numeric factorizations (one per new coefficient vector met)
    reuses: int = 0            #: solves that found their factor kept
    solves: int = 0            #: solves (a block of k right-hand sides counts k)
    time_s: dict = field(default_factory=dict)   #: seconds: pattern, analyze, factorize, solve

    def as_dict(self) -> dict:
        return asdict(self)


def _canonical(A: sp.spmatrix) -> sp.csr_matrix:
    A = sp.csr_matrix(A, dtype=float, copy=True)
    A.sum_duplicates()
    A.sort_indices()
    return A


class NewtonMatrix:
    """``H(c) = K + B' diag(c) B`` on the pattern of K + B'B: analyzed once, factorized per c (module docstring).

    ``K`` (n x n, SPD sparse), ``B`` (m x n sparse), ``factor``: a backend name or object (default: the
    process-wide choice, :func:`dualfem.numerics.factor.choose`), ``keep``: numeric factors kept.
    """

    def __init__(self, K: sp.spmatrix, B: sp.spmatrix, factor: str | Backend | None = None, keep: int = 4,
                 modes: np.ndarray | None = None, rtol: float | None = None):
        #: a non-direct backend (``amg``): AMG-preconditioned CG per coefficient vector instead of a
        #: factorization (module docstring)
        self.amg = isinstance(factor, str) and factor.strip().lower() in registered(direct=False)
        self.modes, self.rtol = modes, rtol
        kb: Any = backend_class(str(factor)) if self.amg else None
        self.backend: Any = kb(modes, rtol) if self.amg else choose_backend(factor)
        ensure_threads()
        t0 = time.perf_counter()
        K, B = _canonical(K), _canonical(B)
        n, m = K.shape[0], B.shape[0]
        if K.shape != (n, n) or B.shape[1] != n:
            raise ValueError(f"K of shape {K.shape} and B of shape {B.shape} do not match")
        self.n, self.m, self.keep = n, m, max(int(keep), 1)
        # the pattern of K + B'B (every value positive: no cancellation can drop an entry)
        Kp = sp.csr_matrix((np.ones(K.nnz), K.indices, K.indptr), shape=K.shape)
        Bp = sp.csr_matrix((np.ones(B.nnz), B.indices, B.indptr), shape=B.shape)
        P = (Kp + (Bp.T @ Bp)).tocsr()
        P.sum_duplicates()
        P.sort_indices()
        self.indptr, self.indices = P.indptr, P.indices
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(P.indptr))
        keys = rows * n + P.indices.astype(np.int64)           # increasing: canonical CSR
        # K's values on the pattern
        Kr = np.repeat(np.arange(n, dtype=np.int64), np.diff(K.indptr))
        self.k_values = np.zeros(P.nnz)
        self.k_values[np.searchsorted(keys, Kr * n + K.indices)] = K.data
        # M: column j holds b_ja b_jb at the positions (a, b) of row j's outer product
        counts = np.diff(B.indptr)
        pos_l, col_l, val_l = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0)]
        for k in np.unique(counts[counts > 0]):
            js = np.flatnonzero(counts == k)
            idx = B.indptr[js][:, None] + np.arange(k)[None, :]            # (r, k) positions in B.data
            cols, vals = B.indices[idx].astype(np.int64), B.data[idx]
            a, b = np.broadcast_arrays(cols[:, :, None], cols[:, None, :])
            pos_l.append(np.searchsorted(keys, (a * n + b).ravel()))
            col_l.append(np.repeat(js, k * k))
            val_l.append((vals[:, :, None] * vals[:, None, :]).ravel())
        self.M = sp.csr_matrix((np.concatenate(val_l), (np.concatenate(pos_l), np.concatenate(col_l))),
                               shape=(P.nnz, m))
        #: coefficient vector (bytes) -> slot of its kept numeric factor, least recently used first
        self._slots: OrderedDict[bytes, int] = OrderedDict()
        #: one analysis, ``keep`` numeric factors in one object where the backend has it (PARDISO:
        #: :meth:`~dualfem.numerics.factor.base.Backend.multi_factor`); other backends: one object per slot
        self._shared = None if self.amg else self.backend.multi_factor(self.keep)
        self._facts: list = []
        self.counters = NewtonCounters()
        self.counters.time_s["pattern"] = time.perf_counter() - t0

    @property
    def nnz(self) -> int:
        """Entries of the fixed pattern (those of K + B'B)."""
        return int(self.indices.size)

    def matrix(self, c: np.ndarray) -> sp.csr_matrix:
        """``K + B' diag(c) B`` on the fixed pattern (zeros stored where c vanishes)."""
        c = np.asarray(c, float)
        if c.shape != (self.m,):
            raise ValueError(f"coefficients of shape {c.shape}: expected ({self.m},)")
        data = self.k_values + self.M @ c
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    def factor(self, c: np.ndarray) -> Factorization:
        """The numeric factorization of H(c): a kept one, else a new one in the least recently used slot."""
        c = np.ascontiguousarray(c, float)
        key = c.tobytes()
        hit = self._slots.get(key)
        if hit is not None:
            self._slots.move_to_end(key)
            self.counters.reuses += 1
            return self._facts[hit] if self.amg else self._select(hit)
        ts = self.counters.time_s
        H = self.matrix(c)
        if len(self._slots) >= self.keep:
            _, slot = self._slots.popitem(last=False)
        else:
            slot = len(self._slots)
        if self.amg:
            return self._amg_slot(slot, key, H)
        fact = self._select(slot)
        if not fact.n:                          # never analyzed (PARDISO: one analysis for every slot)
            t0 = time.perf_counter()
            fact.analyze(H)
            ts["analyze"] = ts.get("analyze", 0.0) + time.perf_counter() - t0
            self.counters.analyses += 1
            self._fit_keep(fact)
        t0 = time.perf_counter()
        fact.factorize(H)
        ts["factorize"] = ts.get("factorize", 0.0) + time.perf_counter() - t0
        self.counters.factorizations += 1
        self._slots[key] = slot
        return fact

    def _amg_slot(self, slot: int, key: bytes, H: sp.csr_matrix):
        """A new AMG hierarchy of H in ``slot`` (the amg mode's 'factorization')."""
        from dualfem.numerics.amg import RTOL, AmgKSolve

        t0 = time.perf_counter()
        solver = AmgKSolve(H, self.modes, RTOL if self.rtol is None else self.rtol)
        while len(self._facts) <= slot:
            self._facts.append(None)
        self._facts[slot] = solver
        ts = self.counters.time_s
        ts["factorize"] = ts.get("factorize", 0.0) + time.perf_counter() - t0
        self.counters.factorizations += 1
        self._slots[key] = slot
        return solver

    def _fit_keep(self, fact: Factorization) -> None:
        """Keep no more factors than half the memory available holds (PARDISO reports a factor's size
        at analysis; other backends: unchanged). At least one."""
        from dualfem.numerics.memory import available_bytes

        size = int(fact.info.get("factor_bytes") or 0)
        if size > 0 and self.keep > 1:
            self.keep = max(1, min(self.keep, int(0.5 * available_bytes() // size)))

    def _select(self, slot: int) -> Factorization:
        """The factorization object of ``slot``, made current (PARDISO: one object, factor ``slot``)."""
        if self._shared is not None:
            self._shared.slot(slot)  # type: ignore[union-attr]
            return self._shared
        while len(self._facts) <= slot:
            self._facts.append(self.backend.make())
        return self._facts[slot]

    def solve(self, c: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """``H(c)^-1 rhs`` (rhs of shape (n,) or (n, k))."""
        fact = self.factor(c)
        t0 = time.perf_counter()
        x = fact.solve(rhs)
        ts = self.counters.time_s
        ts["solve"] = ts.get("solve", 0.0) + time.perf_counter() - t0
        self.counters.solves += 1 if np.ndim(rhs) == 1 else np.shape(rhs)[1]
        return x

    def info(self) -> dict:
        """Counters for ``Solution.info`` (prefixed ``newton_``; the pattern's size)."""
        d = self.counters.as_dict()
        out = {f"newton_{k}": v for k, v in d.items() if k != "time_s"}
        out["newton_time_s"] = dict(d["time_s"])
        out["newton_pattern_nnz"] = self.nnz
        out["newton_keep"] = self.keep
        out["newton_backend"] = self.backend.name
        return out

    def free(self) -> None:
        """Release the kept factors."""
        for f in ([self._shared] if self._shared is not None else []) + self._facts:
            if f is not None:
                f.free()
        self._slots.clear()
        self._facts.clear()
