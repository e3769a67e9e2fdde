"""One grading policy for every experiment (compare, bench, stress) and every report.

Every experiment produces :class:`dualfem.experiments.row.Row` records and grades them with
:func:`grade` (through ``Row.regrade``); ``status`` is the certified solver status (the runner's,
:mod:`dualfem.experiments.runner`), the solver's own claim is ``claimed_status``.

A run is judged from four facts: the status it claims, its error against a trusted reference
(relative energy norm, ``|x - x_ref|_K / |x_ref|_K``), the evaluator's largest KKT residual, and
the tolerance it declared. The answer is within tolerance when

    error <= tol + slack,     slack = the reference's own certified error bound (0 if unknown).

==============  ==========================================================================
``correct``     claims ``solved``, the error is within tolerance and so is the KKT error
``failed``      an honest "not solved" status (max_iter, time_limit, stagnation, inaccurate, ...)
``flagged``     claims ``solved`` but the evaluator's residuals exceed ``tol`` or are not finite
                (the answer, or its multipliers, is wrong and a user who checks the residuals
                sees it; decided before, and without, any reference)
``silent_wrong`` claims ``solved``, is wrong, and the residuals look fine: the case no user can
                detect (must never happen)
``unverified``  claims ``solved``, residuals within ``tol``, but there is no trusted reference to
                measure the error
``skipped``     not applicable / not installed
``timeout``     killed by the harness's wall-clock guard
``crashed``     the worker process died (segmentation fault, out of memory)
==============  ==========================================================================
"""
from __future__ import annotations

import math

GRADES = ("correct", "failed", "flagged", "silent_wrong", "unverified", "skipped", "timeout", "crashed")
#: grades that are honest failures (the user is told the answer is not to be trusted)
HONEST = ("failed", "flagged", "timeout", "crashed")


def _finite(v: float | None) -> bool:
    return v is not None and isinstance(v, (int, float)) and math.isfinite(v)


def within(err: float | None, tol: float, slack: float | None = 0.0) -> bool:
    """Whether a relative error ``err`` is within ``tol`` plus the reference's ``slack``."""
    return _finite(err) and err <= tol + (slack if _finite(slack) else 0.0)  # type: ignore[operator]


def grade(status: str, err: float | None, kkt: float | None, tol: float, slack: float | None = 0.0) -> str:
    """The grade of one run (see the module docstring); ``status`` is the claimed status string."""
    status = str(status)
    if status in ("skipped", "timeout", "crashed"):
        return status
    if status != "solved":
        return "failed"
    if not _finite(kkt) or kkt > tol:  # type: ignore[operator]
        return "flagged"        # the evaluator sees it, with or without a reference
    if not _finite(err):
        return "unverified"
    return "correct" if within(err, tol, slack) else "silent_wrong"
