"""Run a solver on a QP: time setup and solve separately, attach independent residuals, certify.

``run`` never lets a solver fail silently: a missing dependency or a skip reason becomes
``Status.SKIPPED`` with the reason, an exception inside the solver becomes ``Status.ERROR`` with
its message, and the residuals always come from :mod:`dualfem.core.evaluator`.

**Certification** (:func:`certify_status`), for every plugin: a ``solved`` claim stands only if
the evaluator's scale-free KKT residuals, recomputed from (x, mu) and the QP (the stationarity
residual beyond its measured rounding floor, :data:`dualfem.core.evaluator.ROUNDING_C`; for a shifted
QP in the QP's own and in the user's unknowns, :mod:`dualfem.core.evaluator`), are within the
tolerance the solver instance declares, and, for exact solvers, the a-posteriori energy-norm
error certificate (:func:`dualfem.numerics.certify.certified_error`) is too where it applies, and
so is the certified error of the multipliers (against the exact multipliers of the verified active
set: the contact forces are certified, not only x).
Otherwise the status becomes ``inaccurate`` with a message naming the residual and by how much;
the plugin's own claim stays in ``Solution.info["claimed_status"]``.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.registry import get_solver
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver


def make_solver(name: str, params: dict[str, Any] | None = None) -> Solver:
    """Instantiate the registered solver ``name`` with ``params`` (validated)."""
    return get_solver(name)(**(params or {}))


def run(solver: Solver | str, qp: QP, params: dict[str, Any] | None = None, *, tol: float | None = None,
        progress: Callable[[str, float], None] | None = None) -> Solution:
    """Solve ``qp`` with ``solver`` (an instance, or a registry name plus ``params``).

    ``tol``: the relative accuracy asked for (e.g. a benchmark tier, with the parameters of
    ``Solver.tolerance_params(tol)``); the answer is then certified to ``tol`` itself (a `solved` at a
    benchmark tier means that tier's accuracy, whatever the solver declares by default).
    Without it, to the tolerance the solver declares. ``progress(stage, seconds)`` is called as
    each stage (setup, solve, certify) finishes.
    """
    tick = progress or (lambda stage, seconds: None)
    if isinstance(solver, str):
        solver = make_solver(solver, params)
    solver.check_params()          # again: a plugin may override __init__ or change params after it
    reason = solver.missing() or solver.skip(qp)
    if reason:
        return Solution(solver=solver.name, status=Status.SKIPPED, message=reason, params=dict(solver.params))
    t0 = time.perf_counter()
    try:
        solver.setup(qp)
        t1 = time.perf_counter()
        tick("setup (factorization)", t1 - t0)
        sol = solver.solve()
        t2 = time.perf_counter()
        tick("solve (iterations)", t2 - t1)
    except InputError:
        raise
    except Exception as exc:  # the solver broke: say so, never hide it
        return Solution(solver=solver.name, status=Status.ERROR, params=dict(solver.params),
                        message=f"{type(exc).__name__}: {exc}",
                        time_s={"setup": 0.0, "solve": time.perf_counter() - t0})
    sol.time_s = {"setup": t1 - t0, "solve": t2 - t1, **{k: v for k, v in sol.time_s.items()
                                                         if k not in ("setup", "solve")}}
    sol.params = dict(solver.params)
    attach_residuals(qp, sol)
    t3 = time.perf_counter()
    asked = None if tol is None or not np.isfinite(tol) else float(tol)
    declared = float(solver.tolerance) if asked is None else asked
    certify_status(qp, sol, declared, bool(solver.exact), reduction=getattr(solver, "reduction", None))
    sol.time_s["certify"] = time.perf_counter() - t3
    tick("certification", sol.time_s["certify"])
    return sol


def certify_status(qp: QP, sol: Solution, tol: float, exact: bool, reduction: Any = None) -> Solution:
    """Demote an uncertified ``solved`` claim to ``inaccurate`` (see the module docstring).

    ``reduction``: the solver's LocalReduction of ``qp`` (``Solver.reduction``), reused if valid.
    """
    sol.info.setdefault("claimed_status", str(sol.status))
    sol.info["certified_tol"] = tol
    res = sol.residuals
    if sol.status != Status.SOLVED or res is None or not res.get("finite", False) or sol.x is None \
            or sol.multipliers is None:
        return sol
    worst = max(evaluator.RESIDUALS, key=lambda k: res[k])
    why = None
    if res[worst] > tol:
        why = f"evaluator residual {worst} = {res[worst]:.1e} exceeds the declared tolerance {tol:g}"
    elif exact:
        from dualfem.numerics.certify import KSolver, certified_error, multiplier_floor

        try:
            ks = KSolver(qp, reduction=reduction)
            sol.info["certificate"] = certified_error(qp, sol.x, sol.multipliers, ks)
            cm = sol.info["certificate"].get("multipliers", float("nan"))
            if np.isfinite(cm) and cm > tol:      # only then: the rounding floor of mu* costs one more solve
                sol.info["certificate"]["multipliers_floor"] = multiplier_floor(qp, sol.x, sol.multipliers, ks)
        except (np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
            sol.info["certificate"] = {"bound": float("nan"), "active_set": float("nan"), "value": float("nan"),
                                       "error": f"{type(exc).__name__}: {exc}"}
            sol.message = f"{sol.message}; certificate unavailable ({type(exc).__name__}: {exc})".lstrip("; ")
        cert = sol.info["certificate"]["value"]
        cmu = sol.info["certificate"].get("multipliers", float("nan"))
        cfloor = sol.info["certificate"].get("multipliers_floor", 0.0)
        cmu = cmu - (cfloor if np.isfinite(cfloor) else 0.0)      # beyond the rounding of mu* itself
        if np.isfinite(cert) and cert > tol:
            why = (f"certified energy-norm error bound {cert:.1e} exceeds the declared tolerance {tol:g} "
                   f"(residuals are within it)")
        elif np.isfinite(cmu) and cmu > tol:
            why = (f"certified multiplier error {cmu:.1e} (|mu - mu*|_inf against the exact multipliers of the "
                   f"verified active set, relative to max(|mu*|, |F|), beyond their rounding floor "
                   f"{cfloor:.1e}) exceeds the declared tolerance {tol:g}")
    if why:
        sol.status = Status.INACCURATE
        sol.message = f"{sol.message}; not certified: {why}" if sol.message else f"not certified: {why}"
    return sol


def attach_residuals(qp: QP, sol: Solution) -> Solution:
    """Fill ``sol.residuals`` from the evaluator; a non-finite answer cannot stay 'solved'."""
    if sol.x is None:
        return sol
    if sol.multipliers is None:
        sol.multipliers = np.zeros(qp.m)
    sol.residuals = evaluator.residuals(qp, sol.x, sol.multipliers)
    if not sol.residuals["finite"] and sol.status == Status.SOLVED:
        sol.status = Status.NUMERICAL_ERROR
        sol.message = (sol.message + "; " if sol.message else "") + "solution contains NaN/inf"
    return sol


def summary(qp: QP, sol: Solution) -> dict:
    """The JSON record of one solve (field names are a stable interface)."""
    out: dict[str, Any] = {
        "solver": sol.solver,
        "status": str(sol.status),
        "claimed_status": sol.info.get("claimed_status", str(sol.status)),
        "message": sol.message,
        "problem": qp.name,
        "ndof": qp.n,
        "n_defect_nodes": qp.m,
        "iterations": sol.iterations,
        "time_s": sol.time_s,
        "params": jsonable_params(sol.params),
    }
    if sol.x is not None and sol.multipliers is not None and sol.residuals is not None and sol.residuals["finite"]:
        jump = qp.B @ sol.x
        out.update({
            # the user's objective, from the user's unknowns (a shifted QP: y = x + x_shift, not Pi(x) plus
            # the shift's constant, which cancels catastrophically when the shift is large)
            "energy": sol.residuals.get("objective", sol.residuals["energy"]),
            "max_jump": float(jump.max(initial=0.0)),
            "n_contact": int(evaluator.contact_set(qp, sol.x).sum()),
            "contact_rtol": evaluator.CONTACT_RTOL,
            "total_contact_force": float(np.sum(sol.multipliers)),
            "residuals": evaluator.kkt_residuals(sol.residuals),
            "stationarity_raw": sol.residuals.get("stationarity_raw"),
        })
        cert = sol.info.get("certificate")
        if cert:
            out["certificate"] = {k: v for k, v in cert.items()
                                  if k in ("value", "bound", "active_set", "multipliers", "multipliers_floor")}
    else:
        out.update({"energy": None, "max_jump": None, "n_contact": None, "residuals": None})
    return out


def jsonable_params(d: dict) -> dict:
    """Parameters as JSON-safe scalars (anything else as its string)."""
    return {k: (v if isinstance(v, (int, float, str, bool, type(None))) else str(v)) for k, v in d.items()}
