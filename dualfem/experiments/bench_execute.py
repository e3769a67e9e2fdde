"""One task of a benchmark sweep, run in a worker process (:mod:`dualfem.experiments.harness`):
:func:`execute` a ``run`` (a solver on a scene at a tolerance tier, timed and graded), a
``reference`` (the certified exact solve a scene's errors are measured against, checked by
:func:`check_reference`) or a ``floor`` (one sparse factorization + one solve of the unconstrained
K). Returns the task's :class:`~dualfem.experiments.row.Row` as a dict (times in seconds ``*_s``,
errors relative) and a payload. The sweep that schedules the tasks is :mod:`dualfem.experiments.bench`.
"""
from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dualfem.experiments.curves import sample_errors, timed_runs
from dualfem.experiments.machine import loadavg, machine_info, utc_now
from dualfem.experiments.row import Row
from dualfem.experiments.tasks import _canon


def _base_row(task: dict) -> Row:
    row = Row(run_id=task["run_id"], kind=task["kind"], started_utc=utc_now(), repeats_done=0)
    for k in ("spec", "scene", "scene_key", "label", "solver", "variant", "tier", "tol", "grades", "repeats",
              "time_limit", "cold_setup"):
        row[k] = task.get(k)
    row.solver_params = _canon(task.get("params", {}))
    for k, v in (task.get("scene_params") or {}).items():
        row[f"scene_{k}"] = v
    return row


def skipped_row(task: dict) -> dict:
    """The row of a task that is not run (reason in ``message``)."""
    row = _base_row(task)
    row.update(status="skipped", grade="skipped", message=task["skip"])
    return row.to_dict()


def execute(task: dict, tick: Callable[[str, float], None] = lambda phase, budget: None) -> tuple[dict, Any]:
    """Run one task in this process; returns (row dict, payload). ``tick`` announces each phase."""
    if task.get("skip"):
        return skipped_row(task), None
    from dualfem.core.scene import load_scene

    row = _base_row(task)
    row.update(machine_info())
    row.loadavg = loadavg()       # 1-minute load average when the task started (a busy machine)
    tick("build", task["build_limit"])
    t0 = time.perf_counter()
    qp = load_scene(task["scene"], task["scene_params"]).build()
    row.assembly_s = time.perf_counter() - t0
    row.n_unknowns, row.n_constraints = qp.n, qp.m
    if task["kind"] == "floor":
        return _execute_floor(task, qp, row, tick).to_dict(), None
    if task["kind"] == "reference":
        row, payload = _execute_reference(task, qp, row, tick)
        return row.to_dict(), payload
    row, curve = _execute_run(task, qp, row, tick)
    return row.to_dict(), ({"curve": curve} if curve else None)


def _execute_run(task: dict, qp, row: Row, tick) -> tuple[Row, dict | None]:
    """The run's row, and its convergence curve (:mod:`dualfem.experiments.curves`) or None."""
    from dualfem.core.solution import Status
    from dualfem.verify import Answer, against

    ref = task.get("ref")
    sol, setups, solves, done, note, monitor = timed_runs(task, qp, task["solver"], task["params"], tick,
                                                          task["warmup"], task["repeats"])
    status = str(sol.status)
    total = [a + b for a, b in zip(setups, solves)]
    msg = sol.message
    tl = task.get("time_limit")
    if sol.status in (Status.SOLVED, Status.INACCURATE) and tl and total and _median(total) > tl:
        msg = f"finished in {_median(total):.3g} s, over the time limit {tl:g} s (was {status}); " + msg
        status = "time_limit"
    if note:
        msg = f"{msg}; {note}" if msg else note
    row.update(status=status, claimed_status=sol.info.get("claimed_status", str(sol.status)), message=msg,
               iterations=_canon(sol.iterations), repeats_done=done, setup_s=_median(setups),
               solve_s=_median(solves), total_s=_median(total), setup_s_all=json.dumps(setups),
               solve_s_all=json.dumps(solves))
    row.set_residuals(sol.residuals, task.get("tol"))
    row.set_certificate(sol.info.get("certificate"))
    if sol.x is not None and sol.residuals is not None and sol.residuals.get("finite"):
        if ref is None:
            row.message = (row.message + "; " if row.message else "") + "no certified reference: errors not measured"
        elif ref["qp_key"] != qp.key():
            row.message = (row.message + "; " if row.message else "") + \
                "reference is stale (the scene's QP changed): errors not measured; delete the refs cache"
        else:       # the one judge: measured against the reference and graded (dualfem.verify.judge)
            row.take(against(row.facts(), qp, sol, Answer(ref["solver"], ref["x"], ref["multipliers"],
                                                          ref.get("bound")), grades=row.grades))
            row.ref_kkt = ref["kkt"]
    row.regrade()
    tick("curve errors", task["hard_limit"])
    curve = sample_errors(qp, monitor, ref)
    if curve and curve["note"]:
        row.message = (row.message + "; " if row.message else "") + curve["note"]
    return row, curve


def check_reference(qp, ref: dict, kkt_max: float) -> tuple[str | None, float, float]:
    """(None if ``ref`` is a trusted reference of ``qp``, else why not; its KKT error; its certified
    error), all recomputed from (x, multipliers) against the QP itself (the cached numbers are not
    believed): the policy of :func:`dualfem.experiments.reference.trusted` with ``kkt_max``."""
    from dualfem.core import evaluator
    from dualfem.experiments import reference

    if ref.get("qp_key") != qp.key():
        return "it belongs to another QP (the scene's QP changed)", float("nan"), float("nan")
    x, mu = np.asarray(ref["x"], dtype=float), np.asarray(ref["multipliers"], dtype=float)
    if x.shape != (qp.n,) or mu.shape != (qp.m_total,):      # m_total: every constraint block's multipliers
        return (f"its shapes {x.shape}, {mu.shape} are not the QP's ({qp.n},), ({qp.m_total},)", float("nan"),
                float("nan"))
    try:
        res = evaluator.residuals(qp, x, mu)
        kkt = evaluator.kkt_error(res) if res.get("finite", True) else float("nan")
        bound = reference.certificate(qp, x, mu) if math.isfinite(kkt) else float("nan")
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return f"it cannot be checked ({type(exc).__name__}: {exc})", float("nan"), float("nan")
    ok, why = reference.trusted("solved", True, kkt, bound, kkt_max=kkt_max)
    return (None if ok else why), kkt, bound


def _execute_reference(task: dict, qp, row: Row, tick) -> tuple[Row, Any]:
    from dualfem.experiments import reference

    spec = task["reference"]
    cached = task.get("verify")
    rejected = None
    if cached is not None:          # a cached reference: checked against the QP, recomputed if it fails
        tick("check reference", task["hard_limit"])
        rejected, kkt, bound = check_reference(qp, cached, spec["certify"])
        if rejected is None:
            row.update(status="solved", kkt_error=kkt, ref_bound=bound)
            return row, {"verified": True, "kkt": kkt, "bound": bound}
        rejected = f"the cached reference failed its check against the QP: {rejected}"
    tick("reference", task["hard_limit"])
    ref, tried = reference.compute(qp, kkt_max=spec["certify"], time_limit=spec["time_limit"], tol=spec["tol"],
                                   params=spec["params"], only=tuple(spec["solvers"]))
    if rejected:
        row["ref_rejected"] = rejected
        tried.insert(0, rejected + ", recomputed")
    if ref is None:
        row.update(status="error", solver="none", grade="failed", message="no certified reference: " + "; ".join(tried))
        return row, None
    row.update(solver=ref.solver, variant=ref.solver, solver_params=_canon(ref.params), status="solved",
               tol=spec["certify"], setup_s=ref.time_s, solve_s=0.0, total_s=ref.time_s, repeats_done=1,
               kkt_error=ref.kkt, ref_bound=ref.bound, grade="correct",
               message=f"certified: evaluator KKT error {ref.kkt:.2e} <= {spec['certify']:g}, certified energy-norm "
                       f"error {ref.bound:.1e}; tried " + "; ".join(tried))
    payload = {"x": ref.x, "multipliers": ref.multipliers, "qp_key": qp.key(), "solver": ref.solver,
               "kkt": ref.kkt, "bound": ref.bound, "params": json.dumps(_canon(ref.params), sort_keys=True)}
    return row, payload


def _median(v: list[float]) -> float:
    return float(np.median(v)) if v else float("nan")


def _execute_floor(task: dict, qp, row: dict, tick) -> dict:
    """One sparse factorization + one solve of the unconstrained K (scipy splu, and CHOLMOD if present)."""
    import scipy.sparse.linalg as sla

    rows = []
    K = qp.K.tocsc()

    def splu():
        lu = sla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        return lu.solve

    methods = [("floor_splu", splu)]
    from dualfem.numerics.factor import available
    from dualfem.numerics.linalg import on_fixed_pattern, sparse_factor

    if "pardiso" in available():      # MKL PARDISO: the fastest library factorization here
        methods.append(("floor_pardiso", lambda: sparse_factor(K, "pardiso").solve))
        if qp.local is not None:      # the same K on the elastic pattern (node blocks kept): often faster
            K_el_pattern = on_fixed_pattern(K, qp.local.K_fixed).tocsc()
            methods.append(("floor_pardiso_blocked", lambda: sparse_factor(K_el_pattern, "pardiso").solve))
    missing_cholmod = ""
    if task.get("cholmod"):
        try:
            from sksparse.cholmod import cholesky  # type: ignore

            methods.append(("floor_cholmod", lambda: cholesky(K)))
        except ImportError:
            missing_cholmod = ("CHOLMOD floor not measured: scikit-sparse is not installed "
                               "(apt-get install libsuitesparse-dev; pip install 'dualfem[cholmod]')")
    out = row
    results = {}
    for name, factor in methods:
        fac, sol_t, res = [], [], float("nan")
        for i in range(int(task["warmup"]) + task["repeats"]):
            tick(f"{name} {i}", task["hard_limit"])
            t0 = time.perf_counter()
            f = factor()
            t1 = time.perf_counter()
            x = f(qp.F)
            t2 = time.perf_counter()
            if i >= int(task["warmup"]):
                fac.append(t1 - t0)
                sol_t.append(t2 - t1)
            res = float(np.abs(K @ x - qp.F).max() / max(np.abs(qp.F).max(), 1e-300))
            del f
        results[name] = (fac, sol_t, res)
        rows.append(name)
    # the fastest method is the floor; every method's times are kept in the message
    best = min(results, key=lambda n: _median([a + b for a, b in zip(results[n][0], results[n][1])]))
    fac, sol_t, res = results[best]
    tot = [a + b for a, b in zip(fac, sol_t)]
    others = "; ".join(f"{n}: {_median([a + b for a, b in zip(f_, s_)]):.3g} s (residual {r:.1e})"
                       for n, (f_, s_, r) in results.items())
    out.update(solver=best, variant=best, status="solved" if res < 1e-6 else "inaccurate",
               setup_s=_median(fac), solve_s=_median(sol_t), total_s=_median(tot), repeats_done=len(tot),
               setup_s_all=json.dumps(fac), solve_s_all=json.dumps(sol_t),
               message=f"factorization + one solve of the unconstrained K; {others}"
                       + (f"; {missing_cholmod}" if missing_cholmod else ""))
    return out
