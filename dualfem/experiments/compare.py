"""Cross-check several solvers on one QP against a certified reference.

:func:`compare_solvers` runs the chosen (default: every registered and installed) solvers on one
QP, through :func:`dualfem.runner.run` (so statuses, timings and the evaluator's independent
residuals are the same as for ``dualfem solve``), picks the reference, and judges each run.

Reference: chosen by the one reference policy (:mod:`dualfem.experiments.reference`): among the
runs of *exact* solvers that claim success with an evaluator KKT error within their own declared
tolerance, the one with the smallest a-posteriori energy-norm error certificate
(:func:`dualfem.numerics.certify.certified_error`, computed from the QP alone: the smaller of the
rigorous duality-gap bound on |x - x*|_K / |x|_K and, when the active set is verified with
margins, the first-order size of an exact refinement step on it), ties broken by the KKT error,
then time. The record's ``error_bound`` is that value, ``certificate`` holds both parts. It is
cross-checked against the next best trusted run: their difference must lie within the second
one's declared tolerance plus both bounds. Runs whose x is bit-for-bit the reference's are listed
(``identical_to_reference``) but skipped as cross-checks.

Verdict of each run (``verdict`` field), compare's word for :func:`dualfem.core.grade.grade`:

* ``reference``: the reference itself;
* ``ok``: claims success and is right: evaluator KKT error <= its declared ``tolerance`` and
  relative energy-norm difference to the reference <= ``tolerance`` + the reference's bound;
* ``wrong``: claims success (status ``solved``) but fails one of those tests -- a *silent wrong
  answer*: the only verdict that makes ``dualfem compare`` exit non-zero;
* ``failed``: reports a non-success status (honest; the differences are still shown when it
  returned an x);
* ``skipped``: not applicable or not installed (reason in ``message``);
* ``unchecked``: claims success but no certified reference exists to check it against.
"""
from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dualfem.core import evaluator
from dualfem.core.qp import QP
from dualfem.core.registry import get_solver
from dualfem.core.registry import solvers as registered
from dualfem.core.solution import Solution, Status
from dualfem.experiments import reference
from dualfem.experiments.row import Row
from dualfem.experiments.runner import jsonable_params
from dualfem.numerics.certify import certified_error, solver_for

#: fields of each run record (stable JSON interface of ``dualfem compare --json``)
RUN_FIELDS = ("solver", "status", "verdict", "exact", "tolerance", "iterations", "energy", "time_s",
              "residuals", "kkt_error", "error_bound", "certificate", "diff", "n_contact", "message", "params")


def default_solvers() -> list[str]:
    """Every registered solver, in name order (missing dependencies show up as ``skipped``)."""
    return sorted(registered())


def compare_solvers(qp: QP, names: list[str] | None = None, params: dict[str, dict] | None = None,
                    progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run ``names`` on ``qp``; return the comparison record (see module docstring).

    ``params`` maps a solver name to its parameters. ``progress`` receives one line per finished
    solver.
    """
    from dualfem.experiments.runner import make_solver

    names = list(names) if names is not None else default_solvers()
    params = params or {}
    insts = {nm: make_solver(nm, params.get(nm)) for nm in names}  # validate all before solving
    ksolve = solver_for(qp)
    runs: list[dict[str, Any]] = []
    sols: dict[str, Solution] = {}
    for nm, inst in insts.items():
        t0 = time.perf_counter()
        rec, sols[nm] = _run_one(qp, nm, inst, ksolve)
        runs.append(rec)
        if progress:
            progress(f"{nm}: {rec['status']} in {time.perf_counter() - t0:.2f} s")
    out: dict[str, Any] = {"problem": qp.name, "ndof": qp.n, "n_defect_nodes": qp.m,
                           "params": jsonable_params(qp.params), "reference": None, "runs": runs}
    ref_name, others = _choose_reference(runs)
    if ref_name is not None:
        out["reference"] = _reference_record(qp, runs, sols, ref_name, others)
    for rec in runs:
        rec["verdict"] = _verdict(rec, out["reference"])
    out["silent_wrong"] = [r["solver"] for r in runs if r["verdict"] == "wrong"]
    return out


def _run_one(qp: QP, nm: str, inst, ksolve) -> tuple[dict[str, Any], Solution]:
    """Solve with one solver; its record (without diff and verdict) and its solution."""
    from dualfem.experiments.runner import run

    sol = run(inst, qp)
    finite = sol.residuals is not None and sol.residuals.get("finite", False)
    rec = {
        "solver": nm,
        "status": str(sol.status),
        "claimed_status": sol.info.get("claimed_status", str(sol.status)),
        "exact": bool(getattr(inst, "exact", True)),
        "tolerance": float(getattr(inst, "tolerance", get_solver(nm).tolerance)),
        "iterations": sol.iterations,
        "energy": sol.residuals["energy"] if finite else None,
        "time_s": {**sol.time_s, "total": sum(v for k, v in sol.time_s.items() if k in ("setup", "solve"))},
        "residuals": evaluator.kkt_residuals(sol.residuals) if finite else None,
        "kkt_error": evaluator.kkt_error(sol.residuals) if finite else None,
        "error_bound": None,
        "certificate": None,
        "n_contact": int(evaluator.contact_set(qp, sol.x).sum()) if finite else None,
        "message": sol.message,
        "params": jsonable_params(sol.params),
        "diff": None,
        "verdict": None,
    }
    if finite:
        cert = sol.info.get("certificate")       # computed by the runner's certification when it got there
        if not isinstance(cert, dict):
            try:
                cert = certified_error(qp, sol.x, sol.multipliers, ksolve)
            except (np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
                cert = {"bound": float("nan"), "active_set": float("nan"), "value": float("nan"),
                        "error": f"{type(exc).__name__}: {exc}"}
        rec["certificate"] = cert
        rec["error_bound"] = 0.0 if reference.exact_zero(qp, sol.x, sol.multipliers) else cert["value"]
    return rec, sol


def _reference_record(qp: QP, runs: list[dict], sols: dict[str, Solution], ref_name: str,
                      others: list[str]) -> dict[str, Any]:
    """Differences of every run to the reference, and the cross-check of the reference."""
    ref = sols[ref_name]
    rrec = next(r for r in runs if r["solver"] == ref_name)
    for rec in runs:
        s = sols[rec["solver"]]
        if rec["energy"] is not None:
            rec["diff"] = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
    out: dict[str, Any] = {
        "solver": ref_name, "error_bound": rrec["error_bound"], "kkt_error": rrec["kkt_error"],
        "why": (f"exact solver with the smallest certified energy-norm error bound "
                f"({rrec['error_bound']:.1e}) among exact solvers claiming success"),
        "cross_check": None,
    }
    # the cross-check is the best certified other exact run whose x is not bit-for-bit the
    # reference's (identical answers come from the same linear algebra, e.g. a backend
    # polished on the same reduced system: they would confirm nothing)
    identical = [nm for nm in others if np.array_equal(sols[nm].x, ref.x)]
    rest = [nm for nm in others if nm not in identical]
    if rest:
        c = next(r for r in runs if r["solver"] == rest[0])
        d = c["diff"]["x_energy"]
        allowed = c["tolerance"] + (rrec["error_bound"] or 0.0) + (c["error_bound"] or 0.0)
        out["cross_check"] = {"solver": rest[0], "identical_to_reference": identical, "x_energy": d,
                              "multipliers": c["diff"]["multipliers"], "allowed": allowed, "agrees": bool(d <= allowed)}
    return out


def _choose_reference(runs: list[dict]) -> tuple[str | None, list[str]]:
    """The one reference policy (:mod:`dualfem.experiments.reference`) applied to the runs made:
    trusted runs (exact, solved, KKT error within the solver's own tolerance, finite certificate)
    ranked by certificate, KKT error, time. Returns (reference, the other trusted runs in order)."""
    ranked = []
    for r in runs:
        ok, _ = reference.trusted(r["status"], r["exact"], r["kkt_error"], r["error_bound"], kkt_max=r["tolerance"])
        if ok:
            ranked.append((reference.rank_key(r["error_bound"], r["kkt_error"], r["time_s"]["total"]), r["solver"]))
    ranked.sort()
    names = [n for _, n in ranked]
    return (names[0] if names else None), names[1:]


_VERDICT = {"correct": "ok", "flagged": "wrong", "silent_wrong": "wrong", "failed": "failed",
            "unverified": "unchecked", "skipped": "skipped", "timeout": "failed", "crashed": "failed"}


def _verdict(rec: dict, ref: dict | None) -> str:
    """compare's word for :func:`dualfem.core.grade.grade` of a run (``reference`` for the reference)."""
    if ref is not None and rec["solver"] == ref["solver"]:
        return "reference"
    if rec["status"] == str(Status.SOLVED) and rec["energy"] is None:
        return "wrong"            # claims success without a finite answer
    row = Row(kind="compare", solver=rec["solver"], status=rec["status"], tol=rec["tolerance"],
              kkt_error=rec["kkt_error"], err_x_energy=(rec["diff"] or {}).get("x_energy") if ref else None,
              ref_bound=ref["error_bound"] if ref else None)
    return _VERDICT[row.regrade()]


# ------------------------------------------------------------------------ printing
def table(result: dict) -> str:
    """The comparison as a fixed-width table for a person."""
    lines = [f"{result['problem']}: {result['ndof']} unknowns, {result['n_defect_nodes']} defect nodes"]
    ref = result["reference"]
    if ref:
        lines.append(f"reference: {ref['solver']} -- {ref['why']}; KKT error {ref['kkt_error']:.1e}")
        cc = ref.get("cross_check")
        if cc:
            lines.append(f"cross-check: {cc['solver']} differs by {cc['x_energy']:.1e} (energy norm), "
                         f"allowed {cc['allowed']:.1e}: {'agrees' if cc['agrees'] else 'DISAGREES'}")
            if cc.get("identical_to_reference"):
                lines.append("  (bit-for-bit identical to the reference, not counted as a cross-check: "
                             + ", ".join(cc["identical_to_reference"]) + ")")
        else:
            lines.append("cross-check: no second exact solver claimed success")
    else:
        lines.append("reference: none (no exact solver claimed success with finite residuals)")
    w = max([10] + [len(r["solver"]) for r in result["runs"]])
    hdr = (f"{'solver':{w}s} {'status':15s} {'verdict':9s} {'iterations':22s} {'setup_s':>8s} {'solve_s':>8s} "
           f"{'energy':>17s} {'kkt':>8s} {'bound':>8s} {'tol':>7s} {'dx_K':>8s} {'dmu':>8s} {'contact':>7s}")
    lines += [hdr, "-" * len(hdr)]
    for r in result["runs"]:
        it = ",".join(f"{k}={v}" for k, v in r["iterations"].items()) or "-"
        d = r["diff"] or {}
        en = f"{r['energy']:17.10e}" if r["energy"] is not None else f"{'-':>17s}"
        cm = "-" if not d else ("same" if d["contact_mismatch"] == 0 else f"{d['contact_mismatch']} off")
        lines.append(f"{r['solver']:{w}s} {r['status']:15s} {r['verdict']:9s} {it[:22]:22s} "
                     f"{r['time_s'].get('setup', 0):8.3f} {r['time_s'].get('solve', 0):8.3f} {en} "
                     f"{_num8(r['kkt_error'])} {_num8(r['error_bound'])} {r['tolerance']:7.0e} "
                     f"{_num8(d.get('x_energy'))} {_num8(d.get('multipliers'))} {cm:>7s}")
    for r in result["runs"]:
        if (r["status"] != "solved" or r["verdict"] == "wrong") and r["message"]:
            msg = r["message"]
            lines.append(f"  {msg}" if msg.startswith(r["solver"]) else f"  {r['solver']}: {msg}")
    lines.append("dx_K: relative energy-norm difference to the reference; dmu: multipliers, relative to "
                 "max(|mu_ref|, |F|); bound: certified relative energy-norm error bound (- where x is infeasible); "
                 "tol: the solver's declared tolerance; contact: contact set vs the reference")
    if result["silent_wrong"]:
        lines.append("SILENT WRONG ANSWER: " + ", ".join(result["silent_wrong"]) +
                     " claim(s) success but are wrong beyond their declared tolerance")
    return "\n".join(lines)


def _num8(v) -> str:
    """A number in the table's 8-character scientific format, '-' when missing."""
    return f"{v:8.1e}" if isinstance(v, (int, float)) and math.isfinite(v) else f"{'-':>8s}"


def stderr_progress() -> Callable[[str], None]:
    """One plain line per finished solver on stderr."""
    return lambda line: print(line, file=sys.stderr, flush=True)
