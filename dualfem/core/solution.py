"""Solver results: a status enum and a Solution that carries its own (independent) residuals."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class Status(enum.StrEnum):
    """Outcome of a solve. Only ``SOLVED`` means the solver claims an answer to its tolerance."""

    SOLVED = "solved"
    INACCURATE = "inaccurate"          # stopped with a worse accuracy than asked
    MAX_ITER = "max_iter"
    TIME_LIMIT = "time_limit"
    STAGNATION = "stagnation"          # no progress / cycling detected
    NUMERICAL_ERROR = "numerical_error"  # NaN/inf, failed factorization
    INFEASIBLE = "infeasible"
    ERROR = "error"                    # the solver raised
    SKIPPED = "skipped"                # not applicable to this QP (reason in ``message``)

    def __str__(self) -> str:  # noqa: D105
        return self.value


@dataclass
class Solution:
    """What a solver returns.

    ``x`` are the displacements, ``multipliers`` the nodal contact forces (>= 0 in compression,
    ``Kx - F = B' multipliers``; see :mod:`dualfem.qp`). ``iterations`` is a dict of counters
    (e.g. ``{"outer": k, "inner": m}``), ``history`` a list of per-iteration dicts where the
    solver has one, ``time_s`` holds ``setup`` and ``solve`` wall times in seconds.
    ``residuals`` is filled by :func:`dualfem.evaluator.residuals`, never by the solver.

    **Claim and verdict apart.** A plugin returns its *claim* in ``status``. The runner
    (:func:`dualfem.experiments.runner.run`) then judges it (:func:`dualfem.verify.judge`) and keeps both:
    ``claim`` is the plugin's own status (a string; also in ``info["claimed_status"]``, where JSON
    records read it), ``verdict`` the judge's :class:`dualfem.verify.Verdict` (its outcome, certified
    error bounds, residuals and why), and ``status`` -- for compatibility, as before -- the *certified*
    status: the claim, or ``inaccurate`` when the judge demoted it (``numerical_error`` for a non-finite
    answer). A solver leaves ``claim`` and ``verdict`` None; a Solution no runner judged has both None.
    """

    solver: str
    status: Status
    x: np.ndarray | None = None
    multipliers: np.ndarray | None = None
    iterations: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    time_s: dict = field(default_factory=lambda: {"setup": 0.0, "solve": 0.0})
    message: str = ""
    params: dict = field(default_factory=dict)
    residuals: dict | None = None
    info: dict = field(default_factory=dict)
    claim: str | None = None
    verdict: Any = None     # a dualfem.verify.Verdict (the core does not import the room above it)

    @property
    def ok(self) -> bool:
        """True when the solver claims success."""
        return self.status == Status.SOLVED
