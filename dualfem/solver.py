"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.solver`."""
from dualfem._facade import moved
from dualfem.core.solver import (
    COMMON_RANGES,
    SOLVER_FAMILIES,
    RenamedParameterWarning,
    Solver,
    check_declared,
    check_value,
    declared_tolerance,
    describe_range,
    interval,
    positive,
    reference_solvers,
)

__all__ = [
    "COMMON_RANGES", "RenamedParameterWarning", "SOLVER_FAMILIES", "Solver", "check_declared", "check_value",
    "declared_tolerance", "describe_range", "interval", "positive", "reference_solvers",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors", "missing_module": "dualfem.errors", "QP": "dualfem.qp", "Solution":
    "dualfem.solution",
})
