"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.experiments.runner`."""
from dualfem._facade import moved
from dualfem.experiments.runner import (
    COUNTERS,
    RUNNER_INFO,
    attach_residuals,
    certify_status,
    fingerprint,
    guarded_view,
    jsonable_params,
    make_solver,
    missing_reason,
    run,
    summary,
)

__all__ = [
    "COUNTERS", "RUNNER_INFO", "attach_residuals", "certify_status", "fingerprint", "guarded_view",
    "jsonable_params", "make_solver", "missing_reason", "run", "summary",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors", "describe_exception": "dualfem.errors", "Maps": "dualfem.qp", "QP":
    "dualfem.qp", "Solution": "dualfem.solution", "Status": "dualfem.solution", "Solver": "dualfem.solver",
    "check_declared": "dualfem.solver", "builtin_names": "dualfem.registry", "get_solver": "dualfem.registry",
    "plugin_output": "dualfem.core.quiet",
})
