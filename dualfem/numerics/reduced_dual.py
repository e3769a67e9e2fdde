"""The reduced dual of the contact QP, shared by the solver plugins that work on it (pdas, penalty).

:class:`ReducedDualSolver` is a :class:`~dualfem.core.solver.Solver` base class: it skips QPs whose
dense reduced matrix on the defect unknowns would not fit (:func:`dualfem.numerics.linalg.too_many_local`)
and, in ``setup``, builds the :class:`~dualfem.numerics.linalg.LocalReduction` (``self.red``,
also published as ``self.reduction`` for the runner's certification), the Cholesky factor of its
Schur complement (``self.cho``) and the data of the dual LCP, ``D = BI S^-1 BI'`` and
``b0 = BI S^-1 g`` (``self.D``, ``self.b0``). Plugins import it from here, never from each other.
"""
from __future__ import annotations

from dualfem.core.solver import Solver
from dualfem.numerics.factor import from_param
from dualfem.numerics.linalg import MAX_LOCAL, too_many_local


class ReducedDualSolver(Solver):
    """Base of solvers working on the reduced dual (pdas, penalty): skip QPs whose dense
    reduced matrix would not fit; setup builds the LocalReduction and the LCP data (D, b0)."""

    def skip(self, qp) -> str | None:
        return too_many_local(qp, MAX_LOCAL)

    def setup(self, qp) -> None:
        from dualfem.numerics.linalg import LocalReduction

        self.qp = qp
        self.red = self.reduction = LocalReduction(qp, factor=from_param(self))
        self.cho = self.red.S_cho
        self.D, self.b0 = self.red.dual()
