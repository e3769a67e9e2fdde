"""One ``--tol`` for ``solve``, ``compare`` and ``bench``: the certified tolerance the runner checks.

``--tol T`` (a relative energy-norm error of x, in (0, 1)) asks every solver for the accuracy T: its
parameters become ``Solver.tolerance_params(T)`` (how that solver meets T: docs/solvers_tolerances.md)
under what the user gave with ``-p``, and the runner certifies the answer to T itself
(:func:`dualfem.experiments.runner.run` with ``tol=T``; ``bench --tol T`` replaces the spec's tiers by one
tier ``tol = T``). Without ``--tol`` an answer is certified to the tolerance its solver declares.

``-p tol=...`` stays each solver's raw stop rule (its own option, e.g. uzawa's relative change of mu,
OSQP's eps); when a solver stops ``solved`` by it but the certificate does not hold,
:func:`explain` says why in the run's message.
"""
from __future__ import annotations

import math
from typing import Any

from dualfem.core.errors import InputError


def check_tol(value: Any, flag: str = "--tol") -> float | None:
    """``--tol`` as a float in (0, 1), or None when not given; InputError naming the range otherwise."""
    if value is None:
        return None
    try:
        t = float(value)
    except (TypeError, ValueError):
        t = math.nan
    if isinstance(value, bool) or not math.isfinite(t) or not 0 < t < 1:
        raise InputError(f"{flag} must be a finite number in (0, 1) (the certified relative energy-norm error of x), "
                         f"got {value!r}")
    return t


def with_tolerance(cls: Any, tol: float | None, params: dict[str, Any] | None) -> dict[str, Any]:
    """The parameters of a run asked for ``tol``: ``cls.tolerance_params(tol)`` under the user's ``params``
    (which win: a ``-p tol`` is the solver's raw stop rule); ``params`` unchanged without ``tol``."""
    params = dict(params or {})
    if tol is None or cls is None:
        return params
    return {**cls.tolerance_params(tol), **params}


def explain(sol: Any, params: dict[str, Any] | None, asked: float | None) -> str | None:
    """Why a run the solver called ``solved`` is not, when the user set the solver's own ``tol``: one
    sentence naming both tolerances (None when there is nothing to explain)."""
    claimed = str(sol.info.get("claimed_status", sol.status))
    if claimed != "solved" or str(sol.status) == "solved" or "tol" not in (params or {}):
        return None
    certified = sol.info.get("certified_tol")
    whose = f"--tol {asked:g}" if asked is not None else "the tolerance the solver declares"
    target = f" ({certified:g})" if isinstance(certified, (int, float)) and asked is None else ""
    return (f"-p tol={params['tol']} is {sol.solver}'s own stop rule, which it met; the answer is certified to "
            f"{whose}{target}: ask the solver for a tighter -p tol, or certify to a looser --tol")
