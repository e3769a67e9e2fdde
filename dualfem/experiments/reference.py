"""Computing a trusted reference: run the reference candidates in order until one is trusted.

The policy itself (what is trusted, how references are ranked, which solvers are candidates) lives in the
verify room, :mod:`dualfem.verify.reference`; its names are re-exported here, where bench, stress and the
studies have always imported them. This module only adds :func:`compute`, which runs solvers (and so
belongs to experiments).
"""
from __future__ import annotations

import time
from typing import Any

from dualfem.core.registry import get_solver
from dualfem.experiments.runner import run
from dualfem.verify.reference import (  # noqa: F401 (the policy, re-exported)
    BOUND_MAX,
    KKT_MAX,
    Candidate,
    Reference,
    candidates,
    certificate,
    choose,
    exact_zero,
    may_serve,
    rank_key,
    trust,
    trusted,
)


def compute(qp, *, exclude: tuple[str, ...] = (), kkt_max: float = KKT_MAX, bound_max: float = BOUND_MAX,
            time_limit: float | None = None, tol: float | None = None,
            params: dict[str, dict] | None = None,
            only: tuple[str, ...] | None = None) -> tuple[Reference | None, list[str]]:
    """Run :func:`candidates` in order until one is trusted; returns (reference or None, what was tried).

    ``tol`` asks each solver for that accuracy (``Solver.tolerance_params``), ``params`` adds
    per-solver parameters, ``time_limit`` goes to solvers that take one.
    """

    tried: list[str] = []
    for name, base in candidates(exclude, only):
        cls = get_solver(name)
        p: dict[str, Any] = {**base, **(cls.tolerance_params(tol) if tol else {}), **(params or {}).get(name, {})}
        if time_limit is not None and "time_limit" in cls.defaults:
            p["time_limit"] = float(time_limit)
        t0 = time.perf_counter()
        sol = run(name, qp, p)
        dt = time.perf_counter() - t0
        ok, bound, kkt, why = trust(qp, sol, kkt_max=kkt_max, bound_max=bound_max)
        tried.append(f"{name}: {sol.status}, KKT error {kkt:.2e}, certified error {bound:.1e}"
                     + ("" if ok else f" ({why})"))
        if ok:
            return Reference(solver=name, x=sol.x, multipliers=sol.multipliers, kkt=kkt, bound=bound, time_s=dt,
                             tolerance=float(cls.tolerance), params=p), tried
    if not tried:
        names = ", ".join(only) if only is not None else "none declares Solver.reference"
        tried.append(f"no exact reference solver ({names}) is registered and installed")
    return None, tried
