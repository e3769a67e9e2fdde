"""Run a solver on a QP: time setup and solve separately, attach independent residuals, certify.

``run`` never lets a solver fail silently: a missing dependency or a skip reason becomes
``Status.SKIPPED`` with the reason, an exception inside the solver becomes ``Status.ERROR`` with
its message, and the residuals always come from :mod:`dualfem.core.evaluator`.

**Certification** (:func:`certify_status`), for every plugin: a ``solved`` claim stands only if
the evaluator's scale-free KKT residuals, recomputed from (x, mu) and the QP (the stationarity
residual beyond its measured rounding floor, :data:`dualfem.core.evaluator.ROUNDING_C`; for a shifted
QP in the QP's own and in the user's unknowns, :mod:`dualfem.core.evaluator`), are within the
tolerance the solver instance declares, and the a-posteriori energy-norm error certificate
(:func:`dualfem.numerics.certify.certified_error`) is too where it applies, and so is the certified
error of the multipliers (against the exact multipliers of the verified active set: the contact forces
are certified, not only x). Residuals bound the error only through the conditioning of K: a soft mode
(an eigenvector of K's smallest eigenvalue) added to x* changes the residuals little and x much, so
the error itself is bounded, for exact and inexact solvers alike (an inexact solver's ``tolerance`` is
the promised energy-norm error of x against the QP's solution x*, its modelling error included). An
inexact solver's answer is usually infeasible (a penalty solution penetrates): its error is bounded by
:func:`dualfem.numerics.certify.infeasible_bound` or the exact step onto its verified active set; a
``solved`` claim of an inexact solver for which no error bound applies is not certified.
Otherwise the status becomes ``inaccurate`` with a message naming the residual and by how much;
the plugin's own claim stays in ``Solution.info["claimed_status"]``.
"""
from __future__ import annotations

import copy
import dataclasses
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from dualfem.core import evaluator
from dualfem.core.errors import InputError, describe_exception
from dualfem.core.qp import QP, Maps
from dualfem.core.quiet import plugin_output
from dualfem.core.registry import builtin_names, get_solver
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver, check_declared, unhandled_law

#: ``Solution.info`` keys that belong to the runner: whatever a plugin puts there is dropped
#: the work counters a solver may report in Solution.info, copied to the JSON record's ``counters``
COUNTERS = ("operator", "applications", "solves", "factorizations", "face_solves", "cg_iterations")
RUNNER_INFO = ("claimed_status", "certified_tol", "certificate", "declared", "qp_changed")


def make_solver(name: str, params: dict[str, Any] | None = None) -> Solver:
    """Instantiate the registered solver ``name`` with ``params`` (validated).

    A third-party plugin's ``__init__`` runs with its stdout contained (:func:`plugin_output`); any
    exception of it other than InputError (even SystemExit) becomes an InputError naming the plugin."""
    cls = get_solver(name)
    with plugin_output():
        if name in builtin_names("solver"):
            return cls(**(params or {}))
        try:
            return cls(**(params or {}))
        except InputError:
            raise
        except BaseException as exc:  # noqa: BLE001 - a plugin's bug, whatever it raises
            if type(exc) is KeyboardInterrupt:     # a real Ctrl-C (exactly this class) still stops
                raise
            raise InputError(f"solver plugin {name!r} ({cls.__module__}.{cls.__qualname__}) could not be created: "
                             f"{describe_exception(exc)}") from None


def missing_reason(solver: Solver) -> str | None:
    """``solver.missing()`` (an install hint, or None), contained: its prints go to stderr, and if the
    plugin's ``missing`` raises (anything but a real Ctrl-C), the reason says so."""
    with plugin_output():
        try:
            reason = solver.missing()
        except BaseException as exc:  # noqa: BLE001 - a plugin's bug
            if type(exc) is KeyboardInterrupt:
                raise
            return f"solver plugin {_name(solver)!r}: missing() raised {describe_exception(exc)}"
    return None if reason is None else str(reason)


def run(solver: Solver | str, qp: QP, params: dict[str, Any] | None = None, *, tol: float | None = None,
        progress: Callable[[str, float], None] | None = None, monitor: Any = None,
        grades: str | None = None) -> Solution:
    """Solve ``qp`` with ``solver`` (an instance, or a registry name plus ``params``).

    ``tol``: the relative accuracy asked for (e.g. a benchmark tier, with the parameters of
    ``Solver.tolerance_params(tol)``); the answer is then certified to ``tol`` itself (a `solved` at a
    benchmark tier means that tier's accuracy, whatever the solver declares by default).
    Without it, to the tolerance the solver declares. ``progress(stage, seconds)`` is called as
    each stage (setup, solve, certify) finishes. ``monitor``: an iterate monitor
    (:class:`dualfem.experiments.curves.IterateMonitor`) attached to the solver for ``solve()`` only
    (:meth:`dualfem.core.solver.Solver.report_iterate`); the time spent in it is not counted in the
    solve time, and the answer returned becomes its last sample. ``grades``: what ``tol`` certifies
    (:data:`dualfem.verify.grading.GRADED`): ``"x"`` leaves the multipliers' certificate out of the status
    (it is still computed and reported), None or ``"x,mu"`` certifies both.

    Nothing the plugin says about itself is trusted (docs/plugins.md, sections 1.1-1.3):

    * its declared ``tolerance`` (a finite number in (0, 1)) and ``exact`` are checked before
      ``setup`` (InputError) and read once: a plugin that changes them during the run is an ``error``;
    * the QP it gets is a read-only view of ``qp`` (:func:`guarded_view`: every array read-only,
      attribute changes stay on the view), and ``qp``'s :func:`fingerprint` is compared after the run:
      a changed QP makes the run an ``error`` (``info["qp_changed"]`` names the parts);
    * any exception it raises, SystemExit and other BaseExceptions included (not KeyboardInterrupt:
      Ctrl-C still stops), makes the run an ``error`` with the message; its prints go to stderr;
    * what ``solve()`` returns is checked (:func:`_checked_solution`): not a Solution, an unknown
      status, x or multipliers of the wrong shape or not real numbers give an ``error``; NaN or inf
      is never ``solved``; residuals, certificates and the claimed status are the runner's own.
    """
    tick = progress or (lambda stage, seconds: None)
    if isinstance(solver, str):
        solver = make_solver(solver, params)
    name = _name(solver)
    before = fingerprint(qp)
    att = _attempt(solver, guarded_view(qp), qp, tick, monitor)
    after = fingerprint(qp)            # whatever happened: did the plugin write into the caller's QP?
    changed = [k for k in before if after.get(k) != before[k]]
    if changed:
        att.why, att.status = (f"solver {name!r} changed the QP it was given ({', '.join(changed)}): its answer "
                               f"is discarded, and any later run on this QP is unreliable"), Status.ERROR
    sol, problem = _checked_solution(att.returned, qp, name) if att.why is None else (None, None)
    if sol is None or problem:
        out = Solution(solver=name, status=att.status, message=att.why or problem or "", params=_params(solver),
                       time_s={"setup": att.setup_s, "solve": att.solve_s})
        out.info["claimed_status"] = str(att.status)
        if isinstance(att.returned, Solution) and str(getattr(att.returned, "status", "")) in set(map(str, Status)):
            out.info["claimed_status"] = str(att.returned.status)
        if changed:
            out.info["qp_changed"] = changed
        return out
    sol.time_s = {"setup": att.setup_s, "solve": att.solve_s, **sol.time_s}
    if monitor is not None:
        monitor.finish(sol.x, sol.multipliers, att.solve_s)
    sol.params = _params(solver)
    sol.info["declared"] = {"tolerance": att.declared[0], "exact": att.declared[1]}
    return _certified(qp, sol, att, tol, tick, grades != "x")


@dataclass
class _Attempt:
    """What the guarded calls of one run gave: the plugin's return value, or why there is none."""

    returned: Any = None
    why: str | None = None
    status: Status = Status.ERROR
    declared: tuple[float, bool] = (float("nan"), True)
    setup_s: float = 0.0
    solve_s: float = 0.0
    reduction: Any = None


def _attempt(solver: Solver, view: QP, qp: QP, tick: Callable[[str, float], None], monitor: Any = None) -> _Attempt:
    """check_params, the declared tolerance, missing/skip, setup and solve, contained (see :func:`run`);
    ``monitor`` is attached for ``solve()`` only, and its time taken out of ``solve_s``."""
    att = _Attempt()
    spent = (lambda: monitor.overhead) if monitor is not None else (lambda: 0.0)
    name = _name(solver)
    # a built-in wrapper's library banners (HiGHS, OSQP) are dropped unless --verbose; a plugin's output is kept
    with plugin_output(drop_c_output=name in builtin_names("solver")):
        t0 = t1 = time.perf_counter()
        try:
            solver.check_params()      # again: a plugin may override __init__ or change params after it
            att.declared = check_declared(solver)  # tolerance in (0, 1), exact a bool (InputError otherwise)
            reason = solver.missing() or unhandled_law(solver, view) or solver.skip(view)
            if reason:
                att.why, att.status = str(reason), Status.SKIPPED
            else:
                t0 = time.perf_counter()
                solver.setup(view)
                t1 = time.perf_counter()
                att.setup_s = t1 - t0
                tick("setup (factorization)", att.setup_s)
                attached = _attach(solver, monitor, t1, att.setup_s)
                try:
                    att.returned = solver.solve()
                finally:
                    if attached:
                        _attach(solver, None, t1, 0.0)
                att.solve_s = time.perf_counter() - t1 - spent()
                tick("solve (iterations)", att.solve_s)
        except InputError:
            raise
        except BaseException as exc:   # noqa: BLE001 - the solver broke (even SystemExit): say so, never hide it
            if type(exc) is KeyboardInterrupt:     # a real Ctrl-C (exactly this class) still stops the program
                raise
            att.why = describe_exception(exc)
            if att.setup_s or t1 != t0:
                att.solve_s = time.perf_counter() - t1 - spent()
        if att.why is None:
            try:
                if check_declared(solver) != att.declared:
                    att.why = (f"solver plugin {name!r} changed its declared tolerance/exact during the run "
                               f"(from {att.declared[0]:g}/{att.declared[1]} to {solver.tolerance!r}/"
                               f"{solver.exact!r})")
            except InputError as exc:
                att.why = f"{exc} (changed during the run)"
        att.reduction = _reduction_of(solver, view, qp) if att.why is None else None
    return att


def _attach(solver: Any, monitor: Any, t1: float, setup_s: float) -> bool:
    """Attach ``monitor`` (None: detach) as the solver's iterate monitor, its clock started at ``t1``
    after ``setup_s``; False when there is none or the plugin object refuses the attribute (it stays a point)."""
    if monitor is not None:
        monitor.start(t1, setup_s)
    try:
        solver._iterate_monitor = monitor
    except (AttributeError, TypeError):
        return False
    return monitor is not None


def _certified(qp: QP, sol: Solution, att: _Attempt, tol: float | None, tick: Callable[[str, float], None],
               multipliers: bool = True) -> Solution:
    """The evaluator's residuals and the certificate (to ``tol`` if asked, else the declared tolerance)."""
    attach_residuals(qp, sol)
    t3 = time.perf_counter()
    asked = None if tol is None or not np.isfinite(tol) else float(tol)
    certify_status(qp, sol, att.declared[0] if asked is None else asked, att.declared[1], reduction=att.reduction,
                   multipliers=multipliers)
    bad = [k for k in (*evaluator.RESIDUALS, "energy") if sol.residuals is not None
           and not np.isfinite(sol.residuals.get(k, np.nan))]
    if sol.status == Status.SOLVED and bad:     # e.g. x = 1e308: K x overflows, NaN > tol is False
        sol.status = Status.NUMERICAL_ERROR
        sol.message = (sol.message + "; " if sol.message else "") + \
            f"not certified: the evaluator's {', '.join(bad)} is not finite (NaN/inf)"
    sol.time_s["certify"] = time.perf_counter() - t3
    tick("certification", sol.time_s["certify"])
    return sol


def _name(solver: Any) -> str:
    name = getattr(solver, "name", None)
    return name if isinstance(name, str) and name else type(solver).__name__


def _params(solver: Any) -> dict:
    p = getattr(solver, "params", None)
    return dict(p) if isinstance(p, dict) else {}


def _checked_solution(returned: Any, qp: QP, name: str) -> tuple[Solution | None, str | None]:
    """A fresh Solution made of what the plugin returned, checked; (solution, None) or (_, the problem).

    Only x, multipliers, status, iterations, message, history and the plugin's own ``info`` keys are
    taken; ``residuals`` and the runner's info keys (:data:`RUNNER_INFO`) are the runner's.
    """
    empty = Solution(solver=name, status=Status.ERROR)
    if not isinstance(returned, Solution):
        return empty, f"solve() of solver {name!r} returned {type(returned).__name__}, not a Solution"
    try:
        status = Status(str(returned.status))
    except ValueError:
        return empty, (f"solver {name!r} returned the unknown status {returned.status!r} "
                       f"(one of {', '.join(str(s) for s in Status)})")
    arrays = {}
    for field, size, what in (("x", qp.n, "unknowns"), ("multipliers", qp.m_total, "constraints")):
        a = getattr(returned, field)
        if a is None:
            arrays[field] = None
            continue
        try:
            v = np.asarray(a)
            ok_kind = v.dtype.kind in "fiu" and v.dtype != object
            v = np.array(v, dtype=float) if ok_kind else v
        except (TypeError, ValueError):
            ok_kind = False
        if not ok_kind:
            return empty, f"solver {name!r} returned a {field} that is not an array of real numbers"
        if v.shape != (size,):
            return empty, (f"solver {name!r} returned {field} of shape {v.shape}; the QP has {size} {what}, "
                           f"so it must have shape ({size},)")
        arrays[field] = v
    if status == Status.SOLVED and arrays["x"] is None:
        return empty, f"solver {name!r} claims 'solved' without returning x"
    info = returned.info if isinstance(returned.info, dict) else {}
    times = returned.time_s if isinstance(returned.time_s, dict) else {}
    sol = Solution(
        solver=name, status=status, x=arrays["x"], multipliers=arrays["multipliers"],
        iterations={str(k): int(v) for k, v in returned.iterations.items()       # counters: whole numbers
                    if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
                    and np.isfinite(v) and float(v) == int(v)}
        if isinstance(returned.iterations, dict) else {},
        history=list(returned.history) if isinstance(returned.history, list) else [],
        time_s={str(k): float(v) for k, v in times.items()
                if k not in ("setup", "solve", "certify") and isinstance(v, (int, float)) and np.isfinite(v)},
        message=str(returned.message) if returned.message is not None else "",
        info={k: v for k, v in info.items() if k not in RUNNER_INFO})
    finite = all(a is None or np.all(np.isfinite(a)) for a in arrays.values())
    if not finite and status == Status.SOLVED:     # never 'solved' (attach_residuals says so too)
        sol.status = Status.NUMERICAL_ERROR
        sol.message = (sol.message + "; " if sol.message else "") + "solution contains NaN/inf"
        sol.info["claimed_status"] = str(Status.SOLVED)
    return sol, None


def _reduction_of(solver: Any, view: QP, qp: QP) -> Any:
    """The solver's LocalReduction of the view it was given, rebound to ``qp`` (same arrays); else the hints
    of its matrix-free operator (:class:`dualfem.numerics.certify.OperatorHints`: its diagonal estimate and
    face preconditioner, which only speed the certificate's CG up); else None."""
    from dualfem.numerics.certify import OperatorHints
    from dualfem.numerics.dual_operator import MatrixFreeDualOperator
    from dualfem.numerics.linalg import LocalReduction

    try:
        red = getattr(solver, "reduction", None)
        op = getattr(solver, "op", None)
    except Exception:  # noqa: BLE001 - a property that raises: no reduction to reuse
        return None
    if not _view_intact(view, qp):
        return None
    if type(op) is MatrixFreeDualOperator and op.qp is view:
        return OperatorHints.of(op, qp.m)
    if type(red) is not LocalReduction or red.qp is not view:
        return None
    red = copy.copy(red)
    red.qp = qp
    return red


def _ro(a: Any) -> Any:
    if not isinstance(a, np.ndarray):
        return a
    v = a.view()
    v.flags.writeable = False
    return v


def _ro_sparse(M: Any) -> Any:
    if not sp.issparse(M) or not hasattr(M, "indptr"):
        return M
    V = copy.copy(M)                         # shares the arrays; then read-only views of them
    V.data, V.indices, V.indptr = _ro(M.data), _ro(M.indices), _ro(M.indptr)
    return V


def guarded_view(qp: QP) -> QP:
    """The QP a plugin gets: a shallow copy of ``qp`` whose arrays (F, weights, the sparse matrices'
    data/indices/indptr, the parts' and maps' arrays) are read-only views of ``qp``'s (no copy: free at
    any size), sharing ``qp``'s factorization store. An in-place write raises ValueError ("assignment
    destination is read-only"); assigning an attribute changes the view only."""
    from dualfem.numerics.linalg import store_of

    store = store_of(qp)                     # created on the original: shared with the certification
    view = copy.copy(qp)
    d = view.__dict__
    d["K"], d["B"] = _ro_sparse(qp.K), _ro_sparse(qp.B)
    d["F"], d["weights"] = _ro(qp.F), _ro(qp.weights)
    d["params"] = copy.deepcopy(qp.params)
    maps = qp.maps
    promoted = getattr(maps, "_promoted", None)
    if isinstance(maps, Maps):
        d["maps"] = Maps({k: _ro(v) for k, v in maps.items()}, {k: _ro(v) for k, v in (promoted or {}).items()})
    elif isinstance(maps, dict):
        d["maps"] = {k: _ro(v) for k, v in maps.items()}
    if qp.local is not None:
        d["local"] = dataclasses.replace(qp.local, K_fixed=_ro_sparse(qp.local.K_fixed), dofs=_ro(qp.local.dofs))
    if qp.shift is not None:
        d["shift"] = dataclasses.replace(qp.shift, x=_ro(qp.shift.x))
    if qp.geometry is not None:
        g = qp.geometry
        d["geometry"] = dataclasses.replace(g, nodes=_ro(g.nodes), cells=_ro(g.cells), node_dofs=_ro(g.node_dofs))
    if qp.blocks:
        d["blocks"] = tuple(dataclasses.replace(b, G=_ro_sparse(b.G), weights=_ro(b.weights)) for b in qp.blocks)
    if qp.interface is not None:
        it = qp.interface
        d["interface"] = dataclasses.replace(it, **{f.name: _ro(getattr(it, f.name)) for f in dataclasses.fields(it)})
    d["store"] = store
    view._guarded = {k: d[k] for k in ("K", "F", "B", "weights", "local", "shift", "blocks")}   # type: ignore[attr-defined]
    return view


def _view_intact(view: QP, qp: QP) -> bool:
    """The view still holds the arrays it was given (no attribute of its data replaced)."""
    held = getattr(view, "_guarded", None)
    return isinstance(held, dict) and all(view.__dict__.get(k) is v for k, v in held.items())


def fingerprint(qp: QP) -> dict[str, int]:
    """A cheap checksum (CRC-32 of the bytes, shapes and dtypes) of each part of ``qp`` a solver reads:
    K, F, B, weights, local (K_fixed, dofs), shift (its cost: docs/measurements.md); :func:`run` compares
    it before and after every run (compare and bench run every solver through it)."""
    def crc(*arrays: Any) -> int:
        c = 0
        for a in arrays:
            if sp.issparse(a):
                c = crc(a.data, a.indices, a.indptr) ^ zlib.crc32(repr((a.format, a.shape)).encode(), c)
                continue
            a = np.ascontiguousarray(a)
            c = zlib.crc32(repr((a.shape, a.dtype.str)).encode(), c)
            c = zlib.crc32(memoryview(a).cast("B"), c)
        return c

    out = {"K": crc(qp.K), "F": crc(qp.F), "B": crc(qp.B), "weights": crc(qp.weights)}
    if qp.local is not None:
        out["local"] = crc(qp.local.K_fixed, qp.local.dofs)
    if qp.shift is not None:
        out["shift"] = crc(qp.shift.x, np.array([qp.shift.objective], dtype=float))
    if qp.blocks:
        out["blocks"] = crc(*[a for b in qp.blocks for a in (b.G, b.weights)]) ^ zlib.crc32(
            repr([(b.law.name, repr(b.law)) for b in qp.blocks]).encode())
    return out


def certify_status(qp: QP, sol: Solution, tol: float, exact: bool, reduction: Any = None,
                   multipliers: bool = True) -> Solution:
    """Demote an uncertified ``solved`` claim to ``inaccurate`` (``numerical_error`` where the evaluator's
    residuals or energy are not finite; see the module docstring): the first half of the one judge,
    :func:`dualfem.verify.judge.certify`, applied to ``sol``.

    The plugin's claim stays in ``sol.claim`` (and ``info["claimed_status"]``), the verdict in
    ``sol.verdict``; ``sol.status`` becomes the certified status, ``info["certificate"]`` the certificate.
    ``multipliers=False``: a certified multiplier error above ``tol`` is reported in the message but
    does not demote (a tier that grades x only, :mod:`dualfem.verify.grading`).

    ``reduction``: the solver's LocalReduction of ``qp`` (``Solver.reduction``), reused if valid, or the hints of
    its matrix-free operator (:class:`dualfem.numerics.certify.OperatorHints`).
    """
    from dualfem.verify.judge import certify

    sol.info.setdefault("claimed_status", str(sol.status))
    sol.info["certified_tol"] = tol
    if sol.claim is None:
        sol.claim = str(sol.info["claimed_status"])
    v = certify(qp, sol, tol, exact, reduction, multipliers)
    sol.verdict = v
    if v.certificate is not None:
        sol.info["certificate"] = v.certificate
        if "error" in v.certificate:
            sol.message = f"{sol.message}; certificate unavailable ({v.certificate['error']})".lstrip("; ")
    if v.note:
        sol.message = (f"{sol.message}; " if sol.message else "") + v.note
    if v.why:
        sol.status = Status(v.status)
        sol.message = f"{sol.message}; not certified: {v.why}" if sol.message else f"not certified: {v.why}"
    return sol


def attach_residuals(qp: QP, sol: Solution) -> Solution:
    """Fill ``sol.residuals`` from the evaluator; a non-finite answer cannot stay 'solved'."""
    if sol.x is None:
        return sol
    if sol.multipliers is None:
        sol.multipliers = np.zeros(qp.m_total)
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
        # PERMON-style work counters of the dual solvers (dualfem.numerics.dual_operator.OperatorCounters)
        "counters": {k: sol.info[k] for k in COUNTERS if k in sol.info},
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
            "total_contact_force": float(np.sum(sol.multipliers[:qp.m])),     # the Signorini block's
            "residuals": evaluator.kkt_residuals(sol.residuals),
            "stationarity_raw": sol.residuals.get("stationarity_raw"),
        })
        friction = evaluator.friction_summary(qp, sol.x)
        if friction:
            out["friction"] = friction
        cert = sol.info.get("certificate")
        if cert:
            out["certificate"] = {k: v for k, v in cert.items()
                                  if k in ("value", "bound", "active_set", "infeasible", "degenerate", "multipliers",
                                           "multipliers_floor", "path", "notes")}
    else:
        out.update({"energy": None, "max_jump": None, "n_contact": None, "residuals": None})
    return out


def jsonable_params(d: dict) -> dict:
    """Parameters as JSON-safe scalars (anything else as its string)."""
    return {k: (v if isinstance(v, (int, float, str, bool, type(None))) else str(v)) for k, v in d.items()}
