"""The verify room: everything that decides whether an answer is to be trusted, in one place.

A solver plugin *claims* an answer (a :class:`~dualfem.core.solution.Solution` with a status); this room
*judges* it from the QP and (x, mu) alone, trusting no solver:

* the evaluator's residuals (:mod:`dualfem.core.evaluator`: ``residuals``, ``kkt_error``, ``compare``, ...)
  and the a-posteriori certificate (:mod:`dualfem.numerics.certify`: ``certified_error``,
  ``multiplier_floor``, ``KSolver``, ...), re-exported here (their modules move into this room later:
  import them from ``dualfem.verify``);
* the grading policy and the one outcome vocabulary (:mod:`dualfem.verify.grading`, docs/conventions.md);
* the reference policy (:mod:`dualfem.verify.reference`: when an answer is trusted as a reference);
* the one judge (:mod:`dualfem.verify.judge`): ``judge(qp, claim, tol, reference=...)`` -> :class:`Verdict`,
  used by solve (the runner's certification is its first half), compare, bench and stress.

Room order (docs/layout.md, tests/_imports.py): ``core <- numerics <- {solvers, problems, post} <- verify
<- experiments``; verify imports core and numerics only, never a plugin.
"""
from __future__ import annotations

from dualfem.core.evaluator import (
    RESIDUALS,
    active_set_solution,
    compare,
    contact_set,
    energy_norm,
    force_scale,
    kkt_error,
    kkt_residuals,
    residuals,
    size_energy,
    size_max,
)
from dualfem.numerics.certify import (
    KSolver,
    OperatorHints,
    active_set_check,
    active_set_error,
    certified_error,
    error_bound,
    infeasible_bound,
    multiplier_floor,
    solver_for,
)
from dualfem.verify.grading import (
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
from dualfem.verify.judge import OUTCOMES, Answer, Verdict, against, certify, judge, outcome, outcome_without_answer

__all__ = [
    # evaluator (dualfem.core.evaluator)
    "RESIDUALS", "active_set_solution", "compare", "contact_set", "energy_norm", "force_scale", "kkt_error",
    "kkt_residuals", "residuals", "size_energy", "size_max",
    # certificate (dualfem.numerics.certify)
    "KSolver", "OperatorHints", "active_set_check", "active_set_error", "certified_error", "error_bound",
    "infeasible_bound", "multiplier_floor", "solver_for",
    # grading (dualfem.verify.grading)
    "DEFAULT_GRADES", "GRADED", "GRADES", "HONEST", "SEVERITY", "check_grades", "combined", "grade",
    "grade_multipliers", "within",
    # the one judge (dualfem.verify.judge)
    "OUTCOMES", "Answer", "Verdict", "against", "certify", "judge", "outcome", "outcome_without_answer",
]
