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

**Displacements and multipliers are graded apart.** ``grade_x`` is the grade above for the
displacements x (relative energy-norm error ``err_x_energy``); ``grade_mu`` is the same scale for the
contact forces mu (``err_multipliers`` = ``|mu - mu_ref|_inf / max(|mu_ref|_inf, |F|_inf)``), where a
run whose certified multiplier error (the runner's certificate, beyond the rounding floor of mu*)
exceeds ``tol`` is ``flagged``: the certificate shows it. What a tier grades (``grades``, one of
:data:`GRADED`) decides which of them is the run's ``grade``:

* ``"x"`` (the default, :data:`DEFAULT_GRADES`): the grade is ``grade_x``; the multipliers are still
  measured, certified and reported (``err_multipliers``, ``cert_mu``, ``grade_mu``) but do not make the
  run fail. Why the default: a tier's ``tol`` is an energy-norm tolerance on x (the norm of the paper's
  error estimates, the one the runner's certificate bounds, and what ``--tol`` means), while the
  multiplier error is a maximum norm of a dual quantity whose ratio to the energy-norm error grows with
  the discrete inf-sup constant (with N and 1/delta): the same number asks for a different accuracy of
  mu than of x, and a dual method whose x meets the tier (the paper's uzawa at tier low: x within 1e-3,
  mu 5.8e-3 off) would be failed for a quantity the tier does not name.
* ``"x,mu"``: both are graded at ``tol``; the run is ``correct`` only if both are (the worse grade of the
  two, in the order of :data:`SEVERITY`), and the runner demotes a ``solved`` whose certified
  multiplier error exceeds ``tol`` (:func:`dualfem.verify.judge.judge`, called by
  :func:`dualfem.experiments.runner.certify_status`).
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


#: what a tier may grade: the displacements only, or the displacements and the multipliers
GRADED = ("x", "x,mu")
#: the default (see the module docstring for why)
DEFAULT_GRADES = "x"
#: from best to worst: the combined grade of ``"x,mu"`` is the later of the two
SEVERITY = ("skipped", "correct", "unverified", "failed", "timeout", "crashed", "flagged", "silent_wrong")


def check_grades(grades: str | None, where: str = "grades") -> str:
    """``grades`` checked (None: the default); ValueError naming the allowed values otherwise."""
    g = DEFAULT_GRADES if grades is None else str(grades).replace(" ", "")
    if g not in GRADED:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, GRADED))}, got {grades!r}")
    return g


def grade_multipliers(status: str, err_mu: float | None, kkt: float | None, tol: float,
                      slack: float | None = 0.0, cert_mu: float | None = None) -> str:
    """The grade of a run's multipliers (see the module docstring): as :func:`grade` with the multiplier
    error ``err_mu`` against the reference, and ``flagged`` when the certified multiplier error
    ``cert_mu`` (beyond its rounding floor) exceeds ``tol``."""
    g = grade(status, err_mu, kkt, tol, slack)
    if g in ("correct", "unverified", "silent_wrong") and _finite(cert_mu) and cert_mu > tol:  # type: ignore[operator]
        return "flagged"
    return g


def combined(grade_x: str, grade_mu: str, grades: str) -> str:
    """The run's grade: ``grade_x`` when the tier grades ``"x"``, the worse of the two for ``"x,mu"``."""
    if grades != "x,mu":
        return grade_x
    rank = {g: i for i, g in enumerate(SEVERITY)}
    return max(grade_x, grade_mu, key=lambda g: rank.get(g, len(SEVERITY)))
