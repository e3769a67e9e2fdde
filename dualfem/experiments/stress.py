"""Stress runs: every registered solver under extreme delta, r, units, load magnitude, nu and N.

The grid is defined in :mod:`dualfem.experiments.stress_grid` (around the paper's f2, or any
scene of any registered problem: the axes that apply to it). The runs go through the one sweep
engine of ``dualfem bench`` (:func:`dualfem.experiments.bench.run_tasks`): each run in a guarded
worker process of the shared harness (:mod:`dualfem.experiments.harness`: a hung or crashing
solver is killed and reported, never hangs the grid), its row written to the one results store
(:class:`dualfem.experiments.store.ResultStore`: ``rows/<run_id>.json``, ``results.csv``). Stress's
own needs are features of that engine: the N axis is a chain of task dependencies (``after``)
with a gate (:func:`gate`): a run is attempted only when the previous N of the same solver
finished and the predicted time and memory fit. Each run is measured against the reference
chosen by the one reference policy (:mod:`dualfem.experiments.reference`; for the units and load
axes the base scene's reference mapped exactly) and graded by :func:`dualfem.verify.grading.grade`
with the tolerance the solver instance declares. Each worker caches QPs and references.

Results: the store's files plus ``DIR/meta.json`` (the grid's description for the report).
Folders written before the one engine (``runs.jsonl``, one JSON record per line) stay readable
(:func:`load_results`) and are imported into the store when a grid is resumed in them.
"""
from __future__ import annotations

import json
import sys
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.core.errors import InputError, OutputError
from dualfem.core.scene import DEFAULT_SCENE
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
from dualfem.numerics.memory import available_bytes

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
        #: assembly time (s) of each cached QP, by its key
        self.build_s: dict[str, float] = {}
        self.size = size

    @staticmethod
    def key(scene: dict, scene_name: str) -> str:
        return json.dumps([scene_name, scene], sort_keys=True, default=str)

    def qp(self, scene: dict, scene_name: str = DEFAULT_SCENE):
        from dualfem.core.scene import load_scene

        k = self.key(scene, scene_name)
        if k not in self.qps and int(scene.get("N", 32)) >= LARGE_N:
            # a large scene: free every cached QP, reference and factorization first
            import gc

            self.qps.clear()
            self.refs.clear()
            gc.collect()
        if k not in self.qps:
            t0 = time.perf_counter()
            qp = load_scene(scene_name, dict(scene)).build()
            self.build_s[k] = time.perf_counter() - t0
            self.qps[k] = qp
            while len(self.qps) > self.size:
                self.build_s.pop(self.qps.popitem(last=False)[0], None)
        self.qps.move_to_end(k)
        return self.qps[k]

    def ref(self, scene: dict, exclude: tuple[str, ...], scene_name: str = DEFAULT_SCENE):
        """(reference, None) of ``scene`` not computed by a solver in ``exclude``, or (None, reason)."""
        from dualfem.experiments import reference

        k = (json.dumps([scene_name, scene], sort_keys=True, default=str), exclude)
        if k not in self.refs:
            ref, tried = reference.compute(self.qp(scene, scene_name), exclude=exclude, kkt_max=REF_KKT)
            self.refs[k] = (ref, None) if ref is not None else (None, "no trusted reference: " + "; ".join(tried))
            while len(self.refs) > 2 * self.size:
                self.refs.popitem(last=False)
        return self.refs[k]


def _reference(cache: _Cache, task: Task, exclude: tuple[str, ...]):
    if task.ref.get("mode") == "transform":
        base, why = cache.ref(task.ref["base"], exclude, task.scene_name)
        if base is None:
            return None, why
        from dataclasses import replace

        return replace(base, x=base.x * task.ref["x"], multipliers=base.multipliers * task.ref["mu"],
                       solver=base.solver + " (base scene, mapped exactly)"), None
    return cache.ref(task.scene, exclude, task.scene_name)


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
    if qp.K_fixed is None or qp.K_fixed is qp.K:
        return None
    dk = (qp.K - qp.K_fixed).diagonal()
    kf = qp.K_fixed.diagonal()
    if not dk.any() or not kf.any():
        return None
    return float(np.abs(dk).max() / np.abs(kf).max())


def _row(task: Task) -> Row:
    row = Row(run_id=task.id, kind="stress", spec=GRID_NAME, axis=task.axis, coords=dict(task.coords),
              solver=task.solver, variant=task.solver, solver_params=dict(task.params), scene=task.scene)
    row["scene_name"] = task.scene_name
    return row


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
    qp = cache.qp(task.scene, task.scene_name)
    row.update(tol=float(solver.tolerance), exact=bool(solver.exact), third_party=bool(cls.requires),
               n_unknowns=qp.n, n_constraints=qp.m, time_limit=task.time_limit,
               assembly_s=cache.build_s.get(cache.key(task.scene, task.scene_name)),
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
        else:       # the one judge: measured against the reference and graded (dualfem.verify.judge)
            from dualfem.verify import Answer, against

            row.take(against(row.facts(), qp, sol, Answer(ref.solver, ref.x, ref.multipliers, ref.bound),
                             grades=row.grades, measurable=True))
            row.ref_kkt = ref.kkt
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
    t = task_of(task)
    tick("run", task["hard_limit"])
    try:
        return execute(t, _CACHE).to_dict(), None
    except MemoryError:
        row = _row(t)
        row.update(status="error", grade="failed", message="out of memory (MemoryError)")
        return row.to_dict(), None


def task_of(task: dict) -> Task:
    """The :class:`Task` of an engine task dict (:func:`as_engine_task`)."""
    names = {f.name for f in fields(Task)}
    return Task(**{k: v for k, v in task.items() if k in names})


# ---------------------------------------------------------------------------- scheduling
#: the name a stress grid claims its results folder with (a folder of a bench spec needs --force)
GRID_NAME = "stress"


def hard_limit(task: Task) -> float:
    """Wall-clock limit after which the harness kills a run (solver + assembly + reference)."""
    n = task.scene.get("N", 32)
    allowance = 60.0 + (0.0 if n <= 128 else 10.0 * (n / 128) ** 2.4)
    return 2.0 * task.time_limit + allowance


def _ref_budget(time_limit: float) -> float:
    return max(10 * time_limit, 300.0)


def as_engine_task(t: Task) -> dict:
    """The task dict the engine (:func:`dualfem.experiments.bench.run_tasks`) runs: kind ``stress``,
    its dependency ``after`` (the previous N of the same solver), the harness's hard limit."""
    return {**asdict(t), "kind": "stress", "run_id": t.id, "keep_cache": True, "hard_limit": hard_limit(t)}


def gate(task: dict, finished: dict[str, dict]) -> str | None:
    """The N-axis gate of the engine: None if ``task`` may run, else why it is not attempted.

    A run at N is attempted only when the previous N of the same solver (``after``) finished, was
    not skipped, crashed, killed or out of memory, and its time x :data:`GROWTH` fits the time
    limit and its peak memory x :data:`MEM_GROWTH` fits 80% of the memory available now. When
    the previous reference took too long to repeat at this N, the run goes without a reference.
    """
    if not task.get("after"):
        return None
    prev = Row.from_dict(finished[task["after"]])
    pn = prev.scene.get("N") if isinstance(prev.scene, dict) else None
    if prev.grade == "skipped" and not prev.get("skip_budget"):
        return f"not attempted: the solver skipped N={pn} itself ({(prev.message or '')[:100]})"
    if prev.grade == "crashed" or "out of memory" in (prev.message or ""):
        return f"not attempted: N={pn} already crashed or ran out of memory"
    if prev.grade == "timeout" or prev.get("skip_budget"):
        return f"not attempted: N={pn} already exceeded the time or memory budget"
    mem = (prev.peak_rss_mb or 0.0) / 1e3 * MEM_GROWTH
    avail = available_bytes() / 1e9          # the memory guard's figure: ulimit -v and cgroups included
    if mem > 0.8 * avail:
        return (f"not attempted: predicted peak memory {mem:.1f} GB (x{MEM_GROWTH:g} per doubling of N from "
                f"{(prev.peak_rss_mb or 0) / 1e3:.1f} GB at N={pn}) exceeds 80% of the {avail:.1f} GB "
                f"available to this process now")
    wall = (prev.setup_s or 0) + (prev.solve_s or 0)
    tl = float(task["time_limit"])
    if prev.status == "time_limit" or wall * GROWTH > tl:
        return (f"not attempted: predicted {wall * GROWTH:.0f} s (x{GROWTH:g} per doubling of N from "
                f"{wall:.1f} s at N={pn}) exceeds the {tl:g} s time limit")
    ref_t = prev.get("ref_time_s")
    if isinstance(ref_t, (int, float)) and ref_t * GROWTH > _ref_budget(tl):
        task["ref_ok"] = False
    return None


def grid_text(tasks: list[Task], meta: dict | None = None) -> str:
    """The grid's description written as the folder's ``spec.toml`` (its name claims the folder)."""
    m = meta or {}
    lines = [f'name = "{GRID_NAME}"', 'kind = "stress grid (dualfem stress)"',
             f"quick = {'true' if m.get('quick') else 'false'}",
             f"scene = {json.dumps(str(m.get('scene') or (tasks[0].scene_name if tasks else 'f2')))}",
             f"axes = {json.dumps(sorted({t.axis for t in tasks}))}",
             f"solvers = {json.dumps(sorted({t.solver for t in tasks}))}",
             f"runs = {len(tasks)}"]
    return "\n".join(lines) + "\n"


def run_grid(tasks: list[Task], out: str | Path, *, jobs: int = 1, resume: bool = False, force: bool = False,
             retry_failed: bool = False, dask: str | None = None,
             progress: Callable[[int, int, Row], None] | None = None, meta: dict | None = None,
             command: str = "", connect_timeout: float | None = None) -> list[Row]:
    """Run (or continue) ``tasks`` into the results folder ``out``; return the rows of ``tasks``.

    The one engine's meanings: ``resume`` continues a folder that holds results (finished rows
    are kept and not redone; ``retry_failed`` redoes those whose status is not solved/inaccurate);
    ``force`` writes into a folder that holds another spec's results (nothing in it is dropped);
    without either, a folder with results is refused. Rows of tasks not in ``tasks`` are always kept
    (and listed in ``results.csv``). ``jobs``: parallel guarded workers (joblib), ``dask``: a scheduler
    (refused before anything is written if it does not answer within ``connect_timeout`` s).
    """
    from dualfem.experiments.bench import log_invocation, open_store, run_tasks
    from dualfem.experiments.harness import DASK_CONNECT_TIMEOUT, check_dask
    from dualfem.experiments.machine import utc_now
    from dualfem.experiments.store import FINAL_STATUSES

    out = Path(out)
    held = holds_results(out)
    if held and not (resume or force):       # refused before anything is written
        raise InputError(f"--out {str(out)!r} already holds results ({held}): pass --resume to continue it "
                         f"(finished runs are kept), or choose another --out")
    connect_timeout = DASK_CONNECT_TIMEOUT if connect_timeout is None else connect_timeout
    if dask:
        check_dask(dask, connect_timeout)
    store = open_store(out, GRID_NAME, grid_text(tasks, meta), force=force, same_name=True,
                       warn=lambda msg: print(f"dualfem stress: warning: {msg}", file=sys.stderr, flush=True))
    try:
        legacy = (out / "runs.jsonl").is_file()
        if legacy:
            _import_legacy(store, out / "runs.jsonl")
        log_invocation(store, {"name": GRID_NAME, "command": command or f"dualfem stress --out {out}",
                               "jobs": jobs, "dask": dask, "started_utc": utc_now()})

        def done(rid: str) -> bool:
            r = store.rows.get(rid)
            if r is None or r.get("status") not in FINAL_STATUSES:
                return False
            return not (retry_failed and r.get("status") not in ("solved", "inaccurate"))

        todo = [as_engine_task(t) for t in tasks if not done(t.id)]
        _write_meta(out, {**(meta or {}), "complete": False, "n_tasks": len(tasks)})
        finished = 0

        def on_row(row: dict, payload: Any) -> None:
            nonlocal finished
            finished += 1
            if progress:
                progress(finished, len(todo), Row.from_dict(row))

        run_tasks(todo, store, jobs=max(1, min(jobs, len(todo) or 1)), dask=dask, gate=gate, on_row=on_row,
                  order=lambda t: _sid(t["scene"]), connect_timeout=connect_timeout)
        store.write_csv()
        ordered = [Row.from_dict(store.rows[t.id]) for t in tasks if t.id in store.rows]
        _write_meta(out, {**(meta or {}), "complete": len(ordered) == len(tasks), "n_tasks": len(tasks)})
        return ordered
    except OutputError as exc:          # a failed write names what the folder already holds
        raise store.accounted_error(exc) from exc
    finally:
        store.close()


def holds_results(out: Path) -> str | None:
    """Which results file a folder holds (results.csv, rows/, runs.jsonl), or None."""
    if not out.is_dir():
        return None
    for name in ("results.csv", "runs.jsonl"):
        if (out / name).is_file():
            return name
    if (out / "rows").is_dir() and any((out / "rows").glob("[!.]*.json")):
        return "rows/"
    return None


def _import_legacy(store, path: Path) -> int:
    """Rows of a folder written before the one engine (``runs.jsonl``) into the store (the file is
    left as it is); a line cut by a kill is skipped, its run redone. Returns the rows imported."""
    n = bad = 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        try:
            row = row_from_record(json.loads(line))
        except (ValueError, TypeError, AttributeError):
            bad += 1
            continue
        if row.run_id not in store.rows:
            row.spec = row.spec or GRID_NAME
            store.add(row)
            n += 1
    if bad:
        store.warn(f"{bad} unreadable line(s) of {str(path)!r} not imported; their runs are redone")
    return n


# ------------------------------------------------------------------------------ storage
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
    # its own declared tolerance, which is the slack it grants (dualfem.verify.grading)
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
    """(meta, rows) from a stress results folder: its ``results.csv`` (the one store), or, for a folder
    written before the one engine, its ``runs.jsonl`` (also a path to either file); InputError if unusable."""
    from dualfem.core.io import RESULTS_ENTRIES, check_folder_files
    from dualfem.experiments.store import read_results

    p = Path(path)
    check_folder_files(p if p.is_dir() else p.parent, "RESULTS", only=RESULTS_ENTRIES)     # no FIFO opened
    csv_path = p / "results.csv" if p.is_dir() else (p if p.suffix == ".csv" else None)
    runs = p / "runs.jsonl" if p.is_dir() else (p if p.suffix != ".csv" else None)
    folder = p if p.is_dir() else p.parent
    if csv_path is not None and csv_path.is_file():
        # the stress rows (a folder shared with a bench sweep through --force holds others too)
        rows = [Row.from_dict(r) for r in read_results(csv_path) if r.get("kind") == "stress"]
    elif runs is not None and runs.is_file():
        rows = _read_jsonl(runs)
    else:
        raise InputError(f"RESULTS must be a stress results directory (with results.csv, or runs.jsonl written "
                         f"before the one engine) or one of those files; {str(p)!r} has none")
    meta = {}
    metap = folder / "meta.json"
    if metap.is_file():
        try:
            meta = json.loads(metap.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise InputError(f"{str(metap)!r} is not valid JSON") from None
        if not isinstance(meta, dict):
            raise InputError(f"{str(metap)!r} is not a stress grid's meta.json (a JSON object), got "
                             f"{type(meta).__name__}: move it away, the rows are kept in results.csv")
    return meta, rows


def _read_jsonl(runs: Path) -> list[Row]:
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
    return rows
