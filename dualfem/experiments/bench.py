"""Benchmark sweeps (``dualfem bench``): run time against error for every solver, resumable.

Specs: :mod:`dualfem.experiments.spec`; tasks and run ids: :mod:`dualfem.experiments.tasks`;
the results folder: :mod:`dualfem.experiments.store`; worker processes and executors:
:mod:`dualfem.experiments.harness`; rows: :class:`dualfem.experiments.row.Row`.

Three kinds of rows: ``run`` (a solver on a scene at a tier), ``reference`` (the certified exact
solve a scene's errors are measured against, chosen by :mod:`dualfem.experiments.reference`)
and ``floor`` (one sparse factorization + one solve of the unconstrained K: the lower bound on
the time of any direct method), each run in a worker by :mod:`dualfem.experiments.bench_execute`.
Each run is graded by :func:`dualfem.verify.grading.grade`.
"""
from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write_text, backup
from dualfem.experiments.bench_execute import check_reference, execute, skipped_row  # noqa: F401
from dualfem.experiments.curves import CurveStore
from dualfem.experiments.harness import DASK_CONNECT_TIMEOUT, check_dask, execute_all
from dualfem.experiments.machine import machine_info, utc_now
from dualfem.experiments.progress import Progress
from dualfem.experiments.spec import Spec, load_spec
from dualfem.experiments.store import ResultStore, current_content, same_spec
from dualfem.experiments.tasks import _canon, expand_scenes, expand_tasks, floor_tasks, reference_task


def _describe(row: dict) -> str:
    who = row.get("variant") or row.get("solver") or row.get("kind")
    t = row.get("total_s")
    tt = f" {t:.3g} s" if isinstance(t, (int, float)) and math.isfinite(t) else ""
    e = row.get("err_x_energy")
    ee = f" err {e:.1e}" if isinstance(e, (int, float)) and e is not None and math.isfinite(e) else ""
    tier = f" tier={row['tier']}" if row.get("tier") else ""
    return f"{row.get('kind')} {row.get('label')} {who}{tier}: {row.get('status')}{tt}{ee}"


@dataclass
class SweepSummary:
    """What a sweep did."""

    out: Path
    total: int
    skipped_done: int
    ran: int
    statuses: dict[str, int]
    aux: int = 0
    refs: int = 0



# ===================================================================== the one engine
def run_tasks(tasks: list[dict], store: ResultStore, *, jobs: int = 1, dask: str | None = None,
              gate: Callable[[dict, dict[str, dict]], str | None] | None = None,
              on_row: Callable[[dict, Any], None] | None = None,
              order: Callable[[dict], Any] | None = None, connect_timeout: float = DASK_CONNECT_TIMEOUT) -> int:
    """The one scheduler of every sweep (``dualfem bench`` and ``dualfem stress``); returns the rows written.

    ``tasks``: dicts with ``kind`` (a handler of :data:`dualfem.experiments.harness.HANDLERS`),
    ``run_id``, and optionally ``skip`` (a reason: a skipped row, nothing run) and ``after`` (the
    run id of a task that must be finished first: a task dependency). Tasks run in waves through
    :func:`dualfem.experiments.harness.execute_all` (guarded worker processes: serial, joblib with
    ``jobs`` workers, or dask): every task whose dependency is finished (in this call, or a
    finished row of ``store`` that is not itself being redone) is ready; ``gate(task, finished
    rows)`` then returns None (run it) or a reason (a ``skipped`` row marked ``skip_budget``,
    e.g. a predicted time or memory over the budget); a gate may also adjust the task. Tasks whose
    dependency never finishes get a skipped row. ``order`` sorts each wave (e.g. biggest first).
    Every row is written to ``store`` after ``on_row(row, payload)`` (e.g. to cache a reference),
    unless ``on_row`` returns False (a check that adds no row).
    ``connect_timeout``: seconds to wait for the ``dask`` scheduler.
    """
    from dualfem.experiments.harness import error_row

    redo = {t["run_id"] for t in tasks}
    finished: dict[str, dict] = {k: v for k, v in store.rows.items() if k not in redo}
    written = 0

    def finish(row: dict, payload: Any = None) -> None:
        nonlocal written
        if on_row is not None and on_row(row, payload) is False:
            return          # a check whose row is already stored (e.g. a cached reference that holds)
        store.add(row)
        finished[row["run_id"]] = store.rows[row["run_id"]]
        written += 1

    def skip(task: dict, reason: str, budget: bool) -> None:
        if task["kind"] in ("run", "reference", "floor"):
            row = skipped_row({**task, "skip": reason})
        else:
            row = error_row(task, reason, status="skipped")
        if budget:
            row["skip_budget"] = True
        finish(row)

    pending = list(tasks)
    while pending:
        ready = [t for t in pending if not t.get("after") or t["after"] in finished]
        waiting = [t for t in pending if t.get("after") and t["after"] not in finished]
        if not ready:       # every remaining task waits on one that will never finish
            for t in waiting:
                skip(t, f"not attempted: the run it depends on ({t['after']}) never finished", False)
            break
        to_run = []
        for t in ready:
            why = t.get("skip") or (gate(t, finished) if gate is not None else None)
            if why:
                skip(t, why, not t.get("skip"))
            else:
                to_run.append(t)
        if order is not None:
            to_run.sort(key=order)
        for row, payload in execute_all(to_run, jobs, dask, connect_timeout):
            finish(row, payload)
        pending = waiting
    return written


def open_store(out: str | Path, name: str, text: str, *, force: bool = False, same_name: bool = False,
               warn: Callable[[str], None] | None = None) -> ResultStore:
    """The results folder ``out`` for the sweep ``name`` (spec ``text``), validated, claimed and locked.

    A folder belongs to one spec: one of another name, or of this name with other contents, is
    refused (``force``: add this sweep's rows to it; ``same_name``: a folder of this name accepts
    other contents, as stress grids do); nothing in it is dropped. ``spec.toml`` is replaced by
    ``text``, the one it replaces (other contents) kept as ``spec.toml.replaced-<time>``. Close it when done.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out must be a directory, {str(out)!r} is a file")
    store = ResultStore(out, warn)
    store.claim(name, text, force, same_name)
    store.open()
    prev = store.out / "spec.toml"
    if prev.is_file() and not same_spec(prev.read_text(encoding="utf-8", errors="replace"), text):
        kept = backup(prev, "replaced")          # a new name every time: never replaces an earlier backup
        store.warn(f"the folder's spec.toml (other contents) is kept as {str(kept)!r}")
    atomic_write_text(store.out / "spec.toml", text)
    return store


def log_invocation(store: ResultStore, meta: dict) -> dict:
    """Write the sweep's invocation log (sweep.json: ``meta`` plus every earlier invocation)."""
    path = store.out / "sweep.json"
    try:   # a resumed sweep keeps the list of every invocation that wrote into this directory
        prev = json.loads(path.read_text(encoding="utf-8"))
        meta["invocations"] = list(prev.get("invocations", []))
    except (OSError, ValueError, AttributeError, TypeError):
        meta["invocations"] = []
        if path.is_file():          # unreadable: kept aside (a new name), never overwritten
            store.set_aside(path, "unreadable sweep.json; a new invocation log is started")
    meta["invocations"].append({"command": meta.get("command"), "started_utc": meta.get("started_utc")})
    atomic_write_text(store.out / "sweep.json", json.dumps(meta, indent=1, sort_keys=True))
    return meta


# ===================================================================== sweep
def _begin(spec: Spec, store: ResultStore, out: Path, jobs: int, dask: str | None, command: str) -> dict:
    """The sweep's invocation log (sweep.json); returns the meta record."""
    if not command:   # called from Python: the equivalent command line
        command = f"dualfem bench {spec.path} --out {out}" + (f" --jobs {jobs}" if jobs > 1 else "") + \
            (f" --dask {dask}" if dask else "")
    meta = {"spec": spec.path, "name": spec.name, "command": command, "jobs": jobs, "dask": dask,
            "started_utc": utc_now(), "machine": machine_info()}
    return log_invocation(store, meta)


def _references_and_floors(spec, scenes, pending, store, is_done, jobs, dask, stream,
                           progress, connect_timeout=DASK_CONNECT_TIMEOUT) -> tuple[dict, int, int]:
    """Phase 1: certified references (for scenes with pending runs) and floors; returns (refs, aux, n_refs)."""
    need = {t["scene_key"] for t in pending if not t["skip"]}
    refs: dict[str, dict | None] = {}
    tasks = []
    for sc in scenes:
        if sc.key in need:
            refs[sc.key] = store.load_ref(sc.key)       # None if absent, unreadable or failing its hash
            cached = refs[sc.key]
            # a cached reference is checked against the scene's QP before anything is graded against it
            tasks.append(reference_task(spec, sc) if cached is None else
                         {**reference_task(spec, sc), "verify": {k: cached[k] for k in ("x", "multipliers", "qp_key")}})
    tasks += [t for t in floor_tasks(spec, scenes) if not is_done(t["run_id"])]
    n_refs = 0
    bar = Progress(len(tasks), "references+floor", stream, None if progress else False) if tasks else None

    def on_row(row: dict, payload: Any) -> bool:
        nonlocal n_refs
        key = row.get("scene_key")
        if row["kind"] == "reference" and isinstance(payload, dict) and payload.get("verified"):
            # the cached reference holds: graded against with the errors recomputed now; no row written
            refs[key] = {**refs[key], "kkt": payload["kkt"], "bound": payload["bound"]}
            bar.update(f"reference {row.get('label')}: cached, checked against the QP")
            return False
        if row["kind"] == "reference" and row.get("ref_rejected"):
            store.warn(f"{row['ref_rejected']} ({str(store.ref_path(key))!r}); it was recomputed"
                       + ("" if payload is not None else " and no certified reference was found"))
            if store.ref_path(key).exists():
                store.set_aside(store.ref_path(key), "rejected reference file")
            refs[key] = None
        if row["kind"] == "reference" and payload is not None:
            store.save_ref(key, payload)       # only certified references are cached
            refs[key] = store.load_ref(key)
        n_refs += row["kind"] == "reference"
        bar.update(_describe(row))
        return True

    aux = run_tasks(tasks, store, jobs=jobs, dask=dask, on_row=on_row, connect_timeout=connect_timeout)
    return refs, aux, n_refs


def _size(t: dict) -> float:
    """A run's scene size (biggest first: better load balance across workers)."""
    n = (t.get("scene_params") or {}).get("N", 0)
    return float(n) if isinstance(n, (int, float)) else 0.0


def _runs(pending, refs, store, jobs, dask, stream, progress, title,
          connect_timeout=DASK_CONNECT_TIMEOUT) -> tuple[dict[str, int], int]:
    """Phase 2: the runs (skipped ones are written directly; a run's curve, if the store records curves,
    before its row); returns (status counts, runs executed)."""
    statuses: dict[str, int] = {}
    tasks = [t if t["skip"] else {**t, "ref": refs.get(t["scene_key"])} for t in pending]
    skip_ids = {t["run_id"] for t in tasks if t["skip"]}
    n_run = len(tasks) - len(skip_ids)
    bar = Progress(n_run, title, stream, None if progress else False) if n_run else None
    ran = 0

    def on_row(row: dict, payload: Any) -> None:
        nonlocal ran
        if store.curves is not None:
            store.curves.add(row, payload)
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
        if row["run_id"] not in skip_ids:
            ran += 1
            bar.update(_describe(row))

    run_tasks(tasks, store, jobs=jobs, dask=dask, on_row=on_row, order=lambda t: -_size(t),
              connect_timeout=connect_timeout)
    return statuses, ran


def run_sweep(spec: Spec | str | Path, out: str | Path, *, jobs: int = 1, dask: str | None = None,
              command: str = "", progress: bool = True, stream=None, retry_failed: bool = False,
              force: bool = False, connect_timeout: float = DASK_CONNECT_TIMEOUT) -> SweepSummary:
    """Run (or resume) a sweep; returns a summary. Files: see :class:`ResultStore`.

    Everything is validated before anything is written; the folder is locked for the run and must
    belong to this spec (``force`` adds the rows of another spec to it). Finished rows are never
    redone (``retry_failed``: those whose status is not solved/inaccurate are). The tasks go
    through the one engine, :func:`run_tasks`: references and floors, then the runs. A ``dask``
    scheduler that does not answer within ``connect_timeout`` s is refused before anything is written.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    if jobs < 1:
        raise InputError(f"--jobs must be an integer >= 1, got {jobs}")
    scenes = expand_scenes(spec)          # every scene validated before anything is written
    tasks = expand_tasks(spec, scenes)
    out = Path(out)
    if dask:
        check_dask(dask, connect_timeout)
    store = open_store(out, spec.name, spec.text or json.dumps(_canon(spec.__dict__)), force=force)
    try:
        with store.accounted():         # a failed write names what the folder already holds
            return _sweep(spec, scenes, tasks, store, out, jobs, dask, command, progress, stream, retry_failed,
                          connect_timeout)
    finally:
        store.close()


def _sweep(spec, scenes, tasks, store, out, jobs, dask, command, progress, stream, retry_failed,
           connect_timeout=DASK_CONNECT_TIMEOUT) -> SweepSummary:
    meta = _begin(spec, store, out, jobs, dask, command)
    stream = stream or sys.stderr

    def is_done(rid: str) -> bool:
        if not store.done(rid):
            return False
        return not (retry_failed and store.rows[rid].get("status") not in ("solved", "inaccurate"))

    pending = [t for t in tasks if not is_done(t["run_id"])]
    if spec.curves or (store.out / "curves.csv").is_file() or (store.out / "curves").is_dir():
        # the curves are kept in step with their rows (a run redone without a curve loses its old one)
        CurveStore(store).open()
    # results.csv lists every row of the folder: this spec's, and (a folder shared with --force) those
    # of other specs or other versions of this one; nothing finished is ever dropped from it, except the
    # rows of a scene file or QP file of this spec made with its former content (they stay in rows/)
    store.keep = current_content(scenes, store.rows, store.warn)
    refs, aux, n_refs = _references_and_floors(spec, scenes, pending, store, is_done, jobs, dask, stream, progress,
                                               connect_timeout)
    statuses, ran = _runs(pending, refs, store, jobs, dask, stream, progress, spec.name, connect_timeout)
    store.write_csv()
    meta["finished_utc"] = utc_now()
    atomic_write_text(store.out / "sweep.json", json.dumps(meta, indent=1, sort_keys=True))
    return SweepSummary(out=store.out, total=len(tasks), skipped_done=len(tasks) - len(pending), ran=ran,
                        statuses=statuses, aux=aux, refs=n_refs)
