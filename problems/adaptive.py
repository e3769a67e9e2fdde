"""Adaptive refinement of a gmsh scene (2D thin-defect, fractured, 3D): solve, estimate, re-mesh, until met.

One step: build the QP of the current mesh, solve it (``solve(qp) -> (x, multipliers)``, any solver), the
Zienkiewicz-Zhu estimate of the answer (:func:`dualfem.numerics.estimator.estimate`: recovery on the cut mesh,
the defect faces' tractions imposed; P2: :mod:`dualfem.numerics.estimator_p2`), and, unless the relative
estimate is at most ``target_error``, the next mesh: per element the size that equidistributes the predicted
error (:func:`dualfem.numerics.estimator.equidistributed_sizes`, order ``Estimate.order``: 1 on P1, 2 on P2; at
most ``mesh_size``), given to gmsh as a background mesh (a ``PostView`` field,
:func:`dualfem.problems.gmsh_mesh.mesh_with_defects` with ``size_view``), the element budget scaled so the mesh
stays within ``max_unknowns``; a mesh gmsh fills with fewer than ``UNDERSHOOT`` of the predicted unknowns is
re-meshed with smaller sizes, and the observed ratio is carried to the next step. The loop stops at the target,
when the budget is reached (a step that
could not refine by at least 20 % more unknowns), or after ``max_steps`` meshes.

The scene option ``refine = "adaptive"`` (with ``target_error``, ``max_unknowns``) runs this loop inside the
problem with the ``pdas`` solver and returns the QP of the last mesh (which the chosen solver then solves
and the evaluator certifies as any other); :func:`dualfem.experiments.adaptive.adapt` is the loop a user
drives, each step solved and certified by the runner.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from dualfem.errors import InputError
from dualfem.numerics.estimator import Estimate, equidistributed_sizes, estimate
from dualfem.qp import QP

#: values of the scene key ``refine``
REFINE = ("none", "adaptive")
#: the default of ``target_error`` (relative, energy norm) and ``max_unknowns``, and their ranges
TARGET_DEFAULT, TARGET_RANGE = 0.05, (1e-4, 0.5)
MAX_UNKNOWNS_DEFAULT, MAX_UNKNOWNS_RANGE = 200_000, (500, 5_000_000)
#: the smallest element size asked of gmsh, relative to max(width, height): below it gmsh (tolerances ~1e-8 of
#: the body) has produced slivers of area 1e-20 near a tip
MIN_SIZE = 2e-5
#: meshes in one adaptive run at most (the scene option)
MAX_STEPS = 8
#: a mesh with fewer unknowns than this fraction of the predicted count is re-meshed with smaller sizes
UNDERSHOOT = 0.75

Solve = Callable[[QP], tuple[np.ndarray, np.ndarray]]


@dataclass
class Step:
    """One adaptive step: its index (0: the initial mesh), the problem (its mesh), QP, answer and estimate."""

    index: int
    problem: object
    qp: QP
    x: np.ndarray
    multipliers: np.ndarray
    estimate: Estimate
    #: the certified Solution (:func:`dualfem.experiments.adaptive.adapt`); None inside a scene's own loop
    solution: object = None

    @property
    def unknowns(self) -> int:
        return int(self.qp.n)


def check_keys(refine, target_error, max_unknowns, mesh: str) -> tuple[str, float | None, int | None]:
    """The adaptive keys of a scene, checked: InputError naming the key and its allowed values."""
    if refine not in REFINE:
        raise InputError(f"refine must be one of {', '.join(map(repr, REFINE))}, got {refine!r}")
    if refine == "none":
        for k, v in (("target_error", target_error), ("max_unknowns", max_unknowns)):
            if v is not None:
                raise InputError(f"{k} is a key of adaptive refinement: give refine = \"adaptive\" with it "
                                 f"(or leave {k} out)")
        return refine, None, None
    if mesh != "gmsh":
        raise InputError(f"refine = \"adaptive\" re-meshes with gmsh: it needs mesh = \"gmsh\", got mesh = {mesh!r}")
    lo, hi = TARGET_RANGE
    t = TARGET_DEFAULT if target_error is None else target_error
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t) or not lo <= t <= hi:
        raise InputError(f"target_error must be a number in [{lo:g}, {hi:g}] (the relative error in the energy "
                         f"norm to reach), got {target_error!r}")
    lo_n, hi_n = MAX_UNKNOWNS_RANGE
    n = MAX_UNKNOWNS_DEFAULT if max_unknowns is None else max_unknowns
    if isinstance(n, bool) or not isinstance(n, (int, float)) or not np.isfinite(n) or n != int(n) \
            or not lo_n <= n <= hi_n:
        raise InputError(f"max_unknowns must be an integer in [{lo_n:,}, {hi_n:,}], got {max_unknowns!r}")
    return refine, float(t), int(n)


def pdas_solve(qp: QP) -> tuple[np.ndarray, np.ndarray]:
    """The loop's solve inside a scene (``refine = "adaptive"``): the ``pdas`` plugin through the registry. It
    only chooses the mesh: the last mesh's QP is solved and certified by the caller."""
    from dualfem.registry import get_solver

    solver = get_solver("pdas")()
    solver.setup(qp)
    sol = solver.solve()
    if sol.x is None or sol.multipliers is None or str(sol.status) != "solved":
        raise RuntimeError(f"refine = 'adaptive': the pdas solve of a step failed ({sol.status}: {sol.message})")
    return np.asarray(sol.x), np.asarray(sol.multipliers)


def adapt(problem, solve: Solve, target_error: float, max_unknowns: int, max_steps: int = MAX_STEPS,
          step_growth: float | None = None) -> Iterator[Step]:
    """The adaptive loop (module docstring) from ``problem``, a 2D thin-defect scene with ``mesh = "gmsh"`` and
    ``refine = "none"``; yields every step, the last one the mesh to keep. ``step_growth``: at most this many
    times the unknowns of one step in the next (None: straight to the budget when the target needs it; a
    refinement study takes e.g. 3)."""
    pr = problem
    mesh_size = _largest_size(pr)
    fill = 1.0                                  # gmsh's unknowns over the predicted count, from the last step
    for k in range(max_steps):
        qp = pr.build()
        x, mu = solve(qp)
        est = estimate(qp, x, mu)
        yield Step(k, pr, qp, np.asarray(x), np.asarray(mu), est)
        if est.relative <= target_error or k == max_steps - 1:
            return
        budget = max_unknowns if step_growth is None else int(min(max_unknowns, step_growth * qp.n))
        nxt = _next(pr, qp, est, target_error, budget, mesh_size, fill)
        if nxt is None:
            return
        pr, fill = nxt


def _largest_size(pr) -> float:
    """The scene's mesh_size: no element of a refined mesh is larger (3D: the problem's property)."""
    size = getattr(pr, "mesh_size", None)
    if isinstance(size, float):
        return size
    p = pr.params
    return float(p["mesh_size"] or min(p["width"], p["height"]) / p["N"])


def _next(pr, qp: QP, est: Estimate, target: float, max_unknowns: int, mesh_size: float, fill: float = 1.0):
    """(The problem on the next mesh, its unknowns over the predicted count), or None when the budget leaves no
    room to refine. ``fill``: that ratio on the last step, the sizes asked of gmsh scaled by it beforehand."""
    per_element = qp.n / est.eta2.size                      # unknowns per element on this mesh
    budget = 0.9 * max_unknowns / per_element
    min_size = MIN_SIZE * pr.extent()
    sizes = equidistributed_sizes(est, target, budget, order=est.order, max_size=mesh_size, min_size=min_size)
    predicted = float(np.sum((est.sizes / sizes) ** est.dim)) * per_element
    if predicted < 1.2 * qp.n and qp.n > 0.5 * max_unknowns:
        return None
    c = pr.cut()[0]
    cells = getattr(c, "tets" if est.dim == 3 else "triangles", None)
    cells = c.cells if cells is None else cells                 # a body from a file: its cut's cells
    goal, kept = min(predicted, 0.9 * max_unknowns), None
    scale = min(fill, 1.0)                                  # the count asked of gmsh over the rule's, as sizes^-d
    last = 0
    for _ in range(3):                                      # the mesh may miss the prediction: rescale, re-mesh
        nxt = pr.on_sizes(c.points, cells, np.maximum(sizes * scale ** (1.0 / est.dim), min_size))
        n = nxt.size_of_mesh()
        if n > max_unknowns:
            scale *= 1.05 * n / max_unknowns
            continue
        kept = (nxt, scale * n / goal)
        if n >= UNDERSHOOT * goal or n <= 1.05 * last:      # met, or smaller sizes no longer add (MIN_SIZE binds)
            break
        last = n
        # gmsh fills a strongly graded 3D size field with fewer tetrahedra than sum (h_T / h'_T)^3 (about 0.6
        # of it, measured on the penny): the budget would never be reached
        scale *= n / goal
    return kept


#: scene keys of thin_defect and three_d added after their QPs' parameters were first keyed (networks, size
#: growth, adaptive refinement): left out of a QP's parameters at their defaults
LATER_KEYS = ("defects_file", "size_growth", "refine", "target_error", "max_unknowns")


class Adaptive:
    """The scene option ``refine = "adaptive"`` for a gmsh problem (mixed into ThinDefect, ThreeD, FileBody): the
    loop runs once per :class:`~dualfem.core.problem.Shared`, inside ``cut()``, and the last mesh is kept."""

    #: (points, cells, sizes): the background mesh of this instance's gmsh mesh (:meth:`on_sizes`), or None
    _size_view: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def adapt_mesh(self) -> None:
        """With ``refine = "adaptive"`` and no mesh yet: run the loop (``pdas``), keep the last step's cut mesh
        and the steps' (unknowns, relative estimate) in ``self.shared``."""
        shared = self.shared.data          # type: ignore[attr-defined]
        p = self.params                    # type: ignore[attr-defined]
        if shared.get("cut") is None and p["refine"] == "adaptive":
            steps = list(adapt(self.unrefined(), pdas_solve, p["target_error"], p["max_unknowns"]))
            last = steps[-1].problem
            shared["cut"] = last.cut()
            if "body" in last.shared.data:            # a body from a file: its uncut mesh goes with its cut
                shared["body"] = last.shared.data["body"]
            shared["adaptive"] = [(s.unknowns, s.estimate.relative) for s in steps]

    def unrefined(self):
        """This scene with ``refine = "none"``."""
        return self.with_params(refine="none", target_error=None, max_unknowns=None)  # type: ignore[attr-defined]

    def on_sizes(self, points: np.ndarray, cells: np.ndarray, sizes: np.ndarray):
        """This scene (``refine = "none"``) meshed by gmsh with the per-element ``sizes`` on an earlier mesh
        (``points`` (dim, n) in the reference frame, ``cells`` (dim + 1, nt)) as its background mesh."""
        new = self.unrefined()
        new._size_view = (np.asarray(points), np.asarray(cells), np.asarray(sizes))
        return new

    def size_of_mesh(self) -> int:
        """dim times the nodes of the cut mesh (meshing it): the unknowns before supports are removed."""
        points = self.cut()[0].points  # type: ignore[attr-defined]
        return int(points.shape[0]) * int(points.shape[1])

    def extent(self) -> float:
        """The body's largest side (``MIN_SIZE`` is relative to it)."""
        p = self.params  # type: ignore[attr-defined]
        return max(float(p[k]) for k in ("width", "height", "depth") if k in p)

    def later_params(self, params: dict, given: dict, defaults: dict) -> None:
        """A QP's parameters as before the keys added since (:data:`LATER_KEYS`): each dropped at its default
        (so a scene's QP key does not change), then :meth:`adaptive_params`."""
        for k in LATER_KEYS:
            if k in given and given[k] == defaults[k]:
                params.pop(k, None)
        self.adaptive_params(params)

    def adaptive_params(self, params: dict) -> None:
        """``adaptive_steps`` and ``adaptive_estimate`` (the last relative estimate) into a QP's parameters."""
        steps = self.shared.data.get("adaptive")  # type: ignore[attr-defined]
        if steps:
            params["adaptive_steps"], params["adaptive_estimate"] = len(steps), float(steps[-1][1])
