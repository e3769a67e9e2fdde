"""The one reference policy: which answer every other run of a scene is measured against, and when it
is trusted. Pure policy on facts and on (x, mu) and the QP: computing a reference (running solvers) is
:func:`dualfem.experiments.reference.compute`.

A run is a **trusted reference** when (:func:`trust`)

1. its solver is exact (``Solver.exact``) and it claims ``solved``;
2. the evaluator's largest KKT residual, recomputed from (x, mu) and the QP, is at most
   ``kkt_max`` (never a run that fails its own residuals);
3. its a-posteriori energy-norm error certificate (:func:`dualfem.numerics.certify.certified_error`,
   computed from the QP alone) is finite and at most ``bound_max``. A zero solution of a zero
   load is exact (certificate 0).

Among trusted runs the one with the smallest certificate wins, ties broken by KKT error, then
time (:func:`rank_key`, :func:`choose`). ``compare`` ranks the runs it has (:func:`choose`); ``bench``
and ``stress`` compute one with :func:`dualfem.experiments.reference.compute`, trying :func:`candidates`
in order until one is trusted. The candidates are the solvers that declare themselves reference solvers
(``Solver.reference``, ordered by ``Solver.reference_rank``, solved with ``Solver.reference_params``):
no solver is named here. A run of the reference solver itself is measured against the next candidate
(:func:`candidates` with ``exclude``), never against itself.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from dualfem.core.evaluator import kkt_error
from dualfem.core.registry import solvers
from dualfem.core.solver import reference_solvers
from dualfem.numerics.certify import certified_error

#: default bound on a reference's own evaluator KKT error
KKT_MAX = 1e-8
#: default bound on a reference's certified relative energy-norm error (a looser reference only widens the
#: slack it grants: grades use tolerance + the reference's bound)
BOUND_MAX = 1e-4


@dataclass
class Reference:
    """A trusted reference solution of one QP."""

    solver: str
    x: np.ndarray
    multipliers: np.ndarray
    kkt: float
    bound: float
    time_s: float
    tolerance: float
    params: dict = field(default_factory=dict)


def candidates(exclude: tuple[str, ...] = (), only: tuple[str, ...] | None = None) -> list[tuple[str, dict]]:
    """(name, params) of the registered, installed exact reference solvers, preferred first
    (:func:`dualfem.core.solver.reference_solvers`: the solvers declaring ``reference``, by
    ``reference_rank``), each with its declared ``reference_params``.

    ``only`` replaces that list (e.g. a bench spec's ``reference.solvers``): any registered,
    installed exact solver, in the order given."""

    reg = solvers()
    names = list(only) if only is not None else [n for n, _ in reference_solvers(reg)]
    return [(n, dict(getattr(reg[n], "reference_params", {}))) for n in names
            if n not in exclude and n in reg and reg[n].missing() is None and reg[n].exact]


def may_serve(name: str) -> bool:
    """True when the registered solver ``name`` may be a reference: its class declares ``reference``
    and ``exact`` (docs/plugins.md 1.5). A name that is not registered may not."""
    reg = solvers()
    cls = reg.get(name)
    return cls is not None and bool(getattr(cls, "reference", False)) and bool(cls.exact)


def certificate(qp, x: np.ndarray | None, mu: np.ndarray | None, ksolve=None) -> float:
    """Certified relative energy-norm error of (x, mu); 0 for the exact zero answer of a zero load."""

    if x is None or mu is None:
        return float("nan")
    if exact_zero(qp, x, mu):
        return 0.0
    return float(certified_error(qp, x, mu, ksolve)["value"])


def exact_zero(qp, x: np.ndarray, mu: np.ndarray) -> bool:
    """x = 0, mu = 0 for a zero load: the exact answer, whose relative error the certificate cannot express."""
    return not np.any(x) and not np.any(qp.F) and not np.any(mu)


def trusted(status: str, exact: bool, kkt: float | None, bound: float | None, *, kkt_max: float = KKT_MAX,
            bound_max: float = BOUND_MAX) -> tuple[bool, str]:
    """The policy as a predicate on a run's facts: (trusted, reason)."""
    if not exact:
        return False, "not an exact solver"
    if str(status) != "solved":
        return False, f"status {status}"
    if kkt is None or not kkt <= kkt_max:
        return False, f"KKT error {kkt} > {kkt_max:g}"
    if bound is None or not (math.isfinite(bound) and bound <= bound_max):
        return False, f"certified error {bound} not <= {bound_max:g}"
    return True, "trusted"


def trust(qp, sol, *, exact: bool = True, kkt_max: float = KKT_MAX, bound_max: float = BOUND_MAX,
          ksolve=None) -> tuple[bool, float, float, str]:
    """(trusted, certificate, kkt, reason) of a solution ``sol`` (see the module docstring)."""

    finite = sol.residuals is not None and sol.residuals.get("finite", False)
    kkt = kkt_error(sol.residuals) if finite else float("nan")
    bound = certificate(qp, sol.x, sol.multipliers, ksolve) if finite and str(sol.status) == "solved" and exact \
        else float("nan")
    ok, why = trusted(str(sol.status), exact, kkt, bound, kkt_max=kkt_max, bound_max=bound_max)
    return ok, bound, kkt, why


def rank_key(bound: float, kkt: float, seconds: float) -> tuple[float, float, float]:
    """Order of trusted references: smallest certificate, then KKT error, then time."""
    return (bound, kkt, seconds)


@dataclass(frozen=True)
class Candidate:
    """The facts of one run that the policy needs to rank it as a reference: its solver's name, status,
    exactness, evaluator KKT error, certified relative energy-norm error bound, time in seconds, and the
    largest KKT error it may have (``kkt_max``: compare uses the run's own declared tolerance)."""

    solver: str
    status: str
    exact: bool
    kkt: float | None
    bound: float | None
    seconds: float | None
    kkt_max: float = KKT_MAX


def choose(runs: Iterable[Candidate]) -> tuple[str | None, list[str]]:
    """The policy applied to runs already made: the trusted ones (:func:`trusted` with each run's
    ``kkt_max``), ranked by :func:`rank_key` (then solver name); the reference is the first of them whose
    solver declares ``reference`` (:func:`may_serve`: a third-party solver never is unless it says so), the
    others are the cross-check candidates. Returns (reference or None, the other trusted runs in order)."""
    ranked = []
    for r in runs:
        ok, _ = trusted(r.status, r.exact, r.kkt, r.bound, kkt_max=r.kkt_max)
        if ok:
            ranked.append((rank_key(r.bound, r.kkt, r.seconds), r.solver))  # type: ignore[arg-type]
    ranked.sort()
    names = [n for _, n in ranked]
    ref = next((n for n in names if may_serve(n)), None)
    return ref, [n for n in names if n != ref]
