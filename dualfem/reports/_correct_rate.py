"""Correct rate of ``solved`` claims (qpbenchmark's metric), shared by the bench and stability reports.

Definitions (printed in the reports by :data:`DEFINITION`):

* a **solved claim** is a run whose ``claimed_status`` -- the plugin's own word, before dualfem's
  certification -- is ``solved`` (rows written before ``claimed_status`` existed fall back to
  ``status``);
* a claim is **certified correct** when :func:`dualfem.verify.grading.grade` gives ``correct``: the
  runner's certification stands (status still ``solved``: the evaluator's KKT residuals, and for
  exact solvers the a-posteriori energy-norm error bound, within the tolerance), the evaluator's
  largest KKT residual is <= tol and the relative energy-norm error against the certified
  reference is <= tol + the reference's own certified bound. In a bench, tol is the tier's
  tolerance; in a stress run, the tolerance the solver instance declares;
* **correct rate** = certified correct / checkable solved claims, a claim being checkable unless
  there is no certified reference to measure its error (grade ``unverified``: counted apart);
  undefined, shown as ``-``, without checkable claims;
* **success rate** = certified correct claims within the time limit / runs;
* qpbenchmark computes its "correct rate" over every run, as the share whose ``found`` flag
  agrees with the tolerance check, i.e. ``1 - wrong claims / runs`` (wrong = checkable claims not
  certified correct); it is reported beside ours as
  **claims agree** (an honest failure counts as agreeing there).

A bench run that claimed ``solved`` and was certified, but whose median time exceeded the time
limit (status ``time_limit``, message "... (was solved)"), is graded on its answer: over time is
a failure of speed, not a wrong claim: it counts as certified correct, not as a success.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from dualfem.verify.judge import outcome

#: the correct rate in words (both reports print it)
DEFINITION = (
    "**Correct rate** (qpbenchmark's metric of how far a `solved` return code can be trusted) = certified "
    "correct / checkable solved claims, where a *solved claim* is a run whose `claimed_status` (the solver's own word, "
    "before dualfem certifies it) is `solved`, and *certified correct* means `dualfem.verify.grading` grades it "
    "`correct`: dualfem's certification kept the claim (status still `solved`), the evaluator's largest KKT "
    "residual is <= tol, and the relative energy-norm error against the certified reference is <= tol + the "
    "reference's certified bound (where the tier grades `x,mu`, the multipliers' error and certificate too); "
    "a claim is checkable unless no certified reference exists to measure its error "
    "(*unverified*, counted apart). qpbenchmark's code averages `found == (found and within tolerances)` over "
    "every run; that number, 1 - wrong claims / runs, is the column *claims agree* (an honest failure agrees).")
#: the success rate in words (bench report)
SUCCESS = ("**Success rate** = certified correct claims within the time limit / runs (a run over the time limit "
           "whose answer is correct counts for the correct rate, not for success).")


def _f(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _get(r: Any, key: str) -> Any:
    try:
        return r.get(key)
    except (AttributeError, KeyError):
        return None


def claimed(r: Any) -> str:
    """The solver's own status (``claimed_status``; ``status`` for rows that predate it)."""
    return str(_get(r, "claimed_status") or _get(r, "status") or "")


def _certified_status(r: Any) -> str:
    st = str(_get(r, "status") or "")
    if st == "time_limit" and "(was solved)" in str(_get(r, "message") or ""):
        return "solved"
    return st


def certified_correct(r: Any, tol: float | None = None) -> bool:
    """Whether run ``r`` is graded ``correct``: at ``tol`` (regraded) or, with ``tol=None``, by its own grade."""
    if tol is None:
        return _get(r, "grade") == "correct"
    return _grade_at(r, float(tol)) == "correct"


def _grade_at(r: Any, tol: float) -> str:
    """The run's grade regraded at ``tol`` by the one judge's grading of facts
    (:func:`dualfem.verify.judge.outcome`): x's, or the worse of x's and the multipliers' where the row's tier
    grades ``"x,mu"``. The status is the certified one as recorded (no claim is passed: a run the
    certification demoted at its own tolerance is not re-certified at ``tol``)."""
    slack = _f(_get(r, "ref_bound"))
    slack = slack if math.isfinite(slack) else 0.0
    return outcome(_certified_status(r), tol, _f(_get(r, "kkt_error")), _f(_get(r, "err_x_energy")),
                   _f(_get(r, "err_multipliers")), slack, cert_mu=_f(_get(r, "cert_mu")),
                   grades=_get(r, "grades"))[0]


def claim_stats(rows: Iterable[Any], tol: float | None = None) -> dict[str, Any]:
    """Counts and rates of ``rows`` (skipped runs excluded); ``tol`` as in :func:`certified_correct`.

    Keys: runs, claims, certified (certified correct claims), over_time (of those, over the bench's
    time limit), demoted (claims the certification
    turned into a failure), flagged, silent_wrong, unverified (the grades of the other claims at
    ``tol``), correct_rate, success_rate, agree (qpbenchmark's formula); rates are fractions in
    [0, 1], NaN when their denominator is 0.
    """
    out: dict[str, Any] = {"runs": 0, "claims": 0, "certified": 0, "over_time": 0, "demoted": 0, "flagged": 0,
                           "silent_wrong": 0, "unverified": 0}
    for r in rows:
        if str(_get(r, "status")) == "skipped":
            continue
        out["runs"] += 1
        if claimed(r) != "solved":
            continue
        out["claims"] += 1
        if certified_correct(r, tol):
            out["certified"] += 1
            out["over_time"] += str(_get(r, "status")) == "time_limit"
            continue
        g = _get(r, "grade") if tol is None else _grade_at(r, float(tol))
        key = {"flagged": "flagged", "silent_wrong": "silent_wrong", "unverified": "unverified"}.get(str(g), "demoted")
        out[key] += 1
    n, c = out["runs"], out["claims"]
    checked = c - out["unverified"]
    out["correct_rate"] = out["certified"] / checked if checked else float("nan")
    out["success_rate"] = (out["certified"] - out["over_time"]) / n if n else float("nan")
    out["agree"] = (n - (checked - out["certified"])) / n if n else float("nan")
    return out


def pct(v: float) -> str:
    """A rate as a whole percentage, ``-`` when undefined."""
    return "-" if not math.isfinite(v) else f"{100 * v:.0f} %"
