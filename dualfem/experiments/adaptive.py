"""The adaptive loop a user drives (docs/adaptive.md): every step solved and certified by the runner.

    from dualfem.experiments.adaptive import adapt
    from dualfem.scene import load_scene

    scene = load_scene("griffith.toml")              # a 2D scene with mesh = "gmsh" (refine left at "none")
    for step in adapt(scene, target_error=0.01, max_unknowns=50_000, solver="pdas"):
        print(step.index, step.unknowns, step.estimate.relative, step.solution.status)

Each step is :class:`dualfem.problems.adaptive.Step` with the certified :class:`~dualfem.solution.Solution`
as ``step.solution``; a step whose answer is not certified ``solved`` stops the loop with a RuntimeError
(the mesh would be chosen from an untrusted answer). The estimator and the size rule:
:mod:`dualfem.numerics.estimator`; the re-meshing: :mod:`dualfem.problems.adaptive`.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.solution import Solution, Status
from dualfem.problems import adaptive as _loop

from .runner import run


def adapt(scene, target_error: float = _loop.TARGET_DEFAULT, max_unknowns: int = _loop.MAX_UNKNOWNS_DEFAULT,
          solver: str = "pdas", params: dict[str, Any] | None = None,
          max_steps: int = _loop.MAX_STEPS, step_growth: float | None = None) -> Iterator[_loop.Step]:
    """Yield the adaptive steps of ``scene`` (a thin-defect or fractured problem with ``mesh = "gmsh"``, a 3D
    three_d scene, a body from a ``geometry_file``), each
    solved by ``solver`` (with ``params``) and certified; stops at ``target_error`` (relative, energy norm),
    the ``max_unknowns`` budget or ``max_steps`` meshes; ``step_growth``: at most this many times the unknowns
    of one step in the next (None: as many as the target needs, within the budget). InputError for bad values
    (before any meshing)."""
    p = getattr(scene, "params", {})
    if p.get("refine", "none") != "none":
        raise InputError("adapt() drives the loop itself: give it a scene with refine = \"none\"")
    if p.get("mesh_file"):
        raise InputError("adapt() re-meshes the body with gmsh: a mesh_file body cannot be re-meshed (give its "
                         "geometry_file)")
    _loop.check_keys("adaptive", target_error, max_unknowns, "gmsh" if p.get("geometry_file") else p.get("mesh", ""))
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or not 1 <= max_steps <= 20:
        raise InputError(f"max_steps must be an integer in [1, 20], got {max_steps!r}")
    if step_growth is not None and (isinstance(step_growth, bool) or not isinstance(step_growth, (int, float))
                                    or not 1.5 <= step_growth <= 100):
        raise InputError(f"step_growth must be a number in [1.5, 100] or None, got {step_growth!r}")
    solutions: dict[int, Solution] = {}

    def solve(qp: QP) -> tuple[np.ndarray, np.ndarray]:
        sol = run(solver, qp, params)
        if sol.status != Status.SOLVED or sol.x is None or sol.multipliers is None:
            raise RuntimeError(f"adaptive step on {qp.n} unknowns: {solver} gave {sol.status} ({sol.message}); "
                               f"the loop stops (a mesh is never chosen from an uncertified answer)")
        solutions[id(qp)] = sol
        return np.asarray(sol.x), np.asarray(sol.multipliers)

    for step in _loop.adapt(scene, solve, float(target_error), int(max_unknowns), max_steps,
                            None if step_growth is None else float(step_growth)):
        step.solution = solutions.pop(id(step.qp))
        yield step
