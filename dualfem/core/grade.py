"""Deprecated path of :mod:`dualfem.verify.grading` (the grading policy moved to the verify room).

Importing ``dualfem.core.grade`` still works and gives the same objects, with a DeprecationWarning;
it will be removed in the next release. Import ``dualfem.verify`` (or ``dualfem.verify.grading``).
No module of dualfem imports this shim (tests/_imports.py: ``SHIMS``).
"""
from __future__ import annotations

import warnings

from dualfem.verify.grading import (  # noqa: F401
    DEFAULT_GRADES,
    GRADED,
    GRADES,
    HONEST,
    SEVERITY,
    check_grades,
    combined,
    grade,
    grade_multipliers,
    within,
)

__all__ = ["DEFAULT_GRADES", "GRADED", "GRADES", "HONEST", "SEVERITY", "check_grades", "combined", "grade",
           "grade_multipliers", "within"]

warnings.warn("dualfem.core.grade is deprecated: import dualfem.verify (the grading policy moved to "
              "dualfem.verify.grading)", DeprecationWarning, stacklevel=2)
