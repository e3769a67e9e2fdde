"""The AMG K-solve as a registered backend (``"amg"``): K^-1 by CG preconditioned with a pyamg
smoothed-aggregation hierarchy, where no direct factorization of K fits (3D).

Not a direct factorization (``direct = False``): its solves are accurate to a relative residual ``rtol``
only, so ``factor=`` never names it and :func:`dualfem.numerics.factor.choose` never returns it; the
linear-algebra context (:mod:`dualfem.numerics.la`) selects it as the K-solve of the matrix-free dual
operator (``operator="amg"``, or auto where no factorization fits) and of the certificate, which records the
true residuals of its solves (:mod:`dualfem.numerics.amg`). Its memory model is
:func:`dualfem.numerics.memory.amg_bytes` (per unknown, both dimensions).

``make()`` gives a :class:`~dualfem.numerics.factor.base.Factorization` whose ``factorize`` builds the
hierarchy and whose ``solve`` takes one right-hand side (n,) or a block (n, k) (column by column); the
Schur complement, when asked for, is the generic one by |I| solves (inexact, as every solve).
"""
from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import scipy.sparse as sp

from .base import Backend, Factorization, OrderHint


class AmgFactorization(Factorization):
    """K^-1 by AMG-preconditioned CG to ``rtol`` (near-nullspace ``modes`` (n, k) or None)."""

    backend = "amg"

    def __init__(self, local: np.ndarray | None = None, order: OrderHint = None,
                 modes: np.ndarray | None = None, rtol: float | None = None):
        super().__init__(local, order)
        self.modes = modes
        self.rtol = rtol
        self.ksolve: Any = None          # the AmgKSolve, made by factorize

    def _analyze(self, A: sp.csr_matrix) -> None:
        """Nothing: the hierarchy depends on the values."""

    def _factorize(self, A: sp.csr_matrix) -> None:
        from dualfem.numerics.amg import RTOL, AmgKSolve

        self.ksolve = AmgKSolve(A, self.modes, RTOL if self.rtol is None else self.rtol)
        self.info.update(self.ksolve.info)

    def _solve(self, b: np.ndarray) -> np.ndarray:
        return self.ksolve.solve(b)

    def free(self) -> None:
        self.ksolve = None
        super().free()


class AmgBackend(Backend):
    name = "amg"
    install_hint = "pip install 'dualfem[amg]'  (pyamg)"
    direct = False

    def __init__(self, modes: np.ndarray | None = None, rtol: float | None = None):
        self.modes = modes
        self.rtol = rtol

    @classmethod
    def available(cls) -> bool:
        return importlib.util.find_spec("pyamg") is not None

    @classmethod
    def require(cls) -> None:
        """MissingDependency naming the ``amg`` extra unless pyamg imports (:func:`dualfem.numerics.amg.
        require_pyamg`)."""
        from dualfem.numerics.amg import require_pyamg

        require_pyamg()

    @classmethod
    def peak_bytes(cls, n_unknowns: int, dim: int = 2, analysis: dict | None = None) -> int:
        """The hierarchy and CG's vectors: :func:`dualfem.numerics.memory.amg_bytes` (``dim``, ``analysis``
        unused)."""
        from dualfem.numerics.memory import amg_bytes

        return amg_bytes(n_unknowns)

    @classmethod
    def default_rtol(cls) -> float:
        from dualfem.numerics.amg import RTOL

        return RTOL

    @classmethod
    def inner_rtol(cls, outer_tol: float) -> float:
        from dualfem.numerics.amg import inner_rtol

        return inner_rtol(outer_tol)

    @classmethod
    def for_qp(cls, qp, store=None):
        """The QP's :class:`~dualfem.numerics.amg.AmgKSolve` (rigid-body modes; once per store:
        :func:`dualfem.numerics.amg.amg_for`)."""
        from dualfem.numerics.amg import amg_for

        return amg_for(qp, store)

    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        return AmgFactorization(local, order, self.modes, self.rtol)
