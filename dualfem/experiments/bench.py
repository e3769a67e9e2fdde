"""Benchmark sweeps: run time against error for every registered solver, resumable and parallel.

A sweep is described by a TOML spec (see ``benchmarks/default.toml``)::

    name = "small"
    repeats = 3            # timed repeats per run (median reported)
    warmup = true          # one untimed run first
    time_limit = 60.0      # seconds per run: passed to the solver's own "time_limit" option and
                           # enforced by a wall-clock guard (the run's process is killed)
    cold_setup = true      # dualfem.linalg.clear_cache() before every run: setup is measured
                           # with the factorization, never read from a cache
    [tiers]                # tolerance tiers -> each solver's Solver.tolerance_params(tol)
    low = 1e-3
    high = 1e-9
    [reference]            # certified exact solve per scene, cached on disk
    solvers = ["pdas", "clarabel"]
    [[scenes]]             # a grid: every list is a dimension of the cartesian product
    scene = ["f1", "f2"]
    N = [16, 32]
    delta = [1e-3, 1e-9]
    [[solvers]]
    name = "osqp"
    tiers = ["low"]        # default: every tier
    params = {polishing = true}
    grid = {scaling = [0, 10]}
    max = {N = 256}        # only scenes with N <= 256 (min = {...} likewise): the others are not
                           # runs of this solver in the sweep (no row)
    time_limit = 900.0     # this block's own time limit (default: the spec's), e.g. to let a slow
                           # third-party solver show how far it gets on a big scene
    repeats = 1            # this block's own timed repeats (default: the scene block's)
    optional = false       # true: a solver that is not registered is skipped, not an error

Every run is one tidy row (:data:`COLUMNS`), written as ``rows/<run_id>.json`` (atomically: a
row file is complete or absent) and merged into ``results.csv`` (atomically). ``run_id`` is a
hash of everything that defines the run, so a sweep started again skips every finished row.

Three kinds of rows: ``run`` (a solver on a scene at a tier), ``reference`` (the certified exact
solve a scene's errors are measured against) and ``floor`` (one sparse factorization + one solve
of the unconstrained K: the lower bound on the time of any direct method).

Each task runs in a long-lived child process of the executing worker (:class:`GuardedWorker`):
it is killed when a phase exceeds its wall-clock budget, and the run becomes a ``time_limit``
row. The executor is the calling process (``jobs=1``), joblib/loky (``jobs>1``) or a
dask.distributed scheduler (``dask=ADDRESS``): the same task functions everywhere, and only the
parent process writes files (the workers need no shared file system).
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import pickle
import platform
import select
import struct
import subprocess
import sys
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write, atomic_write_text

#: column order of results.csv (rows may carry more keys; they are appended in sorted order)
COLUMNS = [
    "run_id", "kind", "spec", "scene", "scene_key", "label", "n_unknowns", "n_constraints",
    "solver", "variant", "solver_params", "tier", "tol", "status", "message", "iterations",
    "repeats", "repeats_done", "assembly_s", "setup_s", "solve_s", "total_s",
    "setup_s_all", "solve_s_all", "time_limit", "cold_setup",
    "kkt_error", "stationarity", "primal", "dual", "complementarity", "within_tol",
    "err_x_energy", "err_x_max", "err_multipliers", "err_energy", "contact_mismatch",
    "ref_solver", "ref_kkt", "started_utc",
    "loadavg", "cpu", "cores", "affinity", "threads", "python", "platform", "versions", "git",
]

SPEC_KEYS = {"name", "description", "repeats", "warmup", "time_limit", "guard_factor", "guard_slack",
             "build_limit", "cold_setup", "tiers", "reference", "floor", "scenes", "solvers"}
SCENE_KEYS_RESERVED = {"scene", "repeats", "warmup"}
SOLVER_KEYS = {"name", "tiers", "params", "grid", "max", "min", "optional", "label", "time_limit",
               "repeats"}
REFERENCE_KEYS = {"solvers", "tol", "certify", "time_limit", "params"}
FLOOR_KEYS = {"enabled", "ignore", "repeats", "cholmod", "warmup"}

#: statuses of a run that are final (a resumed sweep does not redo them); ``skipped`` rows are
#: cheap and redone, so that a solver registered later gets its runs.
FINAL_STATUSES = {"solved", "inaccurate", "max_iter", "time_limit", "stagnation", "numerical_error",
                  "infeasible", "error"}


# =========================================================================== spec
@dataclass
class Spec:
    """A validated sweep spec."""

    name: str
    path: str
    repeats: int = 3
    warmup: bool = True
    time_limit: float = 60.0
    guard_factor: float = 1.5
    guard_slack: float = 10.0
    build_limit: float = 900.0
    cold_setup: bool = True
    tiers: dict[str, float] = field(default_factory=dict)
    reference: dict[str, Any] = field(default_factory=dict)
    floor: dict[str, Any] = field(default_factory=dict)
    scenes: list[dict[str, Any]] = field(default_factory=list)
    solvers: list[dict[str, Any]] = field(default_factory=list)
    text: str = ""

    @property
    def hard_limit(self) -> float:
        """Wall-clock budget of one run with the spec's time limit before its process is killed."""
        return self.guard(self.time_limit)

    def guard(self, time_limit: float) -> float:
        """Wall-clock budget of a phase whose own time limit is ``time_limit`` (seconds)."""
        return time_limit * self.guard_factor + self.guard_slack


def _num(where: str, v: Any, *, lo: float = 0.0, integer: bool = False, allow_zero: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or v < lo or (v == lo and not allow_zero) or (integer and v != int(v)):
        kind = "an integer" if integer else "a finite number"
        rng = f">= {lo}" if allow_zero else f"> {lo}"
        raise InputError(f"{where} must be {kind} {rng}, got {v!r}")
    return int(v) if integer else float(v)


def _bool(where: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise InputError(f"{where} must be true or false, got {v!r}")
    return v


def _table(where: str, v: Any, allowed: set[str] | None = None) -> dict:
    if not isinstance(v, dict):
        raise InputError(f"{where} must be a table, got {v!r}")
    if allowed is not None:
        bad = sorted(set(v) - allowed)
        if bad:
            raise InputError(f"unknown key {bad[0]!r} in {where}; allowed: {', '.join(sorted(allowed))}")
    return v


def _as_list(v: Any) -> list:
    return list(v) if isinstance(v, list) else [v]


def load_spec(path: str | Path) -> Spec:
    """Read and validate a sweep spec; InputError names the offending key."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"spec file {str(path)!r} does not exist")
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML in spec {str(path)!r}: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"spec {str(path)!r} is not UTF-8 text") from None
    return parse_spec(data, path=str(path), text=text)


def parse_spec(data: dict, path: str = "<spec>", text: str = "") -> Spec:
    """Validate a spec given as a dict (the parsed TOML)."""
    from dualfem.core.registry import solvers as registered

    _table("the spec", data, SPEC_KEYS)
    s = Spec(name=str(data.get("name", Path(path).stem)), path=path, text=text)
    if "repeats" in data:
        s.repeats = _num("repeats", data["repeats"], lo=1, integer=True, allow_zero=True)
    if "warmup" in data:
        s.warmup = _bool("warmup", data["warmup"])
    for k in ("time_limit", "guard_factor", "build_limit"):
        if k in data:
            setattr(s, k, _num(k, data[k]))
    if "guard_slack" in data:
        s.guard_slack = _num("guard_slack", data["guard_slack"], allow_zero=True)
    if s.guard_factor < 1:
        raise InputError(f"guard_factor must be >= 1, got {s.guard_factor}")
    if "cold_setup" in data:
        s.cold_setup = _bool("cold_setup", data["cold_setup"])

    tiers = _table("[tiers]", data.get("tiers", {"default": 1e-6}))
    if not tiers:
        raise InputError("[tiers] must name at least one tier, e.g. low = 1e-3")
    s.tiers = {str(k): _num(f"tier {k!r}", v) for k, v in tiers.items()}
    if "any" in s.tiers:
        raise InputError("tier name 'any' is reserved (it marks solvers without tolerance options)")

    ref = _table("[reference]", data.get("reference", {}), REFERENCE_KEYS)
    s.reference = {
        "solvers": [str(n) for n in _as_list(ref.get("solvers", ["pdas", "clarabel"]))],
        "tol": _num("reference.tol", ref.get("tol", 1e-10)),
        "certify": _num("reference.certify", ref.get("certify", 1e-8)),
        "time_limit": _num("reference.time_limit", ref.get("time_limit", max(s.time_limit, 600.0))),
        "params": _table("reference.params", ref.get("params", {})),
    }
    if not s.reference["solvers"]:
        raise InputError("reference.solvers must name at least one exact solver")

    fl = _table("[floor]", data.get("floor", {}), FLOOR_KEYS)
    s.floor = {
        "enabled": _bool("floor.enabled", fl.get("enabled", True)),
        "ignore": [str(k) for k in _as_list(fl.get("ignore", ["load", "load_scale", "delta"]))],
        "repeats": _num("floor.repeats", fl.get("repeats", s.repeats), lo=1, integer=True, allow_zero=True),
        "cholmod": _bool("floor.cholmod", fl.get("cholmod", True)),
        "warmup": _bool("floor.warmup", fl.get("warmup", s.warmup)),
    }

    scenes = data.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        raise InputError("the spec needs at least one [[scenes]] block")
    for i, blk in enumerate(scenes):
        blk = dict(_table(f"[[scenes]] block {i + 1}", blk))
        if "scene" not in blk:
            raise InputError(f"[[scenes]] block {i + 1} needs scene = \"f1\" (or a list of scenes)")
        if "repeats" in blk:
            _num(f"repeats in [[scenes]] block {i + 1}", blk["repeats"], lo=1, integer=True, allow_zero=True)
        if "warmup" in blk:
            _bool(f"warmup in [[scenes]] block {i + 1}", blk["warmup"])
        for k, v in blk.items():
            if isinstance(v, list) and not v:
                raise InputError(f"{k} in [[scenes]] block {i + 1} is an empty list")
        s.scenes.append(blk)

    solvers = data.get("solvers")
    if not isinstance(solvers, list) or not solvers:
        raise InputError("the spec needs at least one [[solvers]] block")
    reg = registered()
    for i, blk in enumerate(solvers):
        blk = dict(_table(f"[[solvers]] block {i + 1}", blk, SOLVER_KEYS))
        name = blk.get("name")
        if not isinstance(name, str):
            raise InputError(f"[[solvers]] block {i + 1} needs name = \"SOLVER\"")
        optional = _bool(f"optional of solver {name!r}", blk.get("optional", False))
        if name not in reg and not optional:
            raise InputError(f"unknown solver {name!r} in the spec; registered solvers: {', '.join(sorted(reg))} "
                             f"(mark it optional = true to skip it when it is not registered)")
        tiers_ = [str(t) for t in _as_list(blk.get("tiers", list(s.tiers)))]
        for t in tiers_:
            if t not in s.tiers:
                raise InputError(f"solver {name!r} asks for tier {t!r}; tiers of the spec: {', '.join(s.tiers)}")
        params = _table(f"params of solver {name!r}", blk.get("params", {}))
        grid = _table(f"grid of solver {name!r}", blk.get("grid", {}))
        for k, v in grid.items():
            if not isinstance(v, list) or not v:
                raise InputError(f"grid.{k} of solver {name!r} must be a non-empty list")
        for bound in ("max", "min"):
            for k, v in _table(f"{bound} of solver {name!r}", blk.get(bound, {})).items():
                _num(f"{bound}.{k} of solver {name!r}", v, lo=-math.inf)
        if name in reg:  # unknown solver parameters are input errors, found before any run
            for combo in _grid(grid):
                reg[name](**{**params, **combo})
        tl = (_num(f"time_limit of solver {name!r}", blk["time_limit"]) if "time_limit" in blk else None)
        reps = (_num(f"repeats of solver {name!r}", blk["repeats"], lo=1, integer=True, allow_zero=True)
                if "repeats" in blk else None)
        s.solvers.append({"name": name, "tiers": tiers_, "params": params, "grid": grid,
                          "max": blk.get("max", {}), "min": blk.get("min", {}), "optional": optional,
                          "label": blk.get("label"), "time_limit": tl, "repeats": reps})
    return s


def _grid(grid: dict[str, list]) -> list[dict[str, Any]]:
    keys = list(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]


# ====================================================================== tasks
def _canon(o: Any) -> Any:
    """JSON-able canonical form (numpy arrays -> lists, floats kept exact via repr)."""
    if isinstance(o, dict):
        return {str(k): _canon(v) for k, v in sorted(o.items(), key=lambda kv: str(kv[0]))}
    if isinstance(o, (list, tuple)):
        return [_canon(v) for v in o]
    if isinstance(o, np.ndarray):
        return _canon(o.tolist())
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if callable(o):
        return getattr(o, "__name__", str(o))
    return o


def _hash(obj: Any, n: int = 16) -> str:
    return hashlib.sha1(json.dumps(_canon(obj), sort_keys=True, default=str).encode()).hexdigest()[:n]


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


@dataclass
class SceneSpec:
    """One point of a scene grid."""

    scene: str
    params: dict[str, Any]          # the overrides given in the spec
    resolved: dict[str, Any]        # every parameter of the problem after defaults
    key: str                        # hash of (scene, resolved)
    repeats: int
    warmup: bool

    @property
    def label(self) -> str:
        return " ".join([self.scene] + [f"{k}={_fmt(v)}" for k, v in self.params.items()])


def expand_scenes(spec: Spec) -> list[SceneSpec]:
    """Every scene of the spec's grids (validated by constructing the problem)."""
    from dualfem.core.scene import load_scene

    out: dict[str, SceneSpec] = {}
    for blk in spec.scenes:
        reps = int(blk.get("repeats", spec.repeats))
        warm = bool(blk.get("warmup", spec.warmup))
        grid = {k: _as_list(v) for k, v in blk.items() if k not in SCENE_KEYS_RESERVED or k == "scene"}
        for combo in _grid(grid):
            name = str(combo.pop("scene"))
            prob = load_scene(name, combo)          # InputError for a bad scene or parameter
            resolved = _canon(prob.params)
            key = _hash({"scene": name, "params": resolved})
            out.setdefault(key, SceneSpec(name, combo, resolved, key, reps, warm))
    return list(out.values())


def expand_tasks(spec: Spec, scenes: list[SceneSpec] | None = None) -> list[dict]:
    """Run tasks (one per scene x solver variant x tier), plus skipped rows with their reason."""
    from dualfem.core.registry import solvers as registered

    scenes = expand_scenes(spec) if scenes is None else scenes
    reg = registered()
    tasks = []
    for sc in scenes:
        for blk in spec.solvers:
            name = blk["name"]
            cls = reg.get(name)
            time_limit = spec.time_limit if blk.get("time_limit") is None else blk["time_limit"]
            hard_limit = spec.guard(time_limit)
            repeats = sc.repeats if blk.get("repeats") is None else blk["repeats"]
            for combo in _grid(blk["grid"]):
                variant = blk["label"] or name
                if combo:
                    variant += "[" + ",".join(f"{k}={_fmt(v)}" for k, v in combo.items()) + "]"
                base = {**blk["params"], **combo}
                tier_params: dict[str, dict] = {}
                for t in blk["tiers"]:
                    tp = cls.tolerance_params(spec.tiers[t]) if cls is not None else {"_tol": spec.tiers[t]}
                    tier_params[t] = tp
                if cls is not None and all(not tp for tp in tier_params.values()):
                    tier_params = {"any": {}}        # no tolerance options: one run serves every tier
                for tier, tp in tier_params.items():
                    params = {k: v for k, v in {**tp, **base}.items() if k != "_tol"}
                    if cls is not None and "time_limit" in cls.defaults and "time_limit" not in base:
                        params["time_limit"] = float(time_limit)
                    tol = spec.tiers.get(tier, float("nan"))
                    ident = {"scene": sc.key, "solver": name, "params": params, "tier": tier, "tol": tol,
                             "repeats": repeats, "warmup": sc.warmup, "cold": spec.cold_setup,
                             "time_limit": time_limit}
                    task = {"kind": "run", "run_id": _hash(ident), "spec": spec.name, "scene": sc.scene,
                            "scene_params": sc.params, "scene_key": sc.key, "label": sc.label,
                            "solver": name, "variant": variant, "params": params, "tier": tier, "tol": tol,
                            "repeats": repeats, "warmup": sc.warmup, "cold_setup": spec.cold_setup,
                            "time_limit": time_limit, "hard_limit": hard_limit,
                            "build_limit": spec.build_limit}
                    if not _in_range(sc, blk):
                        continue     # excluded by the spec's min/max: not a run of this sweep
                    reason = None
                    if cls is None:
                        reason = f"solver {name!r} is not registered (optional in the spec)"
                    else:
                        reason = cls.missing()
                    task["skip"] = reason
                    tasks.append(task)
    return tasks


def _in_range(sc: SceneSpec, blk: dict) -> bool:
    """Whether the scene lies within the solver block's ``min``/``max`` scene values."""
    for k, lim in blk["max"].items():
        v = sc.resolved.get(k)
        if isinstance(v, (int, float)) and v > lim:
            return False
    for k, lim in blk["min"].items():
        v = sc.resolved.get(k)
        if isinstance(v, (int, float)) and v < lim:
            return False
    return True


def reference_task(spec: Spec, sc: SceneSpec) -> dict:
    """The task computing the certified reference of one scene."""
    ident = {"ref": sc.key, "reference": spec.reference}
    return {"kind": "reference", "run_id": "ref-" + _hash(ident), "spec": spec.name, "scene": sc.scene,
            "scene_params": sc.params, "scene_key": sc.key, "label": sc.label,
            "reference": spec.reference, "hard_limit": spec.guard(spec.reference["time_limit"]), "build_limit": spec.build_limit, "repeats": 0, "warmup": False}


def floor_tasks(spec: Spec, scenes: list[SceneSpec]) -> list[dict]:
    """One floor task per group of scenes that share K's sparsity and size (``floor.ignore``)."""
    if not spec.floor["enabled"]:
        return []
    out: dict[str, dict] = {}
    for sc in scenes:
        group = {k: v for k, v in sc.resolved.items() if k not in spec.floor["ignore"]}
        ident = {"floor": group, "repeats": spec.floor["repeats"], "cholmod": spec.floor["cholmod"],
                 "warmup": spec.floor["warmup"]}
        rid = "floor-" + _hash(ident)
        if rid not in out:
            shared = " ".join(f"{k}={_fmt(v)}" for k, v in sc.params.items() if k not in spec.floor["ignore"])
            out[rid] = {"kind": "floor", "run_id": rid, "spec": spec.name, "scene": sc.scene,
                        "scene_params": sc.params, "scene_key": sc.key, "label": f"floor {shared}".strip(),
                        "repeats": spec.floor["repeats"], "cholmod": spec.floor["cholmod"],
                        "warmup": spec.floor["warmup"],
                        "hard_limit": spec.build_limit, "build_limit": spec.build_limit}
    return list(out.values())


# ============================================================== machine info
_MACHINE: dict | None = None


def machine_info() -> dict:
    """CPU, cores, thread settings and library versions of the process running the task."""
    global _MACHINE
    if _MACHINE is not None:
        return dict(_MACHINE)
    from importlib.metadata import PackageNotFoundError, version

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = os.cpu_count()
    threads = {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                           "RAYON_NUM_THREADS") if k in os.environ}
    vers = {}
    for pkg in ("dualfem", "numpy", "scipy", "scikit-fem", "osqp", "clarabel", "cvxpy", "scikit-sparse",
                "joblib", "distributed"):
        try:
            vers[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    git = ""
    try:
        here = Path(__file__).resolve().parents[2]
        if (here / ".git").exists():
            git = subprocess.run(["git", "-C", str(here), "rev-parse", "--short", "HEAD"], capture_output=True,
                                 text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    _MACHINE = {"cpu": cpu, "cores": os.cpu_count(), "affinity": affinity,
                "threads": json.dumps(threads, sort_keys=True) if threads else "unset",
                "python": platform.python_version(), "platform": platform.platform(terse=True),
                "versions": json.dumps(vers, sort_keys=True), "git": git}
    return dict(_MACHINE)


# ============================================================ task execution
def _utc() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _base_row(task: dict) -> dict:
    row = {k: task.get(k) for k in ("run_id", "kind", "spec", "scene", "scene_key", "label", "solver",
                                     "variant", "tier", "tol", "repeats", "time_limit", "cold_setup")}
    row["solver_params"] = json.dumps(_canon(task.get("params", {})), sort_keys=True)
    for k, v in (task.get("scene_params") or {}).items():
        row[f"scene_{k}"] = v
    row["started_utc"] = _utc()
    row["repeats_done"] = 0
    return row


def skipped_row(task: dict) -> dict:
    """The row of a task that is not run (reason in ``message``)."""
    row = _base_row(task)
    row.update(status="skipped", message=task["skip"])
    return row


def _median(v: list[float]) -> float:
    return float(np.median(v)) if v else float("nan")


def _residual_cols(res: dict | None, tol: float | None) -> dict:
    from dualfem.core.evaluator import kkt_error

    if not res:
        return {"kkt_error": None, "within_tol": False}
    k = kkt_error(res)
    out = {n: res[n] for n in ("stationarity", "primal", "dual", "complementarity")}
    out["kkt_error"] = k
    out["within_tol"] = bool(tol is not None and math.isfinite(tol) and math.isfinite(k) and k <= tol)
    return out


def _loadavg() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def execute(task: dict, tick: Callable[[str, float], None] = lambda phase, budget: None) -> tuple[dict, Any]:
    """Run one task in this process; returns (row, payload). ``tick`` announces each phase."""
    row = _base_row(task)
    row.update(machine_info())
    row["loadavg"] = _loadavg()       # 1-minute load average when the task started (a busy machine)
    if task.get("skip"):
        return skipped_row(task), None
    from dualfem.core.scene import load_scene

    tick("build", task["build_limit"])
    t0 = time.perf_counter()
    qp = load_scene(task["scene"], task["scene_params"]).build()
    row["assembly_s"] = time.perf_counter() - t0
    row["n_unknowns"], row["n_constraints"] = qp.n, qp.m
    if task["kind"] == "floor":
        return _execute_floor(task, qp, row, tick), None
    if task["kind"] == "reference":
        return _execute_reference(task, qp, row, tick)
    return _execute_run(task, qp, row, tick), None


def _timed_runs(task: dict, qp, name: str, params: dict, tick, warmup: bool, repeats: int):
    """Warm-up (untimed) then ``repeats`` timed runs; returns (last solution, setup list, solve list, note)."""
    from dualfem.numerics import linalg
    from dualfem.core.runner import run
    from dualfem.core.solution import Status

    setups, solves, statuses = [], [], []
    sol = None
    stop = {Status.TIME_LIMIT, Status.ERROR, Status.SKIPPED}
    if warmup:
        tick("warmup", task["hard_limit"])
        if task.get("cold_setup", True):
            linalg.clear_cache()
        sol = run(name, qp, params)
        if sol.status in stop:     # nothing to time: report the warm-up as is
            return sol, [sol.time_s["setup"]], [sol.time_s["solve"]], 0, "from the warm-up run"
    done = 0
    for i in range(repeats):
        tick(f"repeat {i + 1}", task["hard_limit"])
        if task.get("cold_setup", True):
            linalg.clear_cache()
        sol = run(name, qp, params)
        setups.append(sol.time_s["setup"])
        solves.append(sol.time_s["solve"])
        statuses.append(str(sol.status))
        done += 1
        if sol.status in stop:
            break
    note = "" if len(set(statuses)) <= 1 else f"statuses differ across repeats: {statuses}"
    return sol, setups, solves, done, note


def _execute_run(task: dict, qp, row: dict, tick) -> dict:
    from dualfem.core import evaluator
    from dualfem.core.solution import Status

    ref = task.get("ref")
    sol, setups, solves, done, note = _timed_runs(task, qp, task["solver"], task["params"], tick,
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
    row.update(status=status, message=msg, iterations=json.dumps(_canon(sol.iterations), sort_keys=True),
               repeats_done=done, setup_s=_median(setups), solve_s=_median(solves), total_s=_median(total),
               setup_s_all=json.dumps(setups), solve_s_all=json.dumps(solves))
    row.update(_residual_cols(sol.residuals, task.get("tol")))
    if sol.x is not None and sol.residuals is not None and sol.residuals.get("finite"):
        if ref is None:
            row["message"] = (row["message"] + "; " if row["message"] else "") + "no certified reference: errors not measured"
        elif ref["qp_key"] != qp.key():
            row["message"] = (row["message"] + "; " if row["message"] else "") + \
                "reference is stale (the scene's QP changed): errors not measured; delete the refs cache"
        else:
            c = evaluator.compare(qp, sol.x, sol.multipliers, ref["x"], ref["multipliers"])
            row.update(err_x_energy=c["x_energy"], err_x_max=c["x_max"], err_multipliers=c["multipliers"],
                       err_energy=c["energy"], contact_mismatch=c["contact_mismatch"],
                       ref_solver=ref["solver"], ref_kkt=ref["kkt"])
    return row


def _execute_reference(task: dict, qp, row: dict, tick) -> tuple[dict, Any]:
    from dualfem.core.evaluator import kkt_error
    from dualfem.core.registry import solvers as registered

    spec = task["reference"]
    reg = registered()
    tried = []
    for name in spec["solvers"]:
        cls = reg.get(name)
        if cls is None:
            tried.append(f"{name}: not registered")
            continue
        if cls.missing():
            tried.append(f"{name}: {cls.missing()}")
            continue
        params = {**cls.tolerance_params(spec["tol"]), **spec["params"].get(name, {})}
        if "time_limit" in cls.defaults:
            params["time_limit"] = float(spec["time_limit"])
        t = {**task, "cold_setup": False}      # the reference is not timed: reuse cached factorizations
        sol, setups, solves, _, _ = _timed_runs(t, qp, name, params, tick, False, 1)
        k = kkt_error(sol.residuals) if sol.residuals else float("nan")
        ok = str(sol.status) == "solved" and math.isfinite(k) and k <= spec["certify"]
        tried.append(f"{name}: {sol.status}, KKT error {k:.2e}")
        if ok:
            row.update(solver=name, variant=name, solver_params=json.dumps(_canon(params), sort_keys=True),
                       status="solved", tol=spec["certify"], setup_s=setups[0], solve_s=solves[0],
                       total_s=setups[0] + solves[0], repeats_done=1,
                       iterations=json.dumps(_canon(sol.iterations), sort_keys=True),
                       message=f"certified: evaluator KKT error {k:.2e} <= {spec['certify']:g}; tried " + "; ".join(tried))
            row.update(_residual_cols(sol.residuals, spec["certify"]))
            payload = {"x": sol.x, "multipliers": sol.multipliers, "qp_key": qp.key(), "solver": name,
                       "kkt": k, "params": json.dumps(_canon(params), sort_keys=True)}
            return row, payload
    row.update(status="error", solver="none", message="no certified reference: " + "; ".join(tried))
    return row, None


def _execute_floor(task: dict, qp, row: dict, tick) -> dict:
    """One sparse factorization + one solve of the unconstrained K (scipy splu, and CHOLMOD if present)."""
    import scipy.sparse.linalg as sla

    rows = []
    K = qp.K.tocsc()

    def splu():
        lu = sla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        return lu.solve

    methods = [("floor_splu", splu)]
    missing_cholmod = ""
    if task.get("cholmod"):
        try:
            from sksparse.cholmod import cholesky  # type: ignore

            methods.append(("floor_cholmod", lambda: cholesky(K)))
        except ImportError:
            missing_cholmod = ("CHOLMOD floor not measured: scikit-sparse is not installed "
                               "(apt-get install libsuitesparse-dev; pip install 'dualfem[cholmod]')")
    out = dict(row)
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


# ===================================================== guarded child process
_MSG = struct.Struct("!Q")


def _send(fh, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    fh.write(_MSG.pack(len(data)) + data)
    fh.flush()


def _recv_blocking(fh) -> Any:
    head = fh.read(_MSG.size)
    if len(head) < _MSG.size:
        raise EOFError
    (n,) = _MSG.unpack(head)
    data = fh.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


def _child_main() -> None:  # pragma: no cover - runs in the child process
    """Serve tasks on stdin/stdout; solver output written to fd 1 goes to stderr instead."""
    from dualfem.experiments.worker import volunteer_for_oom_killer

    volunteer_for_oom_killer()
    out_fd = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)      # C libraries print to fd 1 (e.g. OSQP's polishing notes): drop it
    sys.stdout = sys.stderr
    out = os.fdopen(out_fd, "wb")
    inp = sys.stdin.buffer
    while True:
        try:
            task = _recv_blocking(inp)
        except EOFError:
            return
        try:
            row, payload = execute(task, lambda phase, budget: _send(out, ("phase", phase, budget)))
        except BaseException as exc:  # noqa: BLE001 - every failure becomes an error row
            row, payload = _error_row(task, f"{type(exc).__name__}: {exc}"), None
        _send(out, ("done", row, payload))
        if task.get("kind") != "reference":
            # references of one mesh share the K_fixed factorization (they are not timed results);
            # after anything else, free the memory of cached factorizations
            from dualfem.numerics import linalg
            linalg.clear_cache()


def _error_row(task: dict, message: str, status: str = "error") -> dict:
    row = _base_row(task)
    try:
        row.update(machine_info())
    except Exception:  # noqa: BLE001
        pass
    row.update(status=status, message=message)
    return row


class GuardedWorker:
    """A child Python process that executes tasks; killed when a phase exceeds its budget."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.buf = b""

    def _start(self) -> None:
        env = dict(os.environ)
        env.setdefault("MPLBACKEND", "Agg")
        self.proc = subprocess.Popen([sys.executable, "-m", "dualfem.experiments.bench", "--child"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=env, bufsize=0)
        self.buf = b""

    def close(self) -> None:
        if self.proc is not None:
            try:
                self.proc.stdin.close()
                self.proc.wait(timeout=5)
            except Exception:  # noqa: BLE001
                self.proc.kill()
                self.proc.wait()
            self.proc = None

    def _kill(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None

    def _read(self, deadline: float) -> Any:
        fd = self.proc.stdout.fileno()
        while True:
            if len(self.buf) >= _MSG.size:
                (n,) = _MSG.unpack(self.buf[:_MSG.size])
                if len(self.buf) >= _MSG.size + n:
                    msg = pickle.loads(self.buf[_MSG.size:_MSG.size + n])
                    self.buf = self.buf[_MSG.size + n:]
                    return msg
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            r, _, _ = select.select([fd], [], [], left)
            if r:
                chunk = os.read(fd, 1 << 20)
                if not chunk:
                    raise EOFError
                self.buf += chunk

    def run(self, task: dict) -> tuple[dict, Any]:
        """Execute ``task`` in the child; a phase over budget kills it and gives a time_limit row."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        phase, budget = "start", 120.0
        t_phase = time.monotonic()
        try:
            _send(self.proc.stdin, task)
            while True:
                msg = self._read(t_phase + budget)
                if msg[0] == "phase":
                    phase, budget, t_phase = msg[1], msg[2], time.monotonic()
                elif msg[0] == "done":
                    return msg[1], msg[2]
        except TimeoutError:
            self._kill()
            return _error_row(task, f"killed by the wall-clock guard: phase '{phase}' exceeded {budget:.0f} s",
                              status="time_limit"), None
        except (EOFError, BrokenPipeError, OSError):
            code = self.proc.poll() if self.proc else None
            self._kill()
            why = " (killed: out of memory?)" if code == -9 else ""
            return _error_row(task, f"worker process died in phase '{phase}' (exit code {code}{why})"), None


_LOCAL = threading.local()


def run_guarded(task: dict) -> tuple[dict, Any]:
    """Execute ``task`` in this thread's guarded child process (the function sent to executors)."""
    if task.get("skip"):
        return skipped_row(task), None
    w = getattr(_LOCAL, "worker", None)
    if w is None:
        w = _LOCAL.worker = GuardedWorker()
    try:
        return w.run(task)
    except Exception as exc:  # noqa: BLE001 - never lose a task
        return _error_row(task, f"{type(exc).__name__}: {exc}"), None


def _close_local_worker() -> None:
    w = getattr(_LOCAL, "worker", None)
    if w is not None:
        w.close()
        _LOCAL.worker = None


# ================================================================= executors
def _execute_all(tasks: list[dict], jobs: int, dask: str | None) -> Iterable[tuple[dict, Any]]:
    """Yield (row, payload) for every task as it finishes."""
    if not tasks:
        return
    if dask:
        try:
            from distributed import Client, as_completed
        except ImportError:
            from dualfem.core.errors import MissingDependency
            raise MissingDependency("--dask needs dask.distributed: pip install 'dualfem[parallel]'") from None
        try:
            client = Client(dask, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--dask: cannot connect to the scheduler at {dask!r}: {exc}") from None
        try:
            futs = client.map(run_guarded, tasks, pure=False)
            for fut in as_completed(futs):
                try:
                    yield fut.result()
                except Exception as exc:  # noqa: BLE001 - a lost worker: record it
                    i = futs.index(fut)
                    yield _error_row(tasks[i], f"dask task failed: {type(exc).__name__}: {exc}"), None
        finally:
            client.close()
    elif jobs > 1:
        try:
            from joblib import Parallel, delayed
        except ImportError:
            from dualfem.core.errors import MissingDependency
            raise MissingDependency("--jobs needs joblib: pip install 'dualfem[parallel]'") from None
        par = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered")
        yield from par(delayed(run_guarded)(t) for t in tasks)
    else:
        try:
            for t in tasks:
                yield run_guarded(t)
        finally:
            _close_local_worker()


# ================================================================== progress
class Progress:
    """A bar on a terminal, one plain line per finished item otherwise (CI logs)."""

    def __init__(self, total: int, title: str, stream=None, tty: bool | None = None):
        self.total, self.done, self.title = total, 0, title
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.t0 = time.monotonic()

    def update(self, text: str) -> None:
        self.done += 1
        el = time.monotonic() - self.t0
        eta = el / self.done * (self.total - self.done) if self.done else 0.0
        if self.tty:
            w = 30
            k = int(w * self.done / max(self.total, 1))
            line = f"\r{self.title} [{'#' * k}{'.' * (w - k)}] {self.done}/{self.total} " \
                   f"{el:5.0f}s eta {eta:5.0f}s {text[:60]:60s}"
            self.stream.write(line)
            if self.done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(f"{self.title} [{self.done}/{self.total}] {text} (elapsed {el:.0f} s)\n")
        self.stream.flush()


def _describe(row: dict) -> str:
    who = row.get("variant") or row.get("solver") or row.get("kind")
    t = row.get("total_s")
    tt = f" {t:.3g} s" if isinstance(t, (int, float)) and math.isfinite(t) else ""
    e = row.get("err_x_energy")
    ee = f" err {e:.1e}" if isinstance(e, (int, float)) and e is not None and math.isfinite(e) else ""
    tier = f" tier={row['tier']}" if row.get("tier") else ""
    return f"{row.get('kind')} {row.get('label')} {who}{tier}: {row.get('status')}{tt}{ee}"


# =============================================================== result store
class ResultStore:
    """``rows/<run_id>.json`` (one atomic file per row), ``results.csv`` (atomic merge), ``refs/``."""

    def __init__(self, out: str | Path):
        self.out = Path(out)
        self.rows_dir = self.out / "rows"
        self.refs_dir = self.out / "refs"
        self.rows_dir.mkdir(parents=True, exist_ok=True)
        self.refs_dir.mkdir(parents=True, exist_ok=True)
        # temporary files of writes interrupted by a kill (atomic_write names them ".NAME.*"):
        # the result they were meant to become is absent, so the run is simply redone
        stale = [p for d in (self.rows_dir, self.refs_dir) for p in d.glob(".*")]
        stale += [p for n in ("results.csv", "sweep.json", "spec.toml") for p in self.out.glob(f".{n}.*")]
        for p in stale:
            if p.is_file():
                p.unlink()
        self.rows: dict[str, dict] = {}
        for p in sorted(self.rows_dir.glob("[!.]*.json")):
            try:
                r = json.loads(p.read_text(encoding="utf-8"))
                self.rows[r["run_id"]] = r
            except (OSError, ValueError, KeyError):
                continue     # a foreign or unreadable file: the run is redone
        self._last_csv = 0.0
        self.keep: Callable[[dict], bool] | None = None

    def done(self, run_id: str) -> bool:
        r = self.rows.get(run_id)
        return r is not None and r.get("status") in FINAL_STATUSES

    def add(self, row: dict) -> None:
        clean = {k: _jsonable(v) for k, v in row.items()}
        atomic_write_text(self.rows_dir / f"{row['run_id']}.json", json.dumps(clean, sort_keys=True))
        self.rows[row["run_id"]] = clean
        if time.monotonic() - self._last_csv > 5.0:
            self.write_csv()

    def write_csv(self) -> Path:
        """results.csv of the rows of the current spec (rows of runs no longer in it stay in rows/)."""
        self._last_csv = time.monotonic()
        rows = list(self.rows.values())
        if self.keep is not None:
            rows = [r for r in rows if self.keep(r)]
        return write_csv(self.out / "results.csv", rows)

    # ------------------------------------------------------------- references
    def ref_path(self, scene_key: str) -> Path:
        return self.refs_dir / f"{scene_key}.npz"

    def load_ref(self, scene_key: str) -> dict | None:
        p = self.ref_path(scene_key)
        if not p.exists():
            return None
        try:
            with np.load(p, allow_pickle=False) as d:
                return {"x": d["x"], "multipliers": d["multipliers"], "qp_key": str(d["qp_key"]),
                        "solver": str(d["solver"]), "kkt": float(d["kkt"])}
        except (OSError, ValueError, KeyError):
            return None

    def save_ref(self, scene_key: str, payload: dict) -> None:
        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, x=payload["x"], multipliers=payload["multipliers"], qp_key=np.array(payload["qp_key"]),
                         solver=np.array(payload["solver"]), kkt=np.array(payload["kkt"]),
                         params=np.array(payload["params"]))
        atomic_write(self.ref_path(scene_key), write)


def _jsonable(v: Any) -> Any:
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(_canon(v), sort_keys=True)
    return v


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """Write tidy rows to CSV atomically (known columns first, then the rest sorted)."""
    extra = sorted({k for r in rows for k in r} - set(COLUMNS))
    cols = COLUMNS + extra
    rows = sorted(rows, key=lambda r: (str(r.get("kind")), str(r.get("label")), str(r.get("variant")),
                                       str(r.get("tier")), str(r.get("run_id"))))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    return atomic_write_text(path, buf.getvalue())


def read_results(path: str | Path) -> list[dict]:
    """Rows of a results.csv (or of the results.csv inside a directory), numbers parsed."""
    path = Path(path)
    if path.is_dir():
        path = path / "results.csv"
    if not path.is_file():
        raise InputError(f"results file {str(path)!r} does not exist")
    out = []
    with open(path, newline="", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            out.append({k: _parse(v) for k, v in r.items()})
    return out


def _parse(v: str) -> Any:
    if v == "":
        return None
    if v in ("True", "False"):
        return v == "True"
    try:
        f = float(v)
    except ValueError:
        return v
    return int(f) if f.is_integer() and "." not in v and "e" not in v.lower() and "inf" not in v.lower() else f


# ===================================================================== sweep
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


def run_sweep(spec: Spec | str | Path, out: str | Path, *, jobs: int = 1, dask: str | None = None,
              command: str = "", progress: bool = True, stream=None,
              retry_failed: bool = False) -> SweepSummary:
    """Run (or resume) a sweep; returns a summary. Files: see :class:`ResultStore`."""
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    if jobs < 1:
        raise InputError(f"--jobs must be an integer >= 1, got {jobs}")
    store = ResultStore(out)
    if not command:   # called from Python: the equivalent command line
        command = f"dualfem bench {spec.path} --out {out}" + (f" --jobs {jobs}" if jobs > 1 else "") + \
            (f" --dask {dask}" if dask else "")
    atomic_write_text(store.out / "spec.toml", spec.text or json.dumps(_canon(spec.__dict__)))
    meta = {"spec": spec.path, "name": spec.name, "command": command, "jobs": jobs, "dask": dask,
            "started_utc": _utc(), "machine": machine_info()}
    try:   # a resumed sweep keeps the list of every invocation that wrote into this directory
        prev = json.loads((store.out / "sweep.json").read_text(encoding="utf-8"))
        meta["invocations"] = list(prev.get("invocations", []))
    except (OSError, ValueError):
        meta["invocations"] = []
    meta["invocations"].append({"command": command, "started_utc": meta["started_utc"]})
    atomic_write_text(store.out / "sweep.json", json.dumps(meta, indent=1, sort_keys=True))
    stream = stream or sys.stderr

    def is_done(rid: str) -> bool:
        if not store.done(rid):
            return False
        return not (retry_failed and store.rows[rid].get("status") not in ("solved", "inaccurate"))

    scenes = expand_scenes(spec)
    tasks = expand_tasks(spec, scenes)
    pending = [t for t in tasks if not is_done(t["run_id"])]
    run_ids = {t["run_id"] for t in tasks}
    floor_ids = {t["run_id"] for t in floor_tasks(spec, scenes)}
    scene_keys = {sc.key for sc in scenes}
    store.keep = lambda r: (r.get("run_id") in run_ids or r.get("run_id") in floor_ids
                            or (r.get("kind") == "reference" and r.get("scene_key") in scene_keys))
    statuses: dict[str, int] = {}
    ran = aux = n_refs = 0

    # phase 1: references (for scenes with pending runs) and floors
    need = {t["scene_key"] for t in pending if not t["skip"]}
    refs: dict[str, dict | None] = {}
    phase1 = []
    for sc in scenes:
        if sc.key in need:
            refs[sc.key] = store.load_ref(sc.key)
            if refs[sc.key] is None:
                phase1.append(reference_task(spec, sc))
    phase1 += [t for t in floor_tasks(spec, scenes) if not is_done(t["run_id"])]
    if phase1:
        bar = Progress(len(phase1), "references+floor", stream, None if progress else False)
        for row, payload in _execute_all(phase1, jobs, dask):
            if row["kind"] == "reference" and payload is not None:
                store.save_ref(row["scene_key"], payload)       # only certified references are cached
                refs[row["scene_key"]] = store.load_ref(row["scene_key"])
            store.add(row)
            aux += 1
            n_refs += row["kind"] == "reference"
            bar.update(_describe(row))

    # phase 2: the runs (skipped ones are written directly)
    to_run = []
    for t in pending:
        if t["skip"]:
            store.add(skipped_row(t))
            statuses["skipped"] = statuses.get("skipped", 0) + 1
        else:
            to_run.append({**t, "ref": refs.get(t["scene_key"])})
    # biggest scenes first: better load balance across workers
    to_run.sort(key=lambda t: -float(t["scene_params"].get("N", 0) if isinstance(t["scene_params"].get("N", 0),
                                                                                     (int, float)) else 0))
    if to_run:
        bar = Progress(len(to_run), spec.name, stream, None if progress else False)
        for row, _ in _execute_all(to_run, jobs, dask):
            store.add(row)
            statuses[row["status"]] = statuses.get(row["status"], 0) + 1
            ran += 1
            bar.update(_describe(row))
    store.write_csv()
    meta["finished_utc"] = _utc()
    atomic_write_text(store.out / "sweep.json", json.dumps(meta, indent=1, sort_keys=True))
    return SweepSummary(out=store.out, total=len(tasks), skipped_done=len(tasks) - len(pending), ran=ran,
                        statuses=statuses, aux=aux, refs=n_refs)


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] == ["--child"]:
        _child_main()
    else:
        print("usage: python -m dualfem.experiments.bench --child (internal); use 'dualfem bench SPEC.toml'", file=sys.stderr)
        sys.exit(2)
