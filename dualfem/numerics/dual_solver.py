"""Base class of the solver plugins that work on the contact dual through a :class:`DualOperator`.

Stable import path for plugins: :mod:`dualfem.dual_solver` (``from dualfem.dual_solver import
DualOperatorSolver``). :class:`DualOperatorSolver` brings the parameters ``operator`` (``auto`` |
``dense`` | ``matrix_free`` | ``amg``, :data:`dualfem.numerics.dual_operator.OPERATORS`; ``amg``:
matrix-free with K-solves by AMG-preconditioned CG to 1e-3 x the solver's declared tolerance,
:mod:`dualfem.numerics.amg`) and ``factor`` (the factorization backend) to a
:class:`~dualfem.core.solver.Solver`; both select within the run's linear-algebra context
(:mod:`dualfem.numerics.la`: ``auto`` takes the context's choice). ``skip`` answers with the operator
choice's refusal (a QP for which no operator fits the memory budget), ``setup`` builds ``self.op`` on the
same choice (:meth:`DualOperatorSolver.operator_choice`, :func:`make_operator`) and
publishes the dense path's :class:`~dualfem.numerics.linalg.LocalReduction` as ``self.reduction``
(the runner's certification reuses it; the matrix-free path's factorization of K is found by the
certificate in the QP's store). A subclass declares only its own ``defaults`` and ``ranges``: the two
parameters (default ``"auto"`` each) and their ranges are merged in when the subclass is created,
and a subclass that declares either keeps its own default and range. ``family`` defaults to ``"dual"``.
Plugins import it from :mod:`dualfem.dual_solver`, never from each other.
"""
from __future__ import annotations

import weakref

from dualfem.core.errors import InputError, MissingDependency
from dualfem.core.solver import Solver
from dualfem.numerics.dual_operator import OPERATORS, DualOperator, check_operator, make_operator
from dualfem.numerics.factor import from_param
from dualfem.numerics.la import current

__all__ = ["DualOperatorSolver", "OPERATORS"]


class DualOperatorSolver(Solver):
    """A solver on the dual operator D = B K^-1 B' (dense or matrix-free, chosen by ``operator``)."""

    family = "dual"
    #: the parameters every dual-operator solver has (merged into each subclass's ``defaults``)
    defaults = {"operator": "auto", "factor": "auto"}
    #: their allowed values (``factor``: a backend name, checked by ``validate``)
    ranges = {"operator": OPERATORS, "factor": None}
    op: DualOperator

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        base = DualOperatorSolver
        cls.defaults = {**cls.defaults, **{k: v for k, v in base.defaults.items() if k not in cls.defaults}}
        cls.ranges = {**cls.ranges, **{k: v for k, v in base.ranges.items() if k not in cls.ranges}}

    def validate(self) -> None:
        from_param(self)
        self.params["operator"] = check_operator(self.params["operator"], self.name)

    def operator_choice(self, qp) -> tuple[str, str]:
        """(kind, why) of this solver's dual operator for ``qp``, chosen once per QP in the current
        linear-algebra context (:mod:`dualfem.numerics.la`; ``operator`` and ``factor`` select within it):
        ``skip`` chooses, ``setup`` reuses the choice. InputError / MissingDependency when none fits."""
        held = getattr(self, "_operator_choice", None)
        if held is not None and held[0]() is qp:
            return held[1]
        chosen = current().choose_operator(qp, self.params["operator"], factor=from_param(self))
        self._operator_choice = (weakref.ref(qp), chosen)
        return chosen

    def skip(self, qp) -> str | None:
        try:
            self.operator_choice(qp)
        except (InputError, MissingDependency) as exc:    # no operator fits; operator=amg without pyamg
            return str(exc)
        return None

    def setup(self, qp) -> None:
        self.qp = qp
        self.op = make_operator(qp, self.params["operator"], factor=from_param(self), tol=self.tolerance,
                                chosen=self.operator_choice(qp))
        self.reduction = self.op.reduction
