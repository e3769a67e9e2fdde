"""The one judge: a plugin's claim, the QP and a tolerance in, a typed :class:`Verdict` out.

A solver *claims* an answer: a :class:`~dualfem.core.solution.Solution` whose ``status`` is its own word.
:func:`judge` decides, from the QP and (x, mu) alone, what that claim is worth, in two halves:

1. :func:`certify` (no reference needed; the runner calls it on every run, ``dualfem solve`` included):
   a ``solved`` claim stands only if the evaluator's KKT residuals are within ``tol``, the certified
   energy-norm error bound of x is too where it applies (an inexact solver's answer needs one), and so
   is the certified multiplier error beyond the rounding floor of mu* (unless the tier grades x only);
   otherwise the certified status is ``inaccurate`` and :attr:`Verdict.why` says why.
2. :func:`against` (compare, bench, stress): the errors against a trusted reference (relative energy
   norm of x, multipliers relative to ``max(|mu_ref|_inf, |F|_inf)``) and the outcome of
   :func:`outcome`, the grading policy of :mod:`dualfem.verify.grading` on those facts.

:func:`outcome` is also what a stored row is regraded with (:meth:`dualfem.experiments.row.Row.regrade`),
so a record judged today and a record read back from results.csv get the same outcome.

Outcomes (:data:`OUTCOMES`, documented once in docs/conventions.md, "Outcomes"): ``correct``,
``failed``, ``flagged``, ``silent_wrong``, ``unverified``, ``skipped``, ``timeout``, ``crashed``. A
verdict without a reference can be at best ``unverified`` (the certificate bounds the error, but no
second answer measured it); ``inaccurate`` is a *status* (a demoted claim), whose outcome is ``failed``.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from dualfem.core.evaluator import RESIDUALS
from dualfem.core.evaluator import compare as measure
from dualfem.core.laws import Friction
from dualfem.core.qp import QP
from dualfem.core.solution import Solution, Status
from dualfem.numerics.certify import KSolver, certified_error, multiplier_floor
from dualfem.verify.grading import GRADES, combined, grade, grade_multipliers

#: the outcome of a judged run: the grades of :mod:`dualfem.verify.grading`
OUTCOMES = GRADES


@dataclass(frozen=True)
class Verdict:
    """What the judge decided about one claim (see the module docstring).

    ``status`` is the certified status (what ``Solution.status`` holds after the runner: the claim, or
    ``inaccurate`` when it was demoted), ``claim`` the plugin's own status, ``tol`` the tolerance judged at
    (relative: energy norm for x, the evaluator's scale-free residuals). ``cert_x`` is the certified
    relative energy-norm error bound of x and ``cert_mu`` the certified multiplier error beyond the
    rounding floor of mu* (None where not computed), ``certificate`` the certificate's dict as the
    runner stores it in ``Solution.info["certificate"]``. ``why``: why the claim was demoted ("" when it
    stands); ``note``: a remark for the message that does not demote (a multiplier error a tier grading
    x only does not count). ``err_x``/``err_mu``/``diff``: the errors against ``ref_solver``'s answer
    (whose certified bound ``ref_bound`` is the slack a grade grants), None without a reference.
    """

    outcome: str
    status: str
    claim: str
    tol: float
    residuals: dict | None = None
    kkt: float | None = None
    cert_x: float | None = None
    cert_mu: float | None = None
    certificate: dict | None = None
    why: str = ""
    note: str = ""
    err_x: float | None = None
    err_mu: float | None = None
    diff: dict | None = None
    ref_solver: str | None = None
    ref_bound: float | None = None
    grade_x: str | None = None
    grade_mu: str | None = None

    @property
    def demoted(self) -> bool:
        """True when the judge did not let a ``solved`` claim stand."""
        return self.claim == str(Status.SOLVED) and self.status != self.claim


def _fin(v: Any) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def _kkt(res: dict | None) -> float | None:
    if not res or not res.get("finite", True):
        return None
    return max(res[k] for k in RESIDUALS)


def cert_facts(cert: dict | None) -> tuple[float | None, float | None]:
    """(cert_x, cert_mu) of a certificate dict: its energy-norm bound, and its multiplier error beyond
    the rounding floor of mu* (clipped at 0); None where absent or not finite."""
    cert = cert if isinstance(cert, dict) else {}
    val, mu, floor = cert.get("value"), cert.get("multipliers"), cert.get("multipliers_floor", 0.0)
    cert_x = float(val) if _fin(val) else None  # type: ignore[arg-type]
    cert_mu = max(float(mu) - (float(floor) if _fin(floor) else 0.0), 0.0) if _fin(mu) else None  # type: ignore[arg-type]
    return cert_x, cert_mu


def _certificate(qp: QP, sol: Solution, tol: float, reduction: Any) -> dict:
    """The certificate of (x, mu), with the K-solve path and, when the multiplier error exceeds ``tol``,
    the rounding floor of mu* (one more solve); an error dict when it cannot be computed."""
    try:
        ks = KSolver(qp, reduction=reduction)
        cert = certified_error(qp, sol.x, sol.multipliers, ks)  # type: ignore[arg-type]
        cert["path"] = ks.path
        notes = sorted({b.law.certificate_note() for b in qp.blocks} - {""})
        if notes:
            cert["notes"] = "; ".join([n for n in (cert.get("notes", ""),) if n] + notes)
        cm = cert.get("multipliers", float("nan"))
        if np.isfinite(cm) and cm > tol:      # only then: the rounding floor of mu* costs one more solve
            cert["multipliers_floor"] = multiplier_floor(qp, sol.x, sol.multipliers, ks)  # type: ignore[arg-type]
        return cert
    except (np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
        return {"bound": float("nan"), "active_set": float("nan"), "value": float("nan"),
                "error": f"{type(exc).__name__}: {exc}"}


#: why a frictional answer without an error bound is not certified (also appended to the certificate's notes)
NO_FRICTION_BOUND = ("no error bound applies to this answer of a QP with friction (no bound of the duality gap, "
                     "the face step or a feasible correction holds for it): residuals alone do not certify a "
                     "frictional answer")


def _why(cert: dict, tol: float, exact: bool, multipliers: bool, friction: bool = False) -> tuple[str, str]:
    """(why the claim is demoted or "", a non-demoting note or "") from a certificate. ``friction``: the QP has
    friction blocks, whose answers need a finite bound whatever solver gave them (an exact solver's Signorini
    answer without one stands on its residuals)."""
    value = cert["value"]
    cmu = cert.get("multipliers", float("nan"))
    cfloor = cert.get("multipliers_floor", 0.0)
    cmu = cmu - (cfloor if np.isfinite(cfloor) else 0.0)      # beyond the rounding of mu* itself
    if np.isfinite(value) and value > tol:
        return (f"certified energy-norm error bound {value:.1e} exceeds the declared tolerance {tol:g} "
                f"(residuals are within it)"), ""
    if not exact and not np.isfinite(value):
        return ("no error bound applies to this answer of an inexact solver (residuals alone do not bound "
                "the error of x)"), ""
    if friction and not np.isfinite(value):
        return NO_FRICTION_BOUND, ""
    if np.isfinite(cmu) and cmu > tol and not multipliers:
        return "", f"certified multiplier error {cmu:.1e} exceeds {tol:g} (not graded: x only)"
    if np.isfinite(cmu) and cmu > tol:
        return (f"certified multiplier error {cmu:.1e} (|mu - mu*|_inf against the exact multipliers of the "
                f"verified active set, relative to max(|mu*|, |F|), beyond their rounding floor "
                f"{cfloor:.1e}) exceeds the declared tolerance {tol:g}"), ""
    return "", ""


def certify(qp: QP, sol: Solution, tol: float, exact: bool, reduction: Any = None,
            multipliers: bool = True) -> Verdict:
    """The first half of :func:`judge`: the claim of ``sol`` checked against the QP at ``tol``.

    ``sol.residuals`` are the evaluator's (the runner attaches them first); ``exact``: the solver declares
    itself exact (an inexact one needs a finite error bound); ``multipliers=False``: a certified multiplier
    error above ``tol`` is a :attr:`Verdict.note`, not a demotion (a tier that grades x only);
    ``reduction``: the solver's LocalReduction of ``qp`` (``Solver.reduction``), reused if valid, or the
    hints of its matrix-free operator. Nothing in ``sol`` is changed.
    """
    status = str(sol.status)
    res = sol.residuals
    v = Verdict(outcome="", status=status, claim=sol.claim or status, tol=tol, residuals=res, kkt=_kkt(res))
    if sol.status != Status.SOLVED or res is None or not res.get("finite", False) or sol.x is None \
            or sol.multipliers is None or not all(np.isfinite(res[k]) for k in RESIDUALS):
        return _graded(_not_finite(v, res))
    worst = max(RESIDUALS, key=lambda k: res[k])
    if res[worst] > tol:
        why = f"evaluator residual {worst} = {res[worst]:.1e} exceeds the declared tolerance {tol:g}"
        return _graded(replace(v, status=str(Status.INACCURATE), why=why))
    cert = _certificate(qp, sol, tol, reduction)
    friction = any(isinstance(b.law, Friction) for b in qp.blocks)
    why, note = _why(cert, tol, exact, multipliers, friction)
    if why == NO_FRICTION_BOUND:
        cert["notes"] = "; ".join(n for n in (cert.get("notes", ""), why) if n)
    cert_x, cert_mu = cert_facts(cert)
    v = replace(v, status=str(Status.INACCURATE) if why else status, certificate=cert, cert_x=cert_x,
                cert_mu=cert_mu, why=why, note=note)
    return _graded(_not_finite(v, res))


def _not_finite(v: Verdict, res: dict | None) -> Verdict:
    """A ``solved`` that stands but whose evaluator residuals or energy are not finite (e.g. x = 1e308:
    K x overflows, and NaN > tol is False) is never ``solved``: ``numerical_error``."""
    bad = [k for k in (*RESIDUALS, "energy") if res is not None and not np.isfinite(res.get(k, np.nan))]
    if v.status != str(Status.SOLVED) or not bad:
        return v
    return replace(v, status=str(Status.NUMERICAL_ERROR),
                   why=f"the evaluator's {', '.join(bad)} is not finite (NaN/inf)")


def outcome(status: str, tol: float | None, kkt: float | None, err_x: float | None = None,
            err_mu: float | None = None, ref_bound: float | None = None, cert_x: float | None = None,
            cert_mu: float | None = None, claim: str | None = None,
            grades: str | None = None) -> tuple[str, str, str]:
    """(outcome, grade_x, grade_mu) of a run's facts: its certified ``status`` (and the plugin's ``claim``),
    the tolerance, the evaluator's KKT error, the errors against a reference and the reference's
    certified bound (the slack), its own certificates, and what the tier grades (``grades``: None as
    compare and stress, ``"x"`` or ``"x,mu"``; :mod:`dualfem.verify.grading`).

    Under ``"x,mu"`` a run demoted for its multipliers alone (claimed ``solved``, KKT error and certified
    x error within ``tol``, certified multiplier error above it) keeps a ``grade_x`` of its x.
    """
    t = tol if tol is not None and _fin(tol) else float("nan")
    status = status or "error"
    alone = bool(status == "inaccurate" and claim == "solved" and _fin(kkt) and kkt <= t  # type: ignore[operator]
                 and _fin(cert_mu) and cert_mu > t and (not _fin(cert_x) or cert_x <= t))  # type: ignore[operator]
    status_x = "solved" if alone else status
    gx = grade(status_x, err_x, kkt, t, ref_bound)
    gmu = grade_multipliers(status_x, err_mu, kkt, t, ref_bound, cert_mu)
    g = grade(status, err_x, kkt, t, ref_bound) if not grades else combined(gx, gmu, grades)
    return g, gx, gmu


def _graded(v: Verdict, grades: str | None = None) -> Verdict:
    g, gx, gmu = outcome(v.status, v.tol, v.kkt, v.err_x, v.err_mu, v.ref_bound, v.cert_x, v.cert_mu, v.claim,
                         grades)
    return replace(v, outcome=g, grade_x=gx, grade_mu=gmu)


def outcome_without_answer(status: str) -> str:
    """The outcome of a run that returned no answer to judge (the harness's row of a lost task): killed at
    its wall-clock limit (``time_limit``) is ``timeout``, a dead worker ``crashed``, ``skipped`` stays, any
    other status (an error before an answer) is ``failed``."""
    return {"time_limit": "timeout", "crashed": "crashed", "skipped": "skipped"}.get(str(status), "failed")


@dataclass(frozen=True)
class Answer:
    """A trusted reference answer to judge against: its solver, (x, mu), and its certified relative
    energy-norm error bound (the slack a grade grants; None when unknown)."""

    solver: str
    x: np.ndarray
    multipliers: np.ndarray
    bound: float | None = None


def against(v: Verdict, qp: QP, sol: Solution, ref: Answer | None, *, grades: str | None = None,
            measurable: bool | None = None) -> Verdict:
    """The second half of :func:`judge`: ``v`` measured against the reference ``ref`` (when there is one
    and ``sol`` has an answer to measure) and graded (``grades``: what the tier grades). ``measurable``:
    whether ``sol``'s answer is measured (default: x and the evaluator's residuals are finite)."""
    finite = sol.x is not None and sol.residuals is not None and bool(sol.residuals.get("finite"))
    if ref is not None and (finite if measurable is None else measurable):
        d = measure(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)  # type: ignore[arg-type]
        v = replace(v, diff=d, err_x=d["x_energy"], err_mu=d["multipliers"], ref_solver=ref.solver,
                    ref_bound=ref.bound)
    return _graded(v, grades)


def judge(qp: QP, sol: Solution, tol: float, *, exact: bool = True, reference: Answer | None = None,
          reduction: Any = None, multipliers: bool = True, grades: str | None = None) -> Verdict:
    """The verdict on the claim ``sol`` for ``qp`` at tolerance ``tol`` (see the module docstring).

    The certification half is reused from ``sol.verdict`` when the runner already judged this solution at
    the same tolerance (its certificate costs solves); otherwise :func:`certify` runs on ``sol``'s claim
    (``sol.claim``, else its status). ``reference``: a trusted answer (:class:`Answer`) to measure and
    grade against; without one the outcome is at best ``unverified``.
    """
    v = sol.verdict
    if not isinstance(v, Verdict) or v.tol != tol:
        claimed = copy.copy(sol)          # the claim re-judged without touching ``sol``
        claimed.status = Status(sol.claim or str(sol.status))
        v = certify(qp, claimed, tol, exact, reduction, multipliers)
    return against(v, qp, sol, reference, grades=grades)
