"""CHOLMOD (SuiteSparse) through scikit-sparse, when ``sksparse.cholmod`` imports.

Analysis = ``sksparse.cholmod.analyze`` (symbolic; pattern only), numeric factorization =
``Factor.cholesky_inplace``, solve = ``Factor(b)`` (1-D or 2-D). Without a Schur set CHOLMOD orders
the matrix itself (its default: AMD, or METIS when compiled in). With local unknowns the matrix
is permuted by the nested-dissection order with the local unknowns last and analyzed with the
``natural`` ordering, so that ``P A P' = L L'`` has them in its trailing block and the Schur
complement is ``L_II L_II'``. If CHOLMOD nevertheless permutes them (``Factor.P()``), the Schur
complement falls back to |I| solves (exact, slower).

Not installed on the development machine: tests/test_factor.py exercises it only when it imports.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .base import Backend, Factorization, OrderHint
from .ordering import pattern_ordering


class CholmodFactorization(Factorization):
    backend = "cholmod"

    def _analyze(self, A: sp.csr_matrix) -> None:
        from sksparse.cholmod import analyze

        perm = None
        if self.local.size:
            perm = self.order()
            perm = pattern_ordering(A, self.local) if perm is None else np.asarray(perm, np.int64)
        self.perm = perm
        Ap = self._permuted(A)
        self._f = analyze(Ap, mode="supernodal", ordering_method="natural" if perm is not None else "default")
        self.info["ordering"] = "given/nested dissection, local last" if perm is not None else "CHOLMOD default"

    def _permuted(self, A: sp.csr_matrix) -> sp.csc_matrix:
        return (A if self.perm is None else A[self.perm][:, self.perm]).tocsc()

    def _factorize(self, A: sp.csr_matrix) -> None:
        self._f.cholesky_inplace(self._permuted(A))

    def _solve(self, b: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return np.asarray(self._f(b))
        y = np.asarray(self._f(np.ascontiguousarray(b[self.perm])))
        x = np.empty_like(y)
        x[self.perm] = y
        return x

    def _own_schur(self) -> np.ndarray:
        n, nl = self.n, self.local.size
        if self.perm is None or not np.array_equal(self._f.P(), np.arange(n)):
            return super()._own_schur()
        L = self._f.L().tocsc()[:, n - nl:][n - nl:, :].toarray()
        S = L @ L.T
        where = np.empty(n, np.int64)
        where[self.perm[n - nl:]] = np.arange(nl)
        p = where[self.local]
        S = S[np.ix_(p, p)]
        return 0.5 * (S + S.T)

    def free(self) -> None:
        self._f = None
        super().free()


class CholmodBackend(Backend):
    name = "cholmod"
    install_hint = "pip install 'dualfem[cholmod]'  (scikit-sparse; needs SuiteSparse headers)"
    memory_model = "pardiso"          # not measured here: a supernodal Cholesky of PARDISO's size

    @classmethod
    def available(cls) -> bool:
        try:
            import sksparse.cholmod  # noqa: F401
        except ImportError:
            return False
        return True

    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        return CholmodFactorization(local, order)
