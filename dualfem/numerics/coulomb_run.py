"""Coulomb friction for a solver that handles Tresca: the fixed point of :mod:`dualfem.numerics.coulomb` over the
solver's own Tresca solves, returned as the fields of one answer (the conic and QP backends use it).

``coulomb_by_tresca(qp, solve_one, tol, max_iter, label)`` (a plugin's whole answer: ``coulomb_solution``):
``solve_one(qp_tresca) -> Solution`` is the solver's
Tresca path on the QP whose Coulomb blocks the fixed point replaced by Tresca blocks of the current threshold
(same rows and multiplier layout). A Tresca solve that is not ``solved`` stops the loop (status
``numerical_error``, its message kept); a fixed point that reaches ``max_iter`` or stalls is ``max_iter``, never
``solved`` (the last Tresca answer is returned for the certificate to judge). Counters: the whole-number counters
of the Tresca solves summed, plus ``coulomb`` (Tresca solves); the contraction estimates, the changes and the
relaxation go to ``info["coulomb"]``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dualfem.core.qp import QP
from dualfem.core.solution import Solution, Status
from dualfem.numerics.coulomb import coulomb_fixed_point


@dataclass
class CoulombOutcome:
    """What a solver puts in its Solution: status, x, mu, iterations (whole numbers), info, message."""

    status: Status
    x: np.ndarray | None
    mu: np.ndarray | None
    iterations: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    message: str = ""


def _whole(counters: dict) -> dict:
    return {k: int(v) for k, v in counters.items()
            if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and float(v) == int(v)}


def coulomb_by_tresca(qp: QP, solve_one: Callable[[QP], Solution], tol: float, max_iter: int,
                      label: str) -> CoulombOutcome:
    """The Coulomb answer of ``qp`` by the fixed point over ``solve_one``'s Tresca solves (module docstring)."""

    def tresca(tq: QP, warm):
        sol = solve_one(tq)
        if sol.status != Status.SOLVED or sol.x is None or sol.multipliers is None:
            raise RuntimeError(f"{label} on a Tresca problem of the Coulomb fixed point: {sol.status} "
                               f"({sol.message})")
        return sol.x, sol.multipliers, _whole(sol.iterations or {})

    try:
        res = coulomb_fixed_point(qp, tresca, tol, max_iter)
    except RuntimeError as exc:
        return CoulombOutcome(Status.NUMERICAL_ERROR, None, None, message=str(exc))
    rho = [c for c in res.contractions if np.isfinite(c)]
    info = {"coulomb": {"iterations": res.iterations, "changes": [float(c) for c in res.changes],
                        "contraction": float(max(rho)) if rho else 0.0, "stalled": bool(res.stalled),
                        "relax": float(res.relax)}}
    status = Status.SOLVED if res.status == "solved" else Status.MAX_ITER
    last = res.changes[-1] if res.changes else 0.0
    why = "" if status == Status.SOLVED else (" (stalled: the change stopped falling)" if res.stalled else
                                              f" (max_iter = {max_iter} reached)")
    msg = (f"Coulomb fixed point: {res.iterations} Tresca solve(s), last relative change of the threshold "
           f"{last:.1e}{why}")
    return CoulombOutcome(status, res.x, res.mu, {**_whole(res.counters), "coulomb": res.iterations}, info, msg)


def coulomb_solution(solver, build_and_solve: Callable[[QP], Solution], label: str,
                     prefix: str | None = None) -> Solution:
    """The Solution of a solver plugin (``solver.name``, ``solver.qp``, its ``coulomb_tol`` and
    ``coulomb_max_iter`` parameters) on a Coulomb QP: :func:`coulomb_by_tresca` over ``build_and_solve`` (one
    Tresca problem set up and solved by the plugin), its message led by ``prefix`` (default ``label``)."""
    c = coulomb_by_tresca(solver.qp, build_and_solve, float(solver.params["coulomb_tol"]),
                          int(solver.params["coulomb_max_iter"]), label)
    return Solution(solver=solver.name, status=c.status, x=c.x, multipliers=c.mu, iterations=c.iterations,
                    message=f"{prefix or label}: {c.message}", info=c.info)
