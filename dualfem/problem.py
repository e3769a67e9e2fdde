"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.problem`."""
from dualfem._facade import moved
from dualfem.core.problem import Problem, Shared
from dualfem.core.units import KINDS as UNIT_KINDS
from dualfem.core.units import UnitMap

__all__ = [
    "Problem", "Shared", "UNIT_KINDS", "UnitMap",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors", "MissingDependency": "dualfem.errors", "missing_module": "dualfem.errors",
    "QP": "dualfem.qp",
})
