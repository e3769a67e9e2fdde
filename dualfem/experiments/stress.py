"""Stress runs: every registered solver under extreme delta, r, units, load magnitude, nu and N.

The grid is defined in :mod:`dualfem.experiments.stress_grid`. Each run executes in a guarded
worker process of the shared harness (:mod:`dualfem.experiments.harness`: a hung or crashing
solver is killed and reported, never hangs the grid), is measured against the reference chosen
by the one reference policy (:mod:`dualfem.experiments.reference`), and graded by
:func:`dualfem.core.grade.grade` with the tolerance the solver instance declares. Each worker
caches QPs and references; runs of one scene go to one worker. On the N axis a run is attempted
only when the previous N of the same solver finished and the predicted time and memory fit.

Results: ``DIR/runs.jsonl``, one complete :class:`~dualfem.experiments.row.Row` (JSON) per
finished run, appended (resumable with ``resume=True``); ``DIR/meta.json`` written atomically.
"""
from __future__ import annotations

import json
import select
import time
from collections import OrderedDict
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.experiments.harness import GuardedWorker, rss_mb
from dualfem.experiments.machine import mem_available_gb
from dualfem.experiments.row import Row
from dualfem.experiments.stress_grid import (  # noqa: F401  (re-exported: the grid's public names)
    AXES,
    BASE,
    DELTAS,
    LOAD_SCALES,
    NS,
    NUS,
    PAPER_R,
    RS,
    UNITS,
    Task,
    _sid,
    build_grid,
    scene_base,
    scene_in_units,
)

#: a reference is trusted when its own largest KKT residual is below this
REF_KKT = 1e-7
#: predicted time growth of one solve when N doubles (4x unknowns, sparse direct ~ n^1.3)
GROWTH = 6.0
#: predicted growth of a run's peak memory when N doubles: 4x unknowns, and nested-dissection fill
#: ~ n log n adds ln(4n)/ln(n) ~ 1.1 at n ~ 5e5: 4 x 1.1 ~ 4.5
MEM_GROWTH = 4.5
#: scenes from this N on are not cached next to others (memory)
LARGE_N = 256


# ------------------------------------------------------------------------ references
class _Cache:
    """Per-worker caches of QPs and reference solutions (small LRU)."""

    def __init__(self, size: int = 3):
        self.qps: OrderedDict[str, Any] = OrderedDict()
        self.refs: OrderedDict[tuple, Any] = OrderedDict()
        self.size = size

    def qp(self, scene: dict):
        from dualfem.core.scene import load_scene

        k = json.dumps(scene, sort_keys=True, default=str)
        if k not in self.qps and int(scene.get("N", 32)) >= LARGE_N:
            # a large scene: free every cached QP, reference and factorization first
            import gc

            self.qps.clear()
            self.refs.clear()
            gc.collect()
        if k not in self.qps:
            t0 = time.perf_counter()
            qp = load_scene("f2", dict(scene)).build()
            qp.params["_build_s"] = time.perf_counter() - t0
            self.qps[k] = qp
            while len(self.qps) > self.size:
                self.qps.popitem(last=False)
        self.qps.move_to_end(k)
        return self.qps[k]

    def ref(self, scene: dict, exclude: tuple[str, ...]):
        """(reference, None) of ``scene`` not computed by a solver in ``exclude``, or (None, reason)."""
        from dualfem.experiments import reference

        k = (json.dumps(scene, sort_keys=True, default=str), exclude)
        if k not in self.refs:
            ref, tried = reference.compute(self.qp(scene), exclude=exclude, kkt_max=REF_KKT)
            self.refs[k] = (ref, None) if ref is not None else (None, "no trusted reference: " + "; ".join(tried))
            while len(self.refs) > 2 * self.size:
                self.refs.popitem(last=False)
        return self.refs[k]


def _reference(cache: _Cache, task: Task, exclude: tuple[str, ...]):
    if task.ref.get("mode") == "transform":
        base, why = cache.ref(task.ref["base"], exclude)
        if base is None:
            return None, why
        from dataclasses import replace

        return replace(base, x=base.x * task.ref["x"], multipliers=base.multipliers * task.ref["mu"],
                       solver=base.solver + " (base scene, mapped exactly)"), None
    return cache.ref(task.scene, exclude)


# ---------------------------------------------------------------------------- one run
def main_iterations(it: dict) -> float | None:
    """The solver's main iteration counter: ``outer`` when present, else the first counter."""
    if not it:
        return None
    if "outer" in it:
        return float(it["outer"])
    v = next(iter(it.values()))
    return float(v) if isinstance(v, (int, float)) else None


def _stiffness_ratio(qp) -> float | None:
    """max diagonal of the delta-dependent interface part of K over max diagonal of the elastic part."""
    dk = (qp.K - qp.K_fixed).diagonal()
    kf = qp.K_fixed.diagonal()
    if not dk.any() or not kf.any():
        return None
    return float(np.abs(dk).max() / np.abs(kf).max())


def _row(task: Task) -> Row:
    return Row(run_id=task.id, kind="stress", axis=task.axis, coords=dict(task.coords), solver=task.solver,
               solver_params=dict(task.params), scene=task.scene)


def execute(task: Task, cache: _Cache) -> Row:
    """Run one task in this process; its graded row."""
    from dualfem.core.registry import get_solver
    from dualfem.experiments.runner import run
    cls = get_solver(task.solver)
    params = dict(task.params)
    if "time_limit" in cls.defaults:
        params["time_limit"] = task.time_limit
    solver = cls(**params)
    row = _row(task)
    qp = cache.qp(task.scene)
    row.update(tol=float(solver.tolerance), exact=bool(solver.exact), third_party=bool(cls.requires),
               n_unknowns=qp.n, n_constraints=qp.m, assembly_s=qp.params.get("_build_s"), time_limit=task.time_limit,
               stiffness_ratio=_stiffness_ratio(qp))
    t0 = time.perf_counter()
    sol = run(solver, qp)
    row.update(status=str(sol.status), claimed_status=sol.info.get("claimed_status", str(sol.status)),
               message=sol.message, iterations=sol.iterations, main_iterations=main_iterations(sol.iterations),
               setup_s=sol.time_s.get("setup"), solve_s=sol.time_s.get("solve"), total_s=time.perf_counter() - t0,
               params_used={k: (v if isinstance(v, (int, float, str, bool, type(None))) else str(v))
                            for k, v in (sol.params or {}).items()})
    row.set_residuals(sol.residuals, row.tol)
    if str(sol.status) != "skipped" and sol.x is not None and np.isfinite(sol.x).all():
        # never grade a reference solver against itself
        ref, why = (None, "reference beyond the time budget at this N") if not task.ref_ok \
            else _reference(cache, task, exclude=(task.solver,))
        if ref is None:
            row["reason"] = why
        else:
            from dualfem.core import evaluator

            cmp = evaluator.compare(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)
            row.update(err_x_energy=cmp["x_energy"], err_x_max=cmp["x_max"], err_multipliers=cmp["multipliers"],
                       err_energy=cmp["energy"], contact_mismatch=cmp["contact_mismatch"], ref_solver=ref.solver,
                       ref_kkt=ref.kkt, ref_bound=ref.bound)
            row["ref_time_s"] = ref.time_s
    row.regrade()
    if row.grade == "unverified" and not row.get("reason"):
        row["reason"] = "no reference"
    return row


_CACHE: _Cache | None = None


def execute_task(task: dict, tick) -> tuple[dict, None]:
    """Harness handler of ``kind = "stress"`` tasks (runs in a worker process)."""
    global _CACHE
    if _CACHE is None:
        _CACHE = _Cache()
    t = Task(**{k: v for k, v in task.items() if k not in ("kind", "run_id", "keep_cache", "hard_limit")})
    tick("run", task["hard_limit"])
    try:
        return execute(t, _CACHE).to_dict(), None
    except MemoryError:
        row = _row(t)
        row.update(status="error", grade="failed", message="out of memory (MemoryError)")
        return row.to_dict(), None


# ---------------------------------------------------------------------------- scheduling
def hard_limit(task: Task) -> float:
    """Wall-clock limit after which the harness kills a run (solver + assembly + reference)."""
    n = task.scene.get("N", 32)
    allowance = 60.0 + (0.0 if n <= 128 else 10.0 * (n / 128) ** 2.4)
    return 2.0 * task.time_limit + allowance


def _ref_budget(t: Task) -> float:
    return max(10 * t.time_limit, 300.0)


def _skipped(t: Task, reason: str) -> Row:
    row = _row(t)
    row.update(status="skipped", grade="skipped", message=reason, skip_budget=True)
    return row


def _gate(t: Task, results: dict[str, Row], idle_rss_mb: float) -> str | None:
    """None if ``t`` may run now, 'wait' if its predecessor is unfinished, else a skip reason."""
    if t.after is None:
        return None
    prev = results.get(t.after)
    if prev is None:
        return "wait"
    pn = prev.get("scene", {}).get("N")
    if prev.grade == "skipped" and not prev.get("skip_budget"):
        return f"not attempted: the solver skipped N={pn} itself ({(prev.message or '')[:100]})"
    if prev.grade == "crashed" or "out of memory" in (prev.message or ""):
        return f"not attempted: N={pn} already crashed or ran out of memory"
    if prev.grade == "timeout" or prev.get("skip_budget"):
        return f"not attempted: N={pn} already exceeded the time or memory budget"
    mem = (prev.peak_rss_mb or 0.0) / 1e3 * MEM_GROWTH
    avail = mem_available_gb() + idle_rss_mb / 1e3    # our own idle workers' memory is ours to reuse
    if mem > 0.8 * avail:
        return (f"not attempted: predicted peak memory {mem:.1f} GB (x{MEM_GROWTH:g} per doubling of N from "
                f"{(prev.peak_rss_mb or 0) / 1e3:.1f} GB at N={pn}) exceeds 80% of the {avail:.1f} GB "
                f"available on this machine now")
    wall = (prev.setup_s or 0) + (prev.solve_s or 0)
    if prev.status == "time_limit" or wall * GROWTH > t.time_limit:
        return (f"not attempted: predicted {wall * GROWTH:.0f} s (x{GROWTH:g} per doubling of N from "
                f"{wall:.1f} s at N={pn}) exceeds the {t.time_limit:g} s time limit")
    return None


class _Scheduler:
    """Feeds tasks to guarded workers (runs of one scene to one worker), honouring N-axis gates."""

    def __init__(self, tasks: list[Task], jobs: int, finish, results: dict[str, Row]) -> None:
        self.workers = [GuardedWorker() for _ in range(jobs)]
        self.queues: list[list[Task]] = [[] for _ in self.workers]
        for t in tasks:
            self.queues[int(_sid(t.scene), 16) % jobs].append(t)
        self.finish = finish
        self.results = results           # every finished row (finish() adds them): the N-axis gates
        self.ref_time: dict[int, float] = {}

    def _idle_rss(self) -> float:
        return sum(rss_mb(w.pid) for w in self.workers if w.task is None and w.pid)

    def _feed(self, i: int, w: GuardedWorker) -> bool:
        q, j, progressed = self.queues[i], 0, False
        while w.task is None and j < len(q):
            t = q[j]
            g = _gate(t, self.results, self._idle_rss())
            if g == "wait":
                j += 1
                continue
            q.pop(j)
            progressed = True
            if g is not None:
                self.finish(_skipped(t, g))
                continue
            prev_n = t.scene.get("N", 32) // 2
            if prev_n in self.ref_time and self.ref_time[prev_n] * GROWTH > _ref_budget(t):
                t.ref_ok = False
            w.submit({"kind": "stress", "run_id": t.id, "keep_cache": True, "hard_limit": hard_limit(t), **asdict(t)})
        return progressed

    def run(self) -> None:
        try:
            while any(self.queues) or any(w.task for w in self.workers):
                progressed = any([self._feed(i, w) for i, w in enumerate(self.workers)])
                busy = [w for w in self.workers if w.task is not None]
                if not busy:
                    if any(self.queues) and not progressed:   # every remaining task waits on one that
                        for q in self.queues:                 # can no longer run: never spin forever
                            while q:
                                self.finish(_skipped(q.pop(0), "dependency never ran"))
                    continue
                select.select(busy, [], [], 1.0)
                for w in busy:
                    res = w.poll(0.0)
                    if res is not None:
                        row = Row.from_dict(res[0])
                        if row.axis == "N" and row.get("ref_time_s"):
                            self.ref_time[row["scene"]["N"]] = row["ref_time_s"]
                        self.finish(row)
        finally:
            for w in self.workers:
                w.close()


def run_grid(tasks: list[Task], out: Path, *, jobs: int = 1, resume: bool = False,
             progress=None, meta: dict | None = None) -> list[Row]:
    """Execute ``tasks``; append rows to ``out/runs.jsonl``; return the rows of ``tasks``."""
    from dualfem.experiments.store import lock_folder

    out.mkdir(parents=True, exist_ok=True)
    with lock_folder(out):
        return _run_grid(tasks, out, jobs, resume, progress, meta)


def _run_grid(tasks: list[Task], out: Path, jobs: int, resume: bool, progress, meta: dict | None) -> list[Row]:
    runs_path = out / "runs.jsonl"
    kept: dict[str, Row] = _kept_rows(runs_path, tasks) if resume else {}
    if not resume and runs_path.exists():     # never deleted: kept beside the new grid
        runs_path.replace(out / f"runs.{time.strftime('%Y%m%dT%H%M%S')}.jsonl.old")
    ids = {t.id for t in tasks}
    done = {k: v for k, v in kept.items() if k in ids}
    todo = [t for t in tasks if t.id not in done]
    _write_meta(out, {**(meta or {}), "complete": False, "n_tasks": len(tasks)})
    total, finished = len(todo), 0
    results: dict[str, Row] = dict(done)
    with open(runs_path, "a", encoding="utf-8") as fh:
        def finish(row: Row) -> None:
            nonlocal finished
            finished += 1
            results[row.run_id] = row
            fh.write(json.dumps(row.to_dict()) + "\n")
            fh.flush()
            if progress:
                progress(finished, total, row)

        _Scheduler(todo, max(1, min(jobs, len(todo) or 1)), finish, results).run()
    ordered = [results[t.id] for t in tasks if t.id in results]
    _write_meta(out, {**(meta or {}), "complete": len(ordered) == len(tasks), "n_tasks": len(tasks)})
    return ordered


def _kept_rows(runs_path: Path, tasks: list[Task]) -> dict[str, Row]:
    """Rows of a resumed grid worth keeping (rewritten atomically): complete rows of axes/solvers not
    in this run, and this run's own finished rows except its scheduling decisions (re-made)."""
    if not runs_path.exists():
        return {}
    kept: dict[str, Row] = {}
    for line in runs_path.read_text(encoding="utf-8").splitlines():
        try:
            row = row_from_record(json.loads(line))
        except (ValueError, TypeError, AttributeError):
            continue  # a line cut by a kill: rerun that task
        kept[row.run_id] = row
    ids_now = {t.id for t in tasks}
    axes_now, solvers_now = {t.axis for t in tasks}, {t.solver for t in tasks}
    kept = {k: r for k, r in kept.items()
            if (k in ids_now and not r.get("skip_budget"))
            or (k not in ids_now and (r.axis not in axes_now or r.solver not in solvers_now))}
    _atomic_lines(runs_path, list(kept.values()))
    return kept


# ------------------------------------------------------------------------------ storage
def _atomic_lines(path: Path, rows: list[Row]) -> None:
    from dualfem.core.io import atomic_write_text

    atomic_write_text(path, "".join(json.dumps(r.to_dict()) + "\n" for r in rows))


def _write_meta(out: Path, meta: dict) -> None:
    from dualfem.core.io import atomic_write_text, jsonable

    atomic_write_text(out / "meta.json", json.dumps(jsonable(meta), indent=1) + "\n")


#: field names of the stress records written before the one Row type (dualfem <= 0.1, commit d5044e1)
_LEGACY = {"id": "run_id", "outcome": "grade", "err": "err_x_energy", "err_mu": "err_multipliers", "kkt": "kkt_error",
           "iters": "main_iterations", "time_setup": "setup_s", "time_solve": "solve_s", "wall_s": "total_s",
           "ndof": "n_unknowns", "m": "n_constraints", "build_s": "assembly_s", "tolerance": "tol",
           "params": "solver_params"}


def row_from_record(rec: dict) -> Row:
    """A Row from a runs.jsonl line (also from the earlier record format, re-graded by today's policy)."""
    if "run_id" in rec and "kind" in rec:
        return Row.from_dict(rec)
    if not isinstance(rec, dict) or "axis" not in rec or "outcome" not in rec:
        raise ValueError("not a stress run record")
    d = {_LEGACY.get(k, k): v for k, v in rec.items() if k not in ("residuals", "reference", "peak_rss_gb")}
    d.update(rec.get("residuals") or {})
    ref = rec.get("reference") or {}
    # records of that format carry no certified bound of their reference: the reference is trusted to
    # its own declared tolerance, which is the slack it grants (dualfem.core.grade)
    d.update(kind="stress", ref_solver=ref.get("name"), ref_kkt=ref.get("kkt"), ref_time_s=ref.get("time_s"),
             ref_bound=ref.get("tolerance"))
    if ref.get("reason"):
        d["reason"] = ref["reason"]
    if rec.get("peak_rss_gb") is not None:
        d["peak_rss_mb"] = rec["peak_rss_gb"] * 1e3
    row = Row.from_dict(d)
    if row.kkt_error is None and rec.get("residuals"):
        row.kkt_error = max(v for v in rec["residuals"].values() if isinstance(v, (int, float)))
    if row.grade not in ("skipped", "timeout", "crashed"):
        row.regrade()
    return row


def load_results(path: str | Path) -> tuple[dict, list[Row]]:
    """(meta, rows) from a results directory (or its ``runs.jsonl``); InputError if unusable."""
    from dualfem.core.errors import InputError

    p = Path(path)
    runs, metap = (p / "runs.jsonl", p / "meta.json") if p.is_dir() else (p, p.with_name("meta.json"))
    if not runs.is_file():
        raise InputError(f"RESULTS must be a stress results directory (with runs.jsonl) or a runs.jsonl "
                         f"file; {str(p)!r} has none")
    rows = []
    for i, line in enumerate(runs.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rows.append(row_from_record(json.loads(line)))
        except json.JSONDecodeError:
            raise InputError(f"{str(runs)!r} line {i} is not valid JSON (a cut run? rerun with --resume)") from None
        except (ValueError, TypeError, AttributeError):
            raise InputError(f"{str(runs)!r} line {i} is not a stress run record") from None
    meta = {}
    if metap.is_file():
        try:
            meta = json.loads(metap.read_text(encoding="utf-8"))
        except json.JSONDecodeError:
            raise InputError(f"{str(metap)!r} is not valid JSON") from None
    return meta, rows

