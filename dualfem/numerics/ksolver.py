"""The K-solver of the certificate (:mod:`dualfem.numerics.certify`): r -> K^-1 r and the dual operator
D = B K^-1 B' of a QP, by the exact local reduction, the matrix-free operator (a factorization of K, or
AMG-preconditioned CG where none fits: its true residuals recorded for the widened bounds described in
:mod:`dualfem.numerics.certify`) or a plain sparse factorization. Imported from there as before."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.qp import QP

#: relative residual of the certificate's AMG K-solves (where no factorization of K fits)
CERT_K_RTOL = 1e-12


class _SparseK:
    """Fallback K-solver (the chosen backend's factorization of K) when the QP has no usable local structure."""

    def __init__(self, qp: QP, factor=None):
        from dualfem.numerics.linalg import sparse_factor

        self.lu = sparse_factor(qp.K, factor)

    def solve(self, r):
        return self.lu.solve(r)


@dataclass
class OperatorHints:
    """What a solver's matrix-free operator knows that speeds the certificate's CG up without entering its
    result: the diagonal estimate of D (the active-set guess's force scale, Jacobi) and an approximate inverse
    of D (the face preconditioner). Taken only when well-formed (shapes, finite positive diagonal); a wrong
    one can slow CG or make it fail (the certificate is then unavailable), never change what it certifies."""

    diagonal: np.ndarray | None = None
    face_preconditioner: object = None

    @classmethod
    def of(cls, op, m: int) -> OperatorHints:
        import scipy.sparse as sp

        d = getattr(op, "diagonal_estimate", None)
        ok_d = isinstance(d, np.ndarray) and d.shape == (m,) and bool(np.all(np.isfinite(d) & (d > 0)))
        P = getattr(op, "face_preconditioner", None)
        ok_p = sp.issparse(P) and P.shape == (m, m) and bool(np.all(np.isfinite(P.data)))
        return cls(np.array(d) if ok_d else None, P.tocsr(copy=True) if ok_p else None)


class KSolver:
    """r -> K^-1 r and the dual operator D = B K^-1 B' of a QP, for the certificate.

    Three ways, by size: the exact local reduction (D dense; ``reduction``: a solver's LocalReduction
    of this very QP, reused as is, else a new one from the factorization of K_fixed in the QP's store,
    ``QP.store``, :func:`dualfem.numerics.linalg.store_of`); the matrix-free operator
    (:class:`dualfem.numerics.dual_operator.MatrixFreeDualOperator`: one factorization of the whole K,
    found in the same store when a matrix-free solver made it, D_AA^-1 by preconditioned CG) when the
    dense reduction does not fit (:func:`dualfem.numerics.dual_operator.choose_operator`); the matrix-free
    operator with AMG K-solves (``ksolve="amg"``, or auto when no factorization of K fits: the hierarchy
    from the QP's store, solves to :data:`CERT_K_RTOL`, their true residuals recorded for the widened
    bounds of the module docstring); a plain sparse factorization of K (D by m solves for m <= 2000) when
    the QP has no usable local structure."""

    def __init__(self, qp: QP, factor=None, reduction=None, ksolve: str = "auto", la=None):
        from dualfem.numerics.dual_operator import MatrixFreeDualOperator
        from dualfem.numerics.la import current
        from dualfem.numerics.linalg import LocalReduction

        #: the linear-algebra context (:mod:`dualfem.numerics.la`): the solver's, the current one by default
        self.la = current() if la is None else la
        factor = self.la.factor if factor is None else factor
        self.qp = qp
        self.red = None
        self.op: MatrixFreeDualOperator | None = None
        self._D: np.ndarray | None = None
        #: the largest true residual |b - K z|_2 of the AMG K-solves since :meth:`reset_k_error` (0: exact)
        self.k_residual = 0.0
        hints = reduction if isinstance(reduction, OperatorHints) else None
        if reduction is not None and type(reduction) is LocalReduction and reduction.qp is qp:
            self.red = reduction          # a solver's reduction of this very QP: same factorization, reused
            return
        kind = "dense"
        if ksolve != "auto":              # a non-direct K-solve backend asked for by name (operator kind)
            kind = ksolve
        elif qp.m:
            try:
                kind = self.la.choose_operator(qp, "auto", factor=getattr(factor, "name", factor))[0]
            except InputError as exc:     # no operator fits: the certificate is unavailable, said so
                raise RuntimeError(str(exc)) from exc
        if kind != "dense":               # matrix_free, or the matrix-free operator on a non-direct K-solve
            self.op = MatrixFreeDualOperator(qp, factor, ksolve="factor" if kind == "matrix_free" else kind,
                                             k_rtol=CERT_K_RTOL)
            if hints is not None:
                self.op.diagonal_estimate = hints.diagonal
                self.op.face_preconditioner = hints.face_preconditioner
            if not self.op.exact:
                # no factorization: D_AA^-1 by the augmented Lagrangian on K + B_A'C B_A (one AMG hierarchy, a
                # few CG solves; docs/measurements.md), and the lumped diagonal of D (no sampled solves) unless
                # the solver's operator knew a better one
                from dualfem.numerics.amg import lumped_delassus_diagonal

                self.op.face = "factor"
                if self.op.diagonal_estimate is None:
                    self.op.diagonal_estimate = lumped_delassus_diagonal(qp.K.tocsr(), qp.B.tocsr())
            return
        try:
            self.red = LocalReduction(qp, factor=factor)
        except Exception:  # noqa: BLE001 - any structure problem: a plain sparse factorization of K
            self._lu = _SparseK(qp, factor)

    @property
    def path(self) -> str:
        """The linear algebra of the certificate: ``dense`` (Schur complement onto the defect unknowns),
        ``matrix_free`` (one sparse factorization of K), ``amg`` (AMG-preconditioned CG, no factorization)
        or ``sparse`` (a plain factorization of K, no local structure)."""
        if self.op is not None:
            return "matrix_free" if self.op.exact else self.op.ksolve
        return "dense" if self.red is not None else "sparse"

    @property
    def amg(self) -> bool:
        """True when the K-solves are AMG-preconditioned CG (inexact: see the module docstring)."""
        return self.op is not None and not self.op.exact

    def _note(self) -> None:
        if self.amg:
            self.k_residual = max(self.k_residual, float(np.max(self.op.fact.last_abs, initial=0.0)))

    def k_error(self) -> tuple[float, float]:
        """(energy-norm, 2-norm) error estimates of one K-solve since :meth:`reset_k_error`: |s|/sqrt(lam),
        |s|/lam with |s| the largest true residual and lam the estimate of lambda_min(K); (0, 0) when exact."""
        if not self.amg or self.k_residual == 0.0:
            return 0.0, 0.0
        lam = self.op.fact.lambda_min()
        if lam <= 0:
            return float("inf"), float("inf")
        return self.k_residual / np.sqrt(lam), self.k_residual / lam

    def reset_k_error(self) -> None:
        self.k_residual = 0.0

    def __call__(self, r: np.ndarray) -> np.ndarray:
        if self.op is not None:
            z = self.op.k_solve(r)
            self._note()
            return z
        return self.red.k_solve(r) if self.red is not None else self._lu.solve(r)

    def apply(self, v: np.ndarray) -> np.ndarray:
        """D v through the operator (its K-solve's residual recorded)."""
        out = self.op.apply(v)
        self._note()
        return out

    def quad(self, r: np.ndarray) -> tuple[float, np.ndarray]:
        """(r'K^-1 r, B K^-1 r): one solve of K_fixed with the reduction, one of K otherwise. With AMG
        K-solves, an upper estimate (|z|_K + |s|_2 / sqrt(lambda_min))^2 (module docstring)."""
        if self.amg:
            z = self.op.k_solve(np.asarray(r, float))
            s = float(np.max(self.op.fact.last_abs, initial=0.0))
            self.k_residual = max(self.k_residual, s)
            lam = self.op.fact.lambda_min() if s > 0 else 1.0
            zKz = max(float(z @ (self.qp.K @ z)), 0.0)
            e = s / np.sqrt(lam) if lam > 0 else float("inf")
            return (np.sqrt(zKz) + e) ** 2, self.op.B @ z
        if self.op is not None:
            return self.op.k_quad(r)
        if self.red is not None:
            q, zI = self.red.k_quad(r)
            return q, self.red.BI @ zI
        z = self._lu.solve(r)
        return float(r @ z), self.qp.B @ z

    def delassus(self) -> np.ndarray | None:
        """D as a dense matrix, or None (matrix-free, or no reduction and m > 2000)."""
        if self._D is None:
            if self.op is not None:
                return None
            if self.red is not None:
                self._D = self.red.delassus()          # symmetric already
            elif self.qp.m <= 2000:
                Bd = self.qp.B.toarray()
                D = Bd @ np.column_stack([self._lu.solve(b) for b in Bd]) if self.qp.m else np.zeros((0, 0))
                self._D = 0.5 * (D + D.T)
            else:
                return None
        return self._D


def solver_for(qp: QP) -> KSolver:
    """A callable r -> K^-1 r, reusing the cached local factorization when possible."""
    return KSolver(qp)
