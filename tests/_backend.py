"""What a test may expect of the installed factorization backends (PARDISO is the optional `pardiso` extra:
MKL wheels for x86-64 only; without it dualfem factorizes with CHOLMOD or SuperLU).

A test of a property that holds with every backend must not use these; a test of what PARDISO itself
does (one analysis for every numeric factor, its own solve halves, its rounding) is marked
:data:`needs_pardiso` and skipped with the reason elsewhere.
"""
from __future__ import annotations

import pytest

from dualfem.numerics.factor import available, get_default

HAS_PARDISO = "pardiso" in available()

#: the backend a solver uses when none is asked for (DUALFEM_FACTOR, else the fastest installed)
DEFAULT = get_default()

needs_pardiso = pytest.mark.skipif(not HAS_PARDISO, reason="needs PARDISO: pip install 'dualfem[pardiso]' (x86-64)")


def newton_analyses(info: dict) -> int:
    """The symbolic analyses a solver's Newton matrices (:mod:`dualfem.numerics.newton_matrix`) should report:
    PARDISO analyzes once for all its numeric factors; another backend once per slot used, i.e. per distinct
    coefficient vector factorized until the ``keep`` slots are full."""
    if info["newton_backend"] == "pardiso":
        return 1
    return min(info["newton_factorizations"], info["newton_keep"])
