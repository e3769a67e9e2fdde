"""Stable import path of the plugin API (docs/plugins.md): the base class of solvers on the contact
dual; the code lives in :mod:`dualfem.numerics.dual_solver` and :mod:`dualfem.numerics.dual_operator`."""
from dualfem.numerics.dual_operator import OPERATORS, DualOperator, make_operator
from dualfem.numerics.dual_solver import DualOperatorSolver

__all__ = ["DualOperator", "DualOperatorSolver", "OPERATORS", "make_operator"]
