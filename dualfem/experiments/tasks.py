"""Tasks of a sweep: every run (scene x solver variant x tier), the references and the floors.

``run_id`` is a hash of everything that defines a run, so a sweep started again skips every
finished row; a scene that reads files (a QP file, a scene file) is identified by their content
(:func:`dualfem.experiments.store.content_ident`), so a changed file is run again.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualfem.experiments.spec import SCENE_KEYS_RESERVED, Spec, _as_list, _grid
from dualfem.experiments.store import content_ident
from dualfem.verify.grading import DEFAULT_GRADES


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
    too_big: str | None = None      # why its runs are not attempted: it would not fit in memory
    content: dict | None = None     # scene and params with files as their content hash (store.content_ident)


    @property
    def label(self) -> str:
        return " ".join([self.scene] + [f"{k}={_fmt(v)}" for k, v in self.params.items()])


def expand_scenes(spec: Spec) -> list[SceneSpec]:
    """Every scene of the spec's grids (validated by constructing the problem)."""
    from dualfem.core.scene import load_scene
    from dualfem.numerics.memory import available_bytes

    out: dict[str, SceneSpec] = {}
    have: int | None = None
    for blk in spec.scenes:
        reps = int(blk.get("repeats", spec.repeats))
        warm = bool(blk.get("warmup", spec.warmup))
        grid = {k: _as_list(v) for k, v in blk.items() if k not in SCENE_KEYS_RESERVED or k == "scene"}
        for combo in _grid(grid):
            name = str(combo.pop("scene"))
            prob = load_scene(name, combo)          # InputError for a bad scene or parameter
            resolved = _canon(prob.params)
            content = content_ident(name, resolved)      # a scene that reads files: keyed by their content
            key = _hash(content if content is not None else {"scene": name, "params": resolved})
            if key not in out:
                if have is None:
                    have = available_bytes()        # read once per sweep (it reads /proc and the cgroups)
                out[key] = SceneSpec(name, combo, resolved, key, reps, warm, too_big=_too_big(prob, have),
                                     content=content)
    return list(out.values())


def _too_big(problem, have: int) -> str | None:
    """Why a scene cannot be run here (the memory guard's estimate against ``have``, the memory available
    to a worker: machine, ulimit -v, cgroups), before any worker allocates it; None when it fits."""
    from dualfem.numerics.factor import get_default
    from dualfem.numerics.memory import SAFETY, fits

    est = problem.size_estimate() if hasattr(problem, "size_estimate") else None
    if est is None:
        return None
    n, label = est
    backend = get_default()
    ok, need, have = fits(n, backend, have)
    if ok:
        return None
    return (f"not run: {label} ({n / 1e6:.3g} M unknowns) needs about {need / 1e9:.3g} GB of memory with the "
            f"{backend} factorization (estimate x {SAFETY:g}), available: {have / 1e9:.3g} GB (machine, ulimit -v, "
            f"cgroup limits)")


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
                    if spec.grades != DEFAULT_GRADES:   # the default keeps the run ids of earlier sweeps
                        ident["grades"] = spec.grades
                    if spec.curves:         # a monitored run is its own run (its solve_s excludes the monitor)
                        ident["curves"] = True
                    task = {"kind": "run", "run_id": _hash(ident), "spec": spec.name, "scene": sc.scene,
                            "scene_params": sc.params, "scene_key": sc.key, "label": sc.label,
                            "solver": name, "variant": variant, "params": params, "tier": tier, "tol": tol,
                            "grades": spec.grades,
                            "repeats": repeats, "warmup": sc.warmup, "cold_setup": spec.cold_setup,
                            "time_limit": time_limit, "hard_limit": hard_limit,
                            "build_limit": spec.build_limit, "curves": spec.curves}
                    if not _in_range(sc, blk):
                        continue     # excluded by the spec's min/max: not a run of this sweep
                    reason = None
                    if cls is None:
                        reason = f"solver {name!r} is not registered (optional in the spec)"
                    else:
                        reason = cls.missing() or sc.too_big
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
            "reference": spec.reference, "hard_limit": spec.guard(spec.reference["time_limit"]),
            "build_limit": spec.build_limit, "repeats": 0, "warmup": False}


def floor_tasks(spec: Spec, scenes: list[SceneSpec]) -> list[dict]:
    """One floor task per group of scenes that share K's sparsity and size (``floor.ignore``)."""
    if not spec.floor["enabled"]:
        return []
    out: dict[str, dict] = {}
    for sc in scenes:
        if sc.too_big:           # its runs are skipped rows: no floor either
            continue
        params = sc.content["params"] if sc.content is not None else sc.resolved     # files by content
        group = {k: v for k, v in params.items() if k not in spec.floor["ignore"]}
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

