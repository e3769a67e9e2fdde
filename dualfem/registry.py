"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.registry`."""
from dualfem._facade import moved
from dualfem.core.registry import (
    DISTRIBUTION,
    builtin_names,
    entry_point_errors,
    get_problem,
    get_solver,
    problem_dims,
    problem_for_dim,
    problems,
    register_problem,
    register_solver,
    solvers,
)

__all__ = [
    "DISTRIBUTION", "builtin_names", "entry_point_errors", "get_problem", "get_solver", "problem_dims",
    "problem_for_dim", "problems",
    "register_problem", "register_solver", "solvers",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors",
})
