"""Cross-check several solvers on one QP against a certified reference.

:func:`compare_solvers` runs the chosen (default: every registered and installed) solvers on one
QP, through :func:`dualfem.experiments.runner.run` (so statuses, timings and the evaluator's
independent residuals are the same as for ``dualfem solve``), picks the reference, and grades
each run. Every run is one :class:`~dualfem.experiments.row.Row` (``kind = "compare"``), the
record bench and stress produce too, graded by the one policy :func:`dualfem.verify.grading.grade`
(:meth:`Row.regrade`); the JSON record of a run (:data:`RUN_FIELDS`, the stable interface of
``dualfem compare --json``) is a view of its Row (:func:`record`).

Reference: chosen by the one reference policy (:mod:`dualfem.verify.reference`): among the
runs of the solvers that declare ``reference`` (``Solver.reference``, docs/plugins.md 1.5: a
third-party solver never is one unless it says so) that claim success with an evaluator KKT error
within their own declared tolerance, the one with the smallest a-posteriori energy-norm error certificate
(:func:`dualfem.numerics.certify.certified_error`, computed from the QP alone: the smaller of the
rigorous duality-gap bound on |x - x*|_K / |x|_K and, when the active set is verified with
margins, the first-order size of an exact refinement step on it), ties broken by the KKT error,
then time. The record's ``error_bound`` is that value, ``certificate`` holds both parts. It is
cross-checked against the next best trusted run of any exact solver: their difference must lie within the second
one's declared tolerance plus both bounds. Runs whose x is bit-for-bit the reference's are listed
(``identical_to_reference``) but skipped as cross-checks.

``grade`` of each run (the vocabulary of :mod:`dualfem.verify.grading`, as in bench and stress):
``correct``, ``failed`` (an honest non-success status), ``flagged`` (claims ``solved``, but the
evaluator's residuals exceed its declared tolerance), ``silent_wrong`` (claims ``solved``,
residuals clean, answer off the reference by more than its tolerance + the reference's bound),
``unverified`` (claims ``solved``, no certified reference), ``skipped``. ``flagged`` and
``silent_wrong`` are the wrong ``solved`` claims (listed in ``silent_wrong`` of the result):
the only grades that make ``dualfem compare`` exit non-zero. The reference itself is graded
like any run (``correct``) and named in ``reference``.

Deprecated: ``verdict``, compare's former word for the grade, is kept in every JSON record as
an alias derived from ``grade`` (:data:`VERDICT_OF_GRADE`; ``reference`` for the reference):
``ok`` = correct, ``wrong`` = flagged or silent_wrong, ``failed`` = failed/timeout/crashed,
``unchecked`` = unverified, ``skipped`` = skipped. Read ``grade``.
"""
from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.registry import get_solver
from dualfem.core.registry import solvers as registered
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import reference_solvers
from dualfem.experiments.row import Row
from dualfem.experiments.runner import jsonable_params
from dualfem.verify import Answer, against, certified_error, solver_for
from dualfem.verify.reference import Candidate, choose, exact_zero

#: fields of each run record (stable JSON interface of ``dualfem compare --json``; ``verdict`` is a
#: deprecated alias of ``grade``)
RUN_FIELDS = ("solver", "status", "grade", "verdict", "exact", "tolerance", "iterations", "energy", "time_s",
              "residuals", "kkt_error", "error_bound", "certificate", "diff", "n_contact", "message", "params",
              "err_x_energy", "err_multipliers", "grade_x", "grade_mu", "cert_x", "cert_mu")
#: the deprecated ``verdict`` of each grade (see the module docstring)
VERDICT_OF_GRADE = {"correct": "ok", "flagged": "wrong", "silent_wrong": "wrong", "failed": "failed",
                    "unverified": "unchecked", "skipped": "skipped", "timeout": "failed", "crashed": "failed"}
#: grades of a wrong ``solved`` claim: exit status 1
WRONG = ("flagged", "silent_wrong")


class Comparison(dict):
    """The result of :func:`compare_solvers`: the JSON record (a dict, see the module docstring),
    and the graded :class:`Row` of every run in :attr:`rows` (the same order as ``runs``)."""

    rows: list[Row]


def default_solvers() -> list[str]:
    """Every registered solver, in name order (missing dependencies show up as ``skipped``)."""
    return sorted(registered())


def compare_solvers(qp: QP, names: list[str] | None = None, params: dict[str, dict] | None = None,
                    progress: Callable[[str], None] | None = None, tol: float | None = None, *,
                    done: dict[str, tuple[Row, Solution]] | None = None,
                    before_run: Callable[[str, Any], None] | None = None,
                    after_run: Callable[[str, Row, Solution], None] | None = None,
                    stages: Callable[[str, float], None] | None = None) -> Comparison:
    """Run ``names`` on ``qp``; return the comparison (see module docstring).

    ``params`` maps a solver name to its parameters. ``progress`` receives one line per finished
    solver. ``tol``: the certified tolerance of every run (``--tol``, :mod:`dualfem.experiments.tolerance`:
    each solver's ``tolerance_params(tol)`` under its ``params``); None: each solver's declared tolerance.
    ``done``: (row, solution) of solvers already run (e.g. by an earlier worker process of
    :mod:`dualfem.cli.launch`, or killed there at their time limit): they are not run again.
    ``before_run(name, solver)`` and ``after_run(name, row, solution)`` are called around each run,
    ``stages(stage, seconds)`` as each stage of a run (setup, solve, certification) finishes.
    """
    from dualfem.experiments.runner import make_solver
    from dualfem.experiments.tolerance import with_tolerance

    if qp.n == 0:       # nothing to solve or cross-check (m = 0, no constraint, is an ordinary QP)
        raise InputError(f"compare needs a QP with at least one unknown; {qp.name!r} has n = 0")
    names = list(names) if names is not None else default_solvers()
    params = params or {}
    insts = {nm: make_solver(nm, with_tolerance(get_solver(nm), tol, params.get(nm))) for nm in names}
    ksolve = solver_for(qp)
    rows: list[Row] = []
    sols: dict[str, Solution] = {}
    for nm, inst in insts.items():
        if done and nm in done:
            row, sols[nm] = done[nm]
            rows.append(row)
            continue
        if before_run is not None:
            before_run(nm, inst)
        t0 = time.perf_counter()
        row, sols[nm] = _run_one(qp, nm, inst, ksolve, tol, params.get(nm), stages)
        if sols[nm].info.get("qp_changed"):     # the runner's fingerprint: every later run would be void
            raise InputError(f"{sols[nm].message}; the comparison is stopped")
        rows.append(row)
        if after_run is not None:
            after_run(nm, row, sols[nm])
        if progress:
            progress(f"{nm}: {row.status} in {time.perf_counter() - t0:.2f} s")
    out = Comparison({"problem": qp.name, "ndof": qp.n, "n_defect_nodes": qp.m,
                      "params": jsonable_params(qp.params), "reference": None})
    ref_name, others = _choose_reference(rows)
    if ref_name is not None:
        out["reference"] = _reference_record(qp, rows, sols, ref_name, others)
    for row in rows:
        row.regrade()
    out.rows = rows
    out["runs"] = [record(r, out["reference"]) for r in rows]
    out["silent_wrong"] = [r.solver for r in rows if r.grade in WRONG]
    return out


def _run_one(qp: QP, nm: str, inst, ksolve, asked: float | None = None, given: dict | None = None,
             stages: Callable[[str, float], None] | None = None) -> tuple[Row, Solution]:
    """Solve with one solver; its row (not yet graded, no difference to a reference) and its solution."""
    from dualfem.experiments.runner import run
    from dualfem.experiments.tolerance import explain

    sol = run(inst, qp, progress=stages, tol=asked)   # a read-only view; checks qp's fingerprint afterwards
    why = explain(sol, given, asked)
    if why:
        sol.message = f"{sol.message}; {why}" if sol.message else why
    finite = sol.residuals is not None and sol.residuals.get("finite", False)
    declared = sol.info.get("declared") or {}     # what the runner read and checked, not what the plugin says now
    tol = asked if asked is not None else float(declared.get("tolerance", get_solver(nm).tolerance))
    row = Row(kind="compare", run_id=f"compare:{nm}", scene=qp.name, n_unknowns=qp.n, n_constraints=qp.m,
              solver=nm, variant=nm, solver_params=jsonable_params(sol.params), tol=tol, status=str(sol.status),
              claimed_status=sol.info.get("claimed_status", str(sol.status)), message=sol.message,
              iterations=dict(sol.iterations), setup_s=sol.time_s.get("setup"), solve_s=sol.time_s.get("solve"),
              total_s=sum(v for k, v in sol.time_s.items() if k in ("setup", "solve")),
              exact=bool(declared.get("exact", get_solver(nm).exact)), third_party=bool(get_solver(nm).requires))
    row.set_residuals(sol.residuals if finite else None, tol)
    if not finite and str(sol.status) == str(Status.SOLVED):
        row.kkt_error = float("inf")      # claims success without a finite answer: the evaluator flags it
    row.update(energy=sol.residuals.get("objective", sol.residuals["energy"]) if finite else None,
               time_s={**sol.time_s, "total": row.total_s}, error_bound=None, certificate=None, diff=None,
               n_contact=int(evaluator.contact_set(qp, sol.x).sum()) if finite else None)
    if finite:
        cert = sol.info.get("certificate")       # computed by the runner's certification when it got there
        if not isinstance(cert, dict):
            try:
                cert = certified_error(qp, sol.x, sol.multipliers, ksolve)
            except (np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
                cert = {"bound": float("nan"), "active_set": float("nan"), "value": float("nan"),
                        "error": f"{type(exc).__name__}: {exc}"}
        row["certificate"] = cert
        row.set_certificate(cert)
        row["error_bound"] = 0.0 if exact_zero(qp, sol.x, sol.multipliers) else cert["value"]
    return row, sol


def record(row: Row, ref: dict | None = None) -> dict[str, Any]:
    """The JSON record of one compare run (:data:`RUN_FIELDS`), a view of its graded Row."""
    finite = row.get("energy") is not None
    verdict = "reference" if ref is not None and row.solver == ref["solver"] else VERDICT_OF_GRADE[row.grade]
    return {
        "solver": row.solver, "status": row.status, "claimed_status": row.claimed_status, "grade": row.grade,
        "verdict": verdict, "exact": row.exact, "tolerance": row.tol, "iterations": row.iterations,
        "energy": row.get("energy"), "time_s": row.get("time_s"),
        "residuals": {k: row[k] for k in evaluator.RESIDUALS} if finite else None,
        "kkt_error": row.kkt_error if finite else None, "error_bound": row.get("error_bound"),
        "certificate": row.get("certificate"), "n_contact": row.get("n_contact"), "message": row.message,
        "params": row.solver_params, "diff": row.get("diff"),
        # errors against the reference (None without one): x in the energy norm, the multipliers
        # |mu - mu_ref|_inf / max(|mu_ref|_inf, |F|_inf)
        "err_x_energy": row.err_x_energy, "err_multipliers": row.err_multipliers,
        # graded apart (dualfem.verify.grading): the displacements, the multipliers, and their certificates
        "grade_x": row.grade_x, "grade_mu": row.grade_mu, "cert_x": row.cert_x, "cert_mu": row.cert_mu,
    }


def _reference_record(qp: QP, rows: list[Row], sols: dict[str, Solution], ref_name: str,
                      others: list[str]) -> dict[str, Any]:
    """Differences of every run to the reference (into its row), and the cross-check of the reference."""
    ref = sols[ref_name]
    rrow = next(r for r in rows if r.solver == ref_name)
    answer = Answer(ref_name, ref.x, ref.multipliers, rrow["error_bound"])   # type: ignore[arg-type]
    for row in rows:
        # the one judge: measured against the reference and graded (dualfem.verify.judge)
        v = against(row.facts(), qp, sols[row.solver], answer, measurable=row.get("energy") is not None)
        row.take(v)
        if v.diff is not None:
            row["diff"] = v.diff
        row.update(ref_solver=ref_name, ref_kkt=rrow.kkt_error, ref_bound=rrow["error_bound"])
    out: dict[str, Any] = {
        "solver": ref_name, "error_bound": rrow["error_bound"], "kkt_error": rrow.kkt_error,
        "why": (f"reference solver with the smallest certified energy-norm error bound "
                f"({rrow['error_bound']:.1e}) among the solvers declaring reference that claim success"),
        "cross_check": None,
    }
    # the cross-check is the best certified other exact run whose x is not bit-for-bit the
    # reference's (identical answers come from the same linear algebra, e.g. a backend
    # polished on the same reduced system: they would confirm nothing)
    identical = [nm for nm in others if np.array_equal(sols[nm].x, ref.x)]
    rest = [nm for nm in others if nm not in identical]
    if rest:
        c = next(r for r in rows if r.solver == rest[0])
        d = c.err_x_energy
        allowed = c.tol + (rrow["error_bound"] or 0.0) + (c["error_bound"] or 0.0)
        out["cross_check"] = {"solver": rest[0], "identical_to_reference": identical, "x_energy": d,
                              "multipliers": c.err_multipliers, "allowed": allowed, "agrees": bool(d <= allowed)}
    return out


def _choose_reference(rows: list[Row]) -> tuple[str | None, list[str]]:
    """The one reference policy (:func:`dualfem.verify.reference.choose`) applied to the runs made, each
    trusted at most at its own tolerance (KKT error within it, finite certificate). Returns (reference or
    None, the other trusted runs in order)."""
    return choose(Candidate(r.solver or "", str(r.status), bool(r.exact), r.kkt_error, r.get("error_bound"),
                            r.total_s, kkt_max=r.tol) for r in rows)  # type: ignore[arg-type]


def grade_record(rec: dict, ref: dict | None) -> str:
    """The grade of a compare JSON record (``status``, ``tolerance``, ``kkt_error``, ``energy``,
    ``diff``) against a reference record (``solver``, ``error_bound``) or None: the one policy."""
    solved_without_answer = rec["status"] == str(Status.SOLVED) and rec.get("energy") is None
    row = Row(kind="compare", solver=rec["solver"], status=rec["status"], tol=rec["tolerance"],
              kkt_error=float("inf") if solved_without_answer else rec["kkt_error"],
              err_x_energy=(rec.get("diff") or {}).get("x_energy") if ref else None,
              ref_bound=ref["error_bound"] if ref else None)
    return row.regrade()


# ------------------------------------------------------------------------ printing
#: the widest line of :func:`table` (characters), the legend and messages wrapped to it
TABLE_WIDTH = 100


def _scene_title(result: dict, scene: str | None) -> str:
    """The table's first line: the scene as the user named it (else the QP's name) and its size."""
    from pathlib import Path

    name = result["problem"]
    if scene:
        name = Path(scene).stem if scene.endswith((".toml", ".npz", ".mat")) else scene
    return f"{name}: {result['ndof']} unknowns, {result['n_defect_nodes']} defect nodes"


def _iters(it: dict) -> str:
    """The iteration count of a run: its first counter (the outer one), '-' when none."""
    for v in it.values():
        return str(v)
    return "-"


def table(result: dict, scene: str | None = None) -> str:
    """The comparison as a fixed-width table for a person, at most :data:`TABLE_WIDTH` characters wide
    while solver names have at most 16 (every number is in ``--json``): one row per solver that ran; the
    skipped ones (not installed, not applicable) summarised in one line. ``scene``: the scene as the
    user named it (a preset, a library name or a scene file), shown instead of the QP's internal name."""
    import textwrap

    wrap = textwrap.TextWrapper(width=TABLE_WIDTH, subsequent_indent="    ", break_on_hyphens=False)
    lines = [_scene_title(result, scene)]
    ref = result["reference"]
    if ref:
        lines += wrap.wrap(f"reference: {ref['solver']} -- {ref['why']}; KKT error {ref['kkt_error']:.1e}")
        cc = ref.get("cross_check")
        if cc:
            lines.append(f"cross-check: {cc['solver']} differs by {cc['x_energy']:.1e} (energy norm), "
                         f"allowed {cc['allowed']:.1e}: {'agrees' if cc['agrees'] else 'DISAGREES'}")
            if cc.get("identical_to_reference"):
                lines += wrap.wrap("  (bit-for-bit identical to the reference, not counted as a cross-check: "
                                   + ", ".join(cc["identical_to_reference"]) + ")")
        else:
            lines.append("cross-check: no second exact solver claimed success")
    else:
        declared = ", ".join(n for n, _ in reference_solvers()) or "none registered"
        lines.append(f"reference: none (no solver declaring reference claimed success with finite residuals; "
                     f"reference solvers: {declared})")
    ran = [r for r in result["runs"] if r["status"] != "skipped"]
    skipped = [r for r in result["runs"] if r["status"] == "skipped"]
    w = max([6] + [len(r["solver"]) for r in ran])
    hdr = (f"{'solver':{w}s} {'status':10s} {'grade':12s} {'iters':>5s} {'time_s':>7s} {'kkt':>7s} {'bound':>7s} "
           f"{'tol':>5s} {'dx_K':>7s} {'dmu':>7s} {'contact':>7s}")
    lines += [hdr, "-" * len(hdr)]
    for r in ran:
        d = r["diff"] or {}
        cm = "-" if not d else ("same" if d["contact_mismatch"] == 0 else f"{d['contact_mismatch']} off")
        ts = r["time_s"]
        t = ts["setup"] + ts["solve"] if isinstance(ts.get("setup"), (int, float)) and \
            isinstance(ts.get("solve"), (int, float)) else None
        lines.append(f"{r['solver']:{w}s} {r['status']:10s} {r['grade']:12s} {_iters(r['iterations']):>5s} "
                     f"{_sec7(t)} {_num7(r['kkt_error'])} {_num7(r['error_bound'])} {r['tolerance']:5.0e} "
                     f"{_num7(d.get('x_energy'))} {_num7(d.get('multipliers'))} {cm:>7s}")
    for r in ran:
        if (r["status"] != "solved" or r["grade"] in WRONG) and r["message"]:
            msg = r["message"] if r["message"].startswith(r["solver"]) else f"{r['solver']}: {r['message']}"
            lines += wrap.wrap("  " + msg)
    if skipped:
        lines += wrap.wrap(f"not run ({len(skipped)}): " + ", ".join(r["solver"] for r in skipped)
                           + " (not installed or not applicable; `dualfem list` says what each needs)")
    lines += wrap.wrap("time_s: setup + solve; iters: the solver's outer iterations; dx_K: relative energy-norm "
                       "difference to the reference; dmu: multipliers, relative to max(|mu_ref|, |F|); bound: "
                       "certified relative energy-norm error bound (- where x is infeasible); tol: the certified "
                       "tolerance (--tol, else the solver's declared one); contact: contact set vs the reference; "
                       "grade: dualfem.verify.grading; "
                       "energies, every iteration counter and the skipped solvers' reasons: --json")
    if result["silent_wrong"]:
        lines.append("SILENT WRONG ANSWER: " + ", ".join(result["silent_wrong"]) +
                     " claim(s) success but are wrong beyond their declared tolerance")
    return "\n".join(lines)


def _num7(v) -> str:
    """A number in the table's 7-character scientific format, '-' when missing."""
    return f"{v:7.1e}" if isinstance(v, (int, float)) and math.isfinite(v) else f"{'-':>7s}"


def _sec7(v) -> str:
    """Seconds in the table's 7-character format, '-' when there are none (a run killed by the watchdog)."""
    return f"{v:7.3f}" if isinstance(v, (int, float)) and math.isfinite(v) else f"{'-':>7s}"


def stderr_progress() -> Callable[[str], None]:
    """One plain line per finished solver on stderr."""
    return lambda line: print(line, file=sys.stderr, flush=True)
