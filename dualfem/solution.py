"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.solution`."""
from dualfem.core.solution import Solution, Status

__all__ = [
    "Solution", "Status",
]
