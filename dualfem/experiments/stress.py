"""Stress grid: every registered solver under extreme delta, r, units, load magnitude, nu and N.

Each run is classified against a reference solution of the same QP:

``correct``
    the relative energy-norm error ``|x - x_ref|_K / |x_ref|_K`` is at most
    ``SAFETY * tolerance``, where ``tolerance`` is the solver class's declared accuracy
    (:attr:`dualfem.solver.Solver.tolerance`) and ``SAFETY = 10`` (the declared tolerance is a
    target at default settings, not a bound; a factor 10 separates "met its target loosely" from
    "wrong"). A solver whose status is not ``solved`` is never counted correct.
``failed`` (honest failure)
    the status says "not solved" (max_iter, time_limit, stagnation, numerical_error, error, ...).
``flagged`` (honest failure)
    the status says "solved", the answer is wrong, but the independent evaluator
    (:mod:`dualfem.evaluator`) flags it: its largest KKT residual exceeds ``SAFETY * tolerance``.
``silent_wrong``
    the status says "solved", the evaluator's residuals are all within ``SAFETY * tolerance``,
    and the answer is wrong beyond ``SAFETY * tolerance``: the case a user cannot detect.
``timeout``
    the harness killed the run after its hard wall-clock limit (honest: no answer).
``crashed``
    the worker process died (segmentation fault, out of memory) - no answer.
``skipped``
    the solver does not apply (missing dependency, its own ``skip`` reason) or the run was not
    attempted because the previous N of the same solver already exceeded the time limit.
``unverified``
    no trusted reference was available (none within the time budget, or the reference's own
    KKT residual exceeded ``REF_KKT``); the run's status and residuals are still recorded.

The reference is the registered ``pdas`` solver when present, else ``clarabel`` at dualfem's
default tolerances 1e-10 (see :func:`reference_solvers`); a reference is trusted only when its own independent KKT
residual is below ``REF_KKT``. A run of the reference solver itself is compared against the
*second* reference (the other of the two) so that it is never graded against itself.

For the ``units`` and ``load`` axes the reference does not come from solving the scaled QP at
all: it is the reference of the base scene mapped by the exact physics (a change of units maps
x by the length factor and the nodal forces by stress x length; the QP is positively
homogeneous in the load, so ``x(s F) = s x(F)``). This tests scale invariance without trusting
any solver on the scaled data.

Runs execute in worker processes (so a hung or crashing solver is killed and reported, never
hangs the grid); each worker caches QPs and references, and runs of one scene go to one worker.
Results are appended to ``DIR/runs.jsonl`` one complete JSON line per finished run (resumable with
``resume=True``); ``DIR/meta.json`` is written atomically at the start and at the end.
"""
from __future__ import annotations

import hashlib
import json
import math
import multiprocessing as mp
import os
import platform
import sys
import time
from collections import OrderedDict
from dataclasses import asdict, dataclass
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any

import numpy as np

SAFETY = 10.0
#: a reference is trusted when its own largest KKT residual is below this
REF_KKT = 1e-7

DELTAS = [1e-12, 1e-9, 1e-6, 1e-3, 1.0, 1e3]
RS = [1e0, 1e3, 1e5, 1e7, 1e9, 1e12]
NUS = [0.0, 0.3, 0.45, 0.49, 0.4999]
LOAD_SCALES = [1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6]
NS = [8, 16, 32, 64, 128, 256, 512, 1024]
#: unit systems relative to the paper's (stress unit MPa, length unit taken as 1 m):
#: name -> (number of new stress units per MPa, number of new length units per m)
UNITS = OrderedDict([("MPa-m", (1.0, 1.0)), ("MPa-mm", (1.0, 1e3)), ("Pa-m", (1e6, 1.0)),
                     ("Pa-mm", (1e6, 1e3)), ("GPa-km", (1e-3, 1e-3))])
AXES = ("delta", "r", "units", "load", "nu", "N")
#: the paper's scene (f2, delta = 1e-5, E = 69000 MPa, nu = 0.3, plane strain) at N = 32
BASE = {"load": "f2", "N": 32, "delta": 1e-5, "E": 69000.0, "nu": 0.3, "plane": "strain"}
#: the paper's fixed augmentation parameter r (MPa per unit length)
PAPER_R = 1e7
#: predicted time growth of one solve when N doubles (4x unknowns, sparse direct ~ n^1.3)
GROWTH = 6.0
#: predicted growth of a run's peak memory when N doubles: 4x unknowns, and nested-dissection fill
#: ~ n log n adds ln(4n)/ln(n) ~ 1.1 at n ~ 5e5: 4 x 1.1 ~ 4.5
MEM_GROWTH = 4.5
#: scenes from this N on are not cached next to others (memory)
LARGE_N = 256

OUTCOMES = ("correct", "failed", "flagged", "timeout", "crashed", "silent_wrong", "unverified", "skipped")
HONEST = ("failed", "flagged", "timeout", "crashed")


# ------------------------------------------------------------------------------ grid
@dataclass
class Task:
    """One run: a scene, a solver with explicit parameters, and how to obtain its reference."""

    id: str
    axis: str
    coords: dict
    scene: dict
    solver: str
    params: dict
    ref: dict
    time_limit: float
    after: str | None = None          # id of the task that must finish first (N axis)
    ref_ok: bool = True                # False: do not compute a reference (beyond budget)

    def key(self) -> str:
        """Stable identity of the run (used to resume)."""
        return self.id


def _sid(d: dict) -> str:
    return hashlib.sha1(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:10]


def scene_in_units(base: dict, stress: float, length: float) -> dict:
    """The same physics as ``base`` (paper units) in a unit system; see :data:`UNITS`.

    E and tractions are stresses (x ``stress``); width, height and the defect are lengths
    (x ``length``); delta is a length per stress (the interface pressure is [u]/delta).
    """
    from dualfem.core.registry import get_problem

    d = {**get_problem("thin_defect").defaults, **base}
    out = dict(base)
    out["E"] = float(d["E"]) * stress
    out["width"] = float(d["width"]) * length
    out["height"] = float(d["height"]) * length
    out["defect"] = [[float(c) * length for c in pt] for pt in d["defect"]]
    out["load_scale"] = float(d["load_scale"]) * stress
    out["delta"] = float(d["delta"]) * length / stress
    return out


def build_grid(solver_names: list[str], *, quick: bool, axes: tuple[str, ...] = AXES,
               time_limit: float | None = None, max_n: int | None = None) -> list[Task]:
    """All tasks of the stress grid for ``solver_names`` (see the module docstring)."""
    from dualfem.core.registry import solvers

    reg = solvers()
    tl = float(time_limit if time_limit is not None else (20.0 if quick else 120.0))
    n_small = 16 if quick else 32
    base = {**BASE, "N": n_small}
    tasks: list[Task] = []

    def add(axis, coords, scene, solver, params=None, ref=None, after=None):
        params = params or {}
        tid = f"{axis}:{solver}:{_sid({'s': scene, 'p': params, 'c': coords})}"
        tasks.append(Task(id=tid, axis=axis, coords=coords, scene=scene, solver=solver, params=params,
                          ref=ref or {"mode": "solve"}, time_limit=tl, after=after))
        return tid

    # the r axis: solvers with a parameter r that is used as given (not chosen by an r_rule)
    r_solvers = [s for s in solver_names
                 if "r" in reg[s].defaults and reg[s].defaults.get("r_rule", "fixed") == "fixed"]
    if "delta" in axes:
        for load in (["f2"] if quick else ["f1", "f2", "f3"]):
            for d in DELTAS:
                for s in solver_names:
                    add("delta", {"load": load, "delta": d}, {**base, "load": load, "delta": d}, s)
    if "r" in axes:
        for s in r_solvers:
            for d in DELTAS:
                for r in RS:
                    add("r", {"delta": d, "r": r}, {**base, "delta": d}, s, {"r": r})
    if "units" in axes:
        for uname, (fs, fl) in UNITS.items():
            scene = scene_in_units(base, fs, fl)
            ref = {"mode": "transform", "base": base, "x": fl, "mu": fs * fl}
            for s in solver_names:
                add("units", {"units": uname, "r": "default"}, scene, s, ref=ref)
                if s in r_solvers:  # the paper's fixed number, not converted
                    add("units", {"units": uname, "r": f"{PAPER_R:g} fixed"}, scene, s, {"r": PAPER_R}, ref=ref)
    if "load" in axes:
        for ls in LOAD_SCALES:
            scene = {**base, "load_scale": ls}
            ref = {"mode": "transform", "base": base, "x": ls, "mu": ls}
            for s in solver_names:
                add("load", {"load_scale": ls}, scene, s, ref=ref)
    if "nu" in axes:
        for nu in NUS:
            for s in solver_names:
                add("nu", {"nu": nu}, {**base, "nu": nu, "plane": "strain"}, s)
    if "N" in axes:
        top = max_n or (128 if quick else 1024)
        prev: dict[str, str] = {}
        for n in [n for n in NS if n <= top]:
            for s in solver_names:
                prev[s] = add("N", {"N": n}, {**BASE, "N": n}, s, after=prev.get(s))
    return tasks


# ------------------------------------------------------------------------ references
def reference_solvers() -> list[tuple[str, dict]]:
    """(name, params) of the reference solvers available, preferred first."""
    from dualfem.core.registry import solvers

    reg = solvers()
    out = []
    if "pdas" in reg and reg["pdas"].missing() is None:
        out.append(("pdas", {}))
    if "clarabel" in reg and reg["clarabel"].missing() is None:
        # dualfem's clarabel defaults (tolerances 1e-10): asking for 1e-12 made Clarabel stop
        # 'inaccurate' or 'stagnation' at delta <= 1e-6 on the stress grid, with worse residuals
        out.append(("clarabel", {"max_iter": 500}))
    return out


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

            from dualfem.numerics.linalg import clear_cache

            self.qps.clear()
            self.refs.clear()
            clear_cache()
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

    def ref(self, scene: dict, which: int):
        """Reference number ``which`` (0 = preferred, 1 = second) of ``scene``, or a reason."""
        from dualfem.core import evaluator
        from dualfem.core.runner import run
        from dualfem.core.solution import Status

        refs = reference_solvers()
        if which >= len(refs):
            return None, "no second reference solver registered"
        k = (json.dumps(scene, sort_keys=True, default=str), which)
        if k not in self.refs:
            name, params = refs[which]
            qp = self.qp(scene)
            t0 = time.perf_counter()
            sol = run(name, qp, params)
            dt = time.perf_counter() - t0
            kkt = evaluator.kkt_error(sol.residuals) if sol.residuals else float("nan")
            if sol.status not in (Status.SOLVED, Status.INACCURATE) or not (kkt <= REF_KKT):
                val = (None, f"reference {name} not trusted: status {sol.status}, KKT {kkt:.1e}")
            else:
                from dualfem.core.registry import get_solver

                val = ({"name": name, "x": sol.x, "mu": sol.multipliers, "kkt": kkt, "time_s": dt,
                        "tolerance": get_solver(name).tolerance}, None)
            self.refs[k] = val
            while len(self.refs) > 2 * self.size:
                self.refs.popitem(last=False)
        return self.refs[k]


def _reference(cache: _Cache, task: Task, which: int):
    if task.ref.get("mode") == "transform":
        base, why = cache.ref(task.ref["base"], which)
        if base is None:
            return None, why
        return {**base, "x": base["x"] * task.ref["x"], "mu": base["mu"] * task.ref["mu"],
                "name": base["name"] + " (base scene, mapped exactly)"}, None
    return cache.ref(task.scene, which)


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


def classify(status: str, err: float | None, kkt: float | None, tol: float) -> str:
    """Outcome of a run (see module docstring)."""
    if status == "skipped":
        return "skipped"
    if status != "solved":
        return "failed"
    if err is None or not math.isfinite(err):
        return "unverified"
    bound = SAFETY * tol
    if err <= bound:
        return "correct"
    if kkt is None or not math.isfinite(kkt) or kkt > bound:
        return "flagged"
    return "silent_wrong"


def execute(task: Task, cache: _Cache) -> dict:
    """Run one task in this process; return its JSON record (no arrays)."""
    from dualfem.core import evaluator
    from dualfem.core.registry import get_solver
    from dualfem.core.runner import run

    cls = get_solver(task.solver)
    params = dict(task.params)
    if "time_limit" in cls.defaults:
        params["time_limit"] = task.time_limit
    rec: dict[str, Any] = {"id": task.id, "axis": task.axis, "coords": task.coords, "scene": task.scene,
                           "solver": task.solver, "params": task.params, "tolerance": cls.tolerance,
                           "exact": cls.exact, "third_party": bool(cls.requires)}
    qp = cache.qp(task.scene)
    rec.update(ndof=qp.n, m=qp.m, build_s=qp.params.get("_build_s"), stiffness_ratio=_stiffness_ratio(qp))
    solver = cls(**params)
    t0 = time.perf_counter()
    sol = run(solver, qp)
    wall = time.perf_counter() - t0
    rec.update(status=str(sol.status), message=sol.message, iterations=sol.iterations,
               iters=main_iterations(sol.iterations), time_setup=sol.time_s.get("setup"),
               time_solve=sol.time_s.get("solve"), wall_s=wall,
               params_used={k: (v if isinstance(v, (int, float, str, bool, type(None))) else str(v))
                            for k, v in (sol.params or {}).items()})
    kkt = None
    if sol.residuals is not None:
        rec["residuals"] = {k: v for k, v in sol.residuals.items() if k != "finite"}
        kkt = evaluator.kkt_error(sol.residuals)
    rec["kkt"] = kkt
    err = None
    if str(sol.status) != "skipped" and sol.x is not None and np.isfinite(sol.x).all():
        which = 0
        refs = reference_solvers()
        if refs and refs[0][0] == task.solver:
            which = 1  # never grade the reference solver against itself
        if not task.ref_ok:
            ref, why = None, "reference beyond the time budget at this N"
        else:
            ref, why = _reference(cache, task, which)
        if ref is None:
            rec["reference"] = {"name": None, "reason": why}
        else:
            cmp = evaluator.compare(qp, sol.x, sol.multipliers, ref["x"], ref["mu"])
            err = cmp["x_energy"]
            rec["reference"] = {"name": ref["name"], "kkt": ref["kkt"], "time_s": ref["time_s"],
                                "tolerance": ref["tolerance"]}
            rec.update(err=err, err_mu=cmp["multipliers"], contact_mismatch=cmp["contact_mismatch"])
    rec["outcome"] = classify(str(sol.status), err, kkt, cls.tolerance)
    if rec["outcome"] in ("silent_wrong", "flagged") and err <= SAFETY * rec["reference"]["tolerance"]:
        # the reference itself is only trusted to SAFETY x its declared tolerance
        rec["outcome"] = "unverified"
        rec["reason"] = (f"error {err:.1e} is within the reference's own accuracy ({SAFETY:g} x the declared "
                         f"tolerance {rec['reference']['tolerance']:g} of {rec['reference']['name']})")
    if rec["outcome"] == "unverified" and str(sol.status) == "solved" and err is None:
        rec.setdefault("reason", (rec.get("reference") or {}).get("reason", "no reference"))
    return rec



# ---------------------------------------------------------------------------- workers
def _rss_gb() -> float:
    """Resident memory of this process in GB (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0


def _proc_rss_gb(pid: int | None) -> float:
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (OSError, ValueError, IndexError, TypeError):
        return 0.0


def mem_available_gb() -> float:
    """MemAvailable of the machine in GB (Linux /proc/meminfo; inf elsewhere)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) / 1e6
    except (OSError, ValueError):
        pass
    return float("inf")


def _worker_main(conn) -> None:  # pragma: no cover - runs in a child process
    import threading
    import warnings

    warnings.simplefilter("ignore")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    parent = os.getppid()
    peak = [0.0]
    from dualfem.experiments.worker import volunteer_for_oom_killer

    volunteer_for_oom_killer()

    def watch() -> None:  # sample memory; exit if the parent died (never leave orphans)
        while True:
            if os.getppid() != parent:
                os._exit(3)
            peak[0] = max(peak[0], _rss_gb())
            time.sleep(0.2)

    threading.Thread(target=watch, daemon=True).start()
    cache = _Cache()
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        task = Task(**msg)
        peak[0] = _rss_gb()
        try:
            rec = execute(task, cache)
        except MemoryError:
            rec = {"id": task.id, "axis": task.axis, "coords": task.coords, "scene": task.scene,
                   "solver": task.solver, "params": task.params, "status": "error",
                   "outcome": "failed", "message": "out of memory (MemoryError)"}
        except Exception as exc:  # the harness itself must not die; record it
            rec = {"id": task.id, "axis": task.axis, "coords": task.coords, "scene": task.scene,
                   "solver": task.solver, "params": task.params, "status": "error",
                   "outcome": "failed", "message": f"harness: {type(exc).__name__}: {exc}"}
        rec["peak_rss_gb"] = max(peak[0], _rss_gb())
        conn.send(rec)


class _Worker:
    def __init__(self, ctx):
        self.ctx = ctx
        self.start()

    def start(self) -> None:
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_worker_main, args=(child,), daemon=True)
        self.proc.start()
        child.close()
        self.task: Task | None = None
        self.t0 = 0.0

    def submit(self, task: Task) -> None:
        self.task, self.t0 = task, time.monotonic()
        self.conn.send(asdict(task))

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(5)
        self.conn.close()

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, BrokenPipeError):
            pass
        self.proc.join(10)
        if self.proc.is_alive():
            self.kill()


def hard_limit(task: Task) -> float:
    """Wall-clock limit after which the harness kills a run (solver + assembly + reference)."""
    n = task.scene.get("N", 32)
    allowance = 60.0 + (0.0 if n <= 128 else 10.0 * (n / 128) ** 2.4)
    return 2.0 * task.time_limit + allowance


def run_grid(tasks: list[Task], out: Path, *, jobs: int = 1, resume: bool = False,
             progress=None, meta: dict | None = None) -> list[dict]:
    """Execute ``tasks``; append records to ``out/runs.jsonl``; return all records."""
    out.mkdir(parents=True, exist_ok=True)
    runs_path = out / "runs.jsonl"
    kept: dict[str, dict] = {}
    if resume and runs_path.exists():
        for line in runs_path.read_text(encoding="utf-8").splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut by a kill: rerun that task
            kept[r["id"]] = r
        # keep every complete record of axes/solvers not in this run; drop cut lines, and records
        # this run's axes and solvers would cover but its grid no longer holds (stale)
        ids_now = {t.id for t in tasks}
        axes_now, solvers_now = {t.axis for t in tasks}, {t.solver for t in tasks}
        kept = {k: r for k, r in kept.items()
                if (k in ids_now and not r.get("skip_budget"))  # scheduling decisions are re-made
                or (k not in ids_now and (r.get("axis") not in axes_now or r.get("solver") not in solvers_now))}
        _atomic_lines(runs_path, list(kept.values()))
    elif runs_path.exists():
        runs_path.unlink()
    ids = {t.id for t in tasks}
    done = {k: v for k, v in kept.items() if k in ids}
    todo = [t for t in tasks if t.id not in done]
    _write_meta(out, {**(meta or {}), "complete": False, "n_tasks": len(tasks)})
    fh = open(runs_path, "a", encoding="utf-8")
    ctx = mp.get_context("spawn")
    jobs = max(1, min(jobs, len(todo) or 1))
    workers = [_Worker(ctx) for _ in range(jobs)]
    queues: list[list[Task]] = [[] for _ in workers]
    for t in todo:  # runs of one scene go to one worker (its QP and reference caches)
        queues[int(_sid(t.scene), 16) % jobs].append(t)
    ref_time: dict[int, float] = {}
    total, finished = len(todo), 0
    results = dict(done)

    def finish(rec: dict) -> None:
        nonlocal finished
        finished += 1
        results[rec["id"]] = rec
        fh.write(json.dumps(_clean(rec)) + "\n")
        fh.flush()
        if rec.get("reference") and rec["reference"].get("time_s") and rec["axis"] == "N":
            ref_time[rec["scene"]["N"]] = rec["reference"]["time_s"]
        if progress:
            progress(finished, total, rec)

    def gate(t: Task) -> str | None:
        """None if ``t`` may run now, 'wait' if its predecessor is unfinished, else a skip reason."""
        if t.after is None:
            return None
        prev = results.get(t.after)
        if prev is None:
            return "wait"
        if prev["outcome"] == "skipped" and not prev.get("skip_budget"):
            return (f"not attempted: the solver skipped N={prev['scene']['N']} itself "
                    f"({(prev.get('message') or '')[:100]})")
        if prev["outcome"] == "crashed" or "out of memory" in (prev.get("message") or ""):
            return f"not attempted: N={prev['scene']['N']} already crashed or ran out of memory"
        if prev["outcome"] == "timeout" or prev.get("skip_budget"):
            return f"not attempted: N={prev['scene']['N']} already exceeded the time or memory budget"
        mem = (prev.get("peak_rss_gb") or 0.0) * MEM_GROWTH
        # memory our own idle workers hold (cached QPs and factorizations) is ours to reuse
        avail = mem_available_gb() + sum(_proc_rss_gb(w.proc.pid) for w in workers if w.task is None)
        if mem > 0.8 * avail:
            return (f"not attempted: predicted peak memory {mem:.1f} GB (x{MEM_GROWTH:g} per doubling of N from "
                    f"{prev['peak_rss_gb']:.1f} GB at N={prev['scene']['N']}) exceeds 80% of the {avail:.1f} GB "
                    f"available on this machine now")
        wall = (prev.get("time_setup") or 0) + (prev.get("time_solve") or 0)
        if prev.get("status") == "time_limit" or wall * GROWTH > t.time_limit:
            return (f"not attempted: predicted {wall * GROWTH:.0f} s (x{GROWTH:g} per doubling of N from "
                    f"{wall:.1f} s at N={prev['scene']['N']}) exceeds the {t.time_limit:g} s time limit")
        return None

    try:
        while any(queues) or any(w.task for w in workers):
            progressed = False
            for i, w in enumerate(workers):
                q = queues[i]
                j = 0
                while w.task is None and j < len(q):
                    t = q[j]
                    g = gate(t)
                    if g == "wait":
                        j += 1
                        continue
                    q.pop(j)
                    progressed = True
                    if g is not None:
                        finish(_skipped(t, g))
                        continue
                    prev_n = t.scene.get("N", 32) // 2
                    if prev_n in ref_time and ref_time[prev_n] * GROWTH > _ref_budget(t):
                        t.ref_ok = False
                    w.submit(t)
            busy = [w for w in workers if w.task is not None]
            if not busy:
                if any(queues) and not progressed:
                    # every remaining task waits on one that can no longer run: never spin forever
                    for q in queues:
                        while q:
                            finish(_skipped(q.pop(0), "dependency never ran"))
                continue
            ready = wait([w.conn for w in busy], timeout=1.0)
            for w in busy:
                if w.conn in ready:
                    try:
                        rec = w.conn.recv()
                    except (EOFError, OSError):
                        rec = _failed(w.task, "crashed", "worker process died (crash or out of memory)")
                        w.kill()
                        w.start()
                    w.task = None
                    finish(rec)
                elif time.monotonic() - w.t0 > hard_limit(w.task):
                    rec = _failed(w.task, "timeout", f"killed after {hard_limit(w.task):.0f} s wall clock")
                    w.kill()
                    w.start()
                    w.task = None
                    finish(rec)
                elif not w.proc.is_alive():
                    rec = _failed(w.task, "crashed", f"worker died (exit code {w.proc.exitcode})")
                    w.kill()
                    w.start()
                    w.task = None
                    finish(rec)
    finally:
        fh.close()
        for w in workers:
            w.stop()
    ordered = [results[t.id] for t in tasks if t.id in results]
    _write_meta(out, {**(meta or {}), "complete": len(ordered) == len(tasks), "n_tasks": len(tasks)})
    return ordered


def _ref_budget(t: Task) -> float:
    return max(10 * t.time_limit, 300.0)


def _skipped(t: Task, reason: str) -> dict:
    return {"id": t.id, "axis": t.axis, "coords": t.coords, "scene": t.scene, "solver": t.solver,
            "params": t.params, "status": "skipped", "outcome": "skipped", "message": reason,
            "skip_budget": True}


def _failed(t: Task, outcome: str, message: str) -> dict:
    return {"id": t.id, "axis": t.axis, "coords": t.coords, "scene": t.scene, "solver": t.solver,
            "params": t.params, "status": outcome, "outcome": outcome, "message": message,
            "wall_s": hard_limit(t)}


def _clean(o):
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    return o


def _atomic_lines(path: Path, recs: list[dict]) -> None:
    from dualfem.core.io import atomic_write_text

    atomic_write_text(path, "".join(json.dumps(_clean(r)) + "\n" for r in recs))


def _write_meta(out: Path, meta: dict) -> None:
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "meta.json", json.dumps(_clean(meta), indent=1) + "\n")


def environment() -> dict:
    """Versions and machine facts recorded with the results."""
    import importlib.metadata as md

    vers = {}
    for p in ("numpy", "scipy", "scikit-fem", "osqp", "clarabel", "cvxpy"):
        try:
            vers[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return {"python": sys.version.split()[0], "platform": platform.platform(), "cpus": os.cpu_count(),
            "versions": vers}


def load_results(path: str | Path) -> tuple[dict, list[dict]]:
    """(meta, records) from a results directory (or its ``runs.jsonl``); InputError if unusable."""
    from dualfem.core.errors import InputError

    p = Path(path)
    if p.is_dir():
        runs, metap = p / "runs.jsonl", p / "meta.json"
    else:
        runs, metap = p, p.with_name("meta.json")
    if not runs.is_file():
        raise InputError(f"RESULTS must be a stress results directory (with runs.jsonl) or a runs.jsonl "
                         f"file; {str(p)!r} has none")
    recs = []
    for i, line in enumerate(runs.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            raise InputError(f"{str(runs)!r} line {i} is not valid JSON (a cut run? rerun with --resume)") from None
        if not isinstance(r, dict) or "outcome" not in r or "axis" not in r:
            raise InputError(f"{str(runs)!r} line {i} is not a stress run record")
        recs.append(r)
    meta = {}
    if metap.is_file():
        try:
            meta = json.loads(metap.read_text(encoding="utf-8"))
        except json.JSONDecodeError:
            raise InputError(f"{str(metap)!r} is not valid JSON") from None
    return meta, recs
