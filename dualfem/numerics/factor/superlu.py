"""SuperLU (scipy.sparse.linalg.splu): always available.

Analysis = the fill-reducing order (nested dissection of the non-local unknowns, the local
unknowns last; or the order given by the caller, e.g. the geometric one of
:func:`dualfem.numerics.factor.ordering.ordering`); SuperLU itself has no separate symbolic phase
in scipy. Numeric factorization = ``splu`` of the permuted matrix in symmetric mode without
pivoting (A is SPD). The Schur complement onto the local unknowns is read from the trailing
blocks of the factors: ``S = L_II U_II`` (no extra solves).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .base import Backend, Factorization, OrderHint
from .ordering import pattern_ordering


class SuperLUFactorization(Factorization):
    backend = "superlu"

    def _analyze(self, A: sp.csr_matrix) -> None:
        perm = self.order()
        if perm is None:
            perm = pattern_ordering(A, self.local) if self.local.size else None
        if perm is not None:
            perm = np.asarray(perm, np.int64)
            nl = self.local.size
            if perm.size != self.n or (nl and not np.array_equal(np.sort(perm[self.n - nl:]), np.sort(self.local))):
                raise ValueError("order must be a permutation of all unknowns with the local ones last")
        self.perm = perm
        self.info["ordering"] = "given/nested dissection, local last" if perm is not None else "MMD_AT_PLUS_A"

    def _factorize(self, A: sp.csr_matrix) -> None:
        opts = {"SymmetricMode": True}
        if self.perm is None:
            self.lu = sla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=opts)
        else:
            Ap = A[self.perm][:, self.perm].tocsc()
            self.lu = sla.splu(Ap, permc_spec="NATURAL", diag_pivot_thresh=0.0, options=opts)
        self.info["factor_nnz"] = int(self.lu.nnz)
        # L and U values (8 B) + row indices (4 B): what the factor holds
        self.info["factor_bytes"] = int(12 * self.lu.nnz)

    def _solve(self, b: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return self.lu.solve(b)
        y = self.lu.solve(np.ascontiguousarray(b[self.perm]))
        x = np.empty_like(y)
        x[self.perm] = y
        return x

    def _own_schur(self) -> np.ndarray:
        if self.perm is None:
            return super()._own_schur()
        n, nl = self.n, self.local.size
        lu = self.lu
        pc, pr = lu.perm_c, lu.perm_r
        # the trailing nl columns must still be the local unknowns after SuperLU's postordering
        tail_ok = np.array_equal(np.sort(pc[n - nl:]), np.arange(n - nl, n))
        if not (tail_ok and np.array_equal(pr[n - nl:], pc[n - nl:])):
            raise RuntimeError("SuperLU moved the local unknowns: cannot read the Schur complement")
        L = lu.L.tocsc()[:, n - nl:][n - nl:, :].toarray()
        U = lu.U.tocsc()[:, n - nl:][n - nl:, :].toarray()
        S = L @ U
        # SuperLU's perm_c may permute within the trailing block: map back to the order of
        # self.perm's tail, then to the order of self.local
        inv = np.empty(n, np.int64)
        inv[pc] = np.arange(n)
        pos = inv[np.arange(n - nl, n)] - (n - nl)
        S = S[np.ix_(pos, pos)]
        tail = self.perm[n - nl:]
        where = np.empty(n, np.int64)
        where[tail] = np.arange(nl)
        p = where[self.local]
        S = S[np.ix_(p, p)]
        return 0.5 * (S + S.T)

    def free(self) -> None:
        self.lu = None
        super().free()


class SuperLUBackend(Backend):
    name = "superlu"
    install_hint = "scipy (always installed)"

    @classmethod
    def available(cls) -> bool:
        return True

    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        return SuperLUFactorization(local, order)
