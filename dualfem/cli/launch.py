"""``dualfem solve`` and ``dualfem compare`` under the watchdog (:mod:`dualfem.experiments.watchdog`).

The QP is built in the worker process (a problem plugin's build is plugin code too, and nothing
large crosses the pipe), then solved and certified there. The phases that run plugin code
(``build`` and ``setup and solve`` of solve; ``run NAME`` of compare) get the budget
``time_limit * 1.5 + 10`` s (:func:`dualfem.experiments.watchdog.budget`) of the solver's own
``time_limit`` parameter (its default unless ``-p time_limit=...`` sets it; 600 s for a solver
without one); the phases of dualfem's own code after a solver returned (``certification``,
``output``; ``certify NAME``, ``reference and grades``) get :func:`own_budget`, at least that of
600 s (a short solver time limit never throws away an answer returned in time); compare's ``build``
takes the largest of the compared solvers' limits. A phase that runs past its budget ends the worker:

* ``solve``: the record has ``status`` ``time_limit`` (``crashed`` if the worker died) and a
  ``message`` naming the phase and its budget (exit status 1);
* ``compare``: the killed solver's run is a ``time_limit`` (or ``crashed``) row, graded ``failed``
  like any honest non-success; a new worker builds the QP again and goes on with the next solver (the runs made
  so far are kept). A killed build or grading phase ends the command with one line (exit status 1).
"""
from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

from dualfem.experiments.watchdog import (
    DEFAULT_TIME_LIMIT,
    Guard,
    Outcome,
    budget,
    guarded_call,
    limit_text,
    time_limit_of,
)


def own_budget(limit: float) -> float:
    """Budget of a phase of dualfem's own code (certification, output, grading): that of ``limit`` but at
    least that of DEFAULT_TIME_LIMIT, so that a short solver time limit never throws away an answer the
    solver returned in time."""
    return budget(max(limit, DEFAULT_TIME_LIMIT))


# ------------------------------------------------------------------------------ solve
def solve_guarded(args: Any, solver: Any, stages: Callable[[str, float], None], tol: float | None = None,
                  given: dict | None = None) -> tuple[dict, bool]:
    """(JSON record, solved?) of ``dualfem solve`` with the validated ``args`` and ``solver``; ``tol``: the
    certified tolerance of ``--tol`` (None: the solver's declared one), ``given``: the user's own solver
    parameters (to explain a mismatch between the solver's stop rule and the certified tolerance)."""
    limit = time_limit_of(solver)
    out = guarded_call(_solve_work, args, solver, limit, stages, tol, given, phase="build", seconds=budget(limit))
    if out.status == "done":
        return out.value
    return _killed_record(args, solver, out, limit), False


def _solve_work(guard: Guard, args: Any, solver: Any, limit: float, stages: Callable[[str, float], None],
                tol: float | None, given: dict | None) -> tuple[dict, bool]:  # pragma: no cover - in the worker
    from dualfem.cli.main import peak_rss_mb, scene_from_args
    from dualfem.core.scene import build_qp
    from dualfem.core.solution import Status
    from dualfem.experiments.runner import run, summary
    from dualfem.experiments.tolerance import explain
    from dualfem.numerics.factor import missing_fast_backend_hint

    t0 = time.perf_counter()
    problem = scene_from_args(args)
    t1 = time.perf_counter()
    qp = build_qp(problem)           # contained: a problem plugin's prints, exceptions, a non-QP
    t2 = time.perf_counter()
    guard.send({"problem": qp.name, "ndof": qp.n, "n_defect_nodes": qp.m})
    if args.figure:
        from dualfem.post.solution_figure import check_figure_qp

        check_figure_qp(qp)          # before the solve and before --vtk is written
    stages("assembly (mesh, matrices)", t2 - t1)
    hint = missing_fast_backend_hint(qp.n)
    if hint and not args.quiet:
        print(f"dualfem solve: note: {hint}", file=sys.stderr)

    def tick(stage: str, seconds: float) -> None:
        stages(stage, seconds)
        if stage.startswith("solve"):
            guard.phase("certification", own_budget(limit))

    guard.phase("setup and solve", budget(limit))
    sol = run(solver, qp, progress=tick, tol=tol)
    why = explain(sol, given, tol)
    if why:
        sol.message = f"{sol.message}; {why}" if sol.message else why
    guard.phase("output", own_budget(limit))
    rec = summary(qp, sol)
    rec["time_s"] = {**rec["time_s"], "assembly": t2 - t1, "total": time.perf_counter() - t0}
    rec["peak_rss_mb"] = peak_rss_mb()
    sif = None
    if getattr(args, "sif", False):   # stress intensity factors at the tips / fronts (dualfem.post.sif), on request
        from dualfem.post.sif_outputs import sif_result

        guard.phase("stress intensity factors", own_budget(limit))
        sif, record = sif_result(qp, sol)
        if record is not None:
            rec["sif"] = record
    _outputs(args, problem, qp, sol, rec, sif)
    return rec, sol.status == Status.SOLVED


def _outputs(args: Any, problem: Any, qp: Any, sol: Any, rec: dict, sif: Any = None) -> None:  # pragma: no cover
    """The ``_post`` hook, ``--vtk``/``--xdmf`` (with ``sif``, the factors ``--sif`` computed) and ``--figure`` of
    ``dualfem solve`` (in the worker)."""
    post = getattr(args, "_post", None)
    if post:
        post(problem, qp, sol, rec)
    if args.vtk or args.xdmf:
        from dualfem.post.vtk import write_outputs

        if sol.x is None:
            print(f"dualfem solve: no solution ({sol.status}): --vtk/--xdmf not written", file=sys.stderr)
        else:
            for path in write_outputs(qp, sol, vtk=args.vtk, xdmf=args.xdmf, sif=sif):
                print(f"wrote {path}", file=sys.stderr)
    if args.figure and sol.x is not None:
        from dualfem.post.solution_figure import write_solution_figure

        for path in write_solution_figure(args.figure, qp, sol):
            print(f"wrote {path}", file=sys.stderr)


def _killed_record(args: Any, solver: Any, out: Outcome, limit: float) -> dict:
    """The record of a solve whose worker was killed by the watchdog (or died)."""
    from dualfem.experiments.runner import _name, _params, jsonable_params

    meta = out.parts[0] if out.parts else {}
    msg = limit_text(out.phase, out.budget, limit) if out.status == "time_limit" else out.message
    return {"solver": _name(solver), "status": out.status, "claimed_status": None, "message": msg,
            "problem": meta.get("problem", str(args.scene)), "ndof": meta.get("ndof"),
            "n_defect_nodes": meta.get("n_defect_nodes"), "iterations": {}, "time_s": {"total": out.elapsed},
            "params": jsonable_params(_params(solver)), "counters": {}, "energy": None, "max_jump": None,
            "n_contact": None, "residuals": None, "killed_in_phase": out.phase}


# ---------------------------------------------------------------------------- compare
def compare_guarded(args: Any, names: list[str], params: dict[str, dict],
                    progress: Callable[[str], None] | None = None,
                    tol: float | None = None) -> tuple[dict | None, str | None]:
    """(the comparison of :func:`dualfem.experiments.compare.compare_solvers`, None), or (None, why)
    when a shared phase (build, reference and grades) was killed; a killed solver is a row."""
    from dualfem.experiments.runner import make_solver

    limits = {nm: time_limit_of(make_solver(nm, params.get(nm))) for nm in names}
    longest = max(limits.values(), default=DEFAULT_TIME_LIMIT)
    shared = own_budget(longest)
    done: dict[str, tuple[Any, Any]] = {}
    meta: dict[str, Any] = {}

    def keep(part: Any) -> None:
        if part[0] == "meta":
            meta.update(part[1])
        else:
            done[part[1]] = (part[2], part[3])

    while True:
        out = guarded_call(_compare_work, args, names, params, dict(done), limits, shared, tol, phase="build",
                           seconds=budget(longest), on_part=keep)
        if out.status == "done":
            return out.value, None
        nm = out.phase.split(" ", 1)[1] if out.phase.startswith(("run ", "certify ")) else None
        if nm not in limits or nm in done:
            why = limit_text(out.phase, out.budget, longest) if out.status == "time_limit" else out.message
            return None, why
        done[nm] = _killed_run(nm, out, limits[nm], meta, params.get(nm), tol)
        if progress:
            progress(f"{nm}: {out.status} after {out.elapsed:.2f} s (killed in phase '{out.phase}')")


def _compare_work(guard: Guard, args: Any, names: list[str], params: dict, done: dict, limits: dict,
                  shared: float, tol: float | None) -> Any:  # pragma: no cover - in the worker
    from dualfem.cli.main import scene_from_args
    from dualfem.core.quiet import c_stdout_to_stderr
    from dualfem.core.scene import build_qp
    from dualfem.experiments.compare import compare_solvers, stderr_progress

    def before(nm: str, inst: Any) -> None:
        guard.phase(f"run {nm}", budget(limits[nm]))
        current[0] = nm

    def tick(stage: str, seconds: float) -> None:
        if stage.startswith("solve"):             # the plugin returned: dualfem's own certification
            guard.phase(f"certify {current[0]}", own_budget(limits[current[0]]))

    current = [""]

    def after(nm: str, row: Any, sol: Any) -> None:
        guard.send(("run", nm, row, _sendable(sol)))
        guard.phase("reference and grades", shared)

    with c_stdout_to_stderr():
        qp = build_qp(scene_from_args(args))
        guard.send(("meta", {"scene": qp.name, "n_unknowns": qp.n, "n_constraints": qp.m}))
        return compare_solvers(qp, names, params, progress=stderr_progress(), tol=tol, done=done, before_run=before,
                               after_run=after, stages=tick)


def _sendable(sol: Any) -> Any:
    """The solution with only plain values in ``info`` (what crosses the pipe)."""
    import copy

    out = copy.copy(sol)
    out.info = {k: v for k, v in sol.info.items() if isinstance(v, (str, int, float, bool, dict, list, type(None)))}
    return out


def _killed_run(nm: str, out: Outcome, limit: float, meta: dict, params: dict | None,
                tol: float | None = None) -> tuple[Any, Any]:
    """(row, solution) of a compare run whose worker was killed at its budget (or died); ``tol``: the
    certified tolerance of ``--tol`` (None: the solver's declared one), as for the runs that finished."""
    from dualfem.core.registry import get_solver
    from dualfem.core.solution import Solution, Status
    from dualfem.experiments.row import Row

    cls = get_solver(nm)
    msg = limit_text(out.phase, out.budget, limit) if out.status == "time_limit" else out.message
    status = Status.TIME_LIMIT if out.status == "time_limit" else Status.ERROR
    row = Row(kind="compare", run_id=f"compare:{nm}", scene=meta.get("scene"), n_unknowns=meta.get("n_unknowns"),
              n_constraints=meta.get("n_constraints"), solver=nm, variant=nm, solver_params=dict(params or {}),
              tol=float(cls.tolerance if tol is None else tol), status=out.status, claimed_status=None, message=msg,
              iterations={}, total_s=None, exact=bool(cls.exact), third_party=bool(cls.requires))
    row.set_residuals(None, row.tol)
    row.update(energy=None, time_s={"killed_after": out.elapsed}, error_bound=None, certificate=None, diff=None,
               n_contact=None)
    return row, Solution(solver=nm, status=status, message=msg)
