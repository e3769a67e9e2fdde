"""How long a stress grid will take, said before it starts (``dualfem stress`` prints it; ``--dry-run`` too).

The estimate is measured, not guessed: one *probe* builds the grid's most frequent scene and runs the
reference policy's first solver on it through the runner (solve plus certificate, as every run of the
grid does), in this process. From the probe's two times (seconds):

* every distinct scene of the grid costs one assembly and one reference solve (a worker caches both);
* every run costs one solve with its certificate;
* a run on the N axis is scaled by :data:`dualfem.experiments.stress.GROWTH` per doubling of N (for a
  gmsh scene: per halving of ``mesh_size``), assembly by the growth of the unknowns (2^dim per
  doubling), and no run is charged more than its per-run time limit: past it the N-axis gate does not
  attempt the next N;
* the sum is divided by the parallel workers.

Solvers slower than the reference (first-order and interior-point methods) take longer than the
probe, so the estimate is a floor of the typical case; ``worst_s`` charges every run its kill limit
(:func:`dualfem.experiments.stress.hard_limit`). Both are wall-clock seconds.
"""
from __future__ import annotations

import math
import time
from collections import Counter

from dualfem.experiments.stress_grid import Task, _sid

#: above this estimate (seconds) ``dualfem stress`` prints a warning line before it starts
WARN_S = 600.0


def _dim(scene: dict) -> int:
    return 3 if scene.get("dim") == 3 else 2


def _doublings(task: Task, probe: Task) -> float:
    """log2 of how much finer the task's mesh is than the probe's (0 off the N axis)."""
    if task.axis != "N":
        return 0.0
    a, b = task.scene, probe.scene
    if a.get("mesh") == "gmsh" and a.get("mesh_size") and b.get("mesh_size"):
        return math.log2(float(b["mesh_size"]) / float(a["mesh_size"]))
    if a.get("N") and b.get("N"):
        return math.log2(float(a["N"]) / float(b["N"]))
    return 0.0


def probe_task(tasks: list[Task]) -> Task:
    """The task whose scene occurs most often in the grid (off the N axis when it can), first of those."""
    pool = [t for t in tasks if t.axis != "N"] or tasks
    key = Counter(_sid(t.scene) for t in pool).most_common(1)[0][0]
    return next(t for t in pool if _sid(t.scene) == key)


def probe(task: Task) -> dict:
    """Assembly and one certified reference-policy solve of ``task``'s scene, timed: ``build_s``,
    ``run_s`` (seconds), the solver's name and the unknowns."""
    from dualfem.core.scene import load_scene
    from dualfem.experiments import reference
    from dualfem.experiments.runner import run

    t0 = time.perf_counter()
    qp = load_scene(task.scene_name, dict(task.scene)).build()
    t1 = time.perf_counter()
    cands = reference.candidates()
    name = cands[0][0] if cands else task.solver
    run(name, qp, cands[0][1] if cands else dict(task.params))
    return {"build_s": t1 - t0, "run_s": time.perf_counter() - t1, "solver": name, "n": qp.n}


def estimate(tasks: list[Task], jobs: int = 1, measured: dict | None = None) -> dict:
    """Wall-clock estimate of ``tasks`` (see the module docstring): ``seconds``, ``worst_s``, the probe's
    numbers (``measured``, default a fresh :func:`probe`) and the counts of runs and distinct scenes."""
    from dualfem.experiments.stress import GROWTH, hard_limit

    if not tasks:
        return {"seconds": 0.0, "worst_s": 0.0, "runs": 0, "scenes": 0, "probe": measured or {}}
    base = probe_task(tasks)
    m = measured if measured is not None else probe(base)
    total = 0.0
    scenes: dict[str, Task] = {}
    for t in tasks:
        k = _doublings(t, base)
        total += min(t.time_limit, m["run_s"] * GROWTH ** k)
        scenes.setdefault(_sid(t.scene), t)
    for t in scenes.values():
        k = _doublings(t, base)
        total += min(t.time_limit, m["build_s"] * (2 ** _dim(t.scene)) ** k + m["run_s"] * GROWTH ** k)
    workers = max(1, min(jobs, len(tasks)))
    return {"seconds": total / workers, "worst_s": sum(hard_limit(t) for t in tasks) / workers,
            "runs": len(tasks), "scenes": len(scenes), "probe": m}


def duration(seconds: float) -> str:
    """``"40 s"``, ``"12 min"``, ``"3.5 h"``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def describe(est: dict) -> str:
    """One line: the estimate, how it was measured, and the worst case."""
    m = est["probe"]
    return (f"{est['runs']} runs on {est['scenes']} scenes, about {duration(est['seconds'])} (from one timed run of "
            f"the base scene: assembly {m.get('build_s', 0):.2f} s, {m.get('solver', '?')} with its certificate "
            f"{m.get('run_s', 0):.2f} s, n = {m.get('n', '?')}; slower solvers take longer, at most "
            f"{duration(est['worst_s'])} if every run hit its kill limit)")
