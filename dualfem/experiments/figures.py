"""The runs behind ``reports/figures.md``: the solutions pictured and the Uzawa histories.

Runs only; :mod:`dualfem.reports.figures` draws and writes. The figures need whole fields, so
:func:`collect` returns the scenes' QPs and the solvers' :class:`~dualfem.core.solution.Solution`
objects (keyed by scene, delta and solver, in a :class:`Cases` frozen once the study is done: the
renderer can only look answers up, never solve) together with the plain numbers of the report's
tables, and the scenes of the library (``scenes/*.toml``: gmsh meshes, inclined, curved, kinked
and several defects) solved once each. Solutions of the pictures come from the one reference
policy's first installed exact candidate (:func:`dualfem.experiments.reference.candidates`)
unless a solver is named; the convergence histories come from the paper's method
(:data:`dualfem.experiments.paper.PAPER_SOLVER`) and from every other registered solver that
records a per-iteration history. The paper's scenes and solver are named in
:mod:`dualfem.experiments.paper`.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import get_solver, solvers
from dualfem.core.scene import DEFAULT_SCENE, library, load_scene
from dualfem.experiments.paper import LOADS, PAPER_FIGURES, PAPER_SCENE, PAPER_SOLVER
from dualfem.experiments.reference import candidates
from dualfem.experiments.runner import run
from dualfem.experiments.workspace import Workspace
from dualfem.post.fields import Post
from dualfem.post.figures import history_series

#: deltas of the jump / pressure / history figures (the paper's range)
SWEEP = (1e-1, 1e-3, 1e-5, 1e-7, 1e-9)
#: (scene, delta, caption) of the deformed-body pictures (paper Figs 2, 3, 4, 7)
DEFORMED = PAPER_FIGURES
#: radius around the defect tips for the "stress at the tips" column (triangle centroids)
TIP_RADIUS = 0.05
#: history quantity per solver, first one found in the solver's history rows
HISTORY_KEYS = ("dual_change", "residual", "grad", "complementarity", "primal")
#: deltas at which the other solvers' histories are drawn, with their line styles
OTHER_DELTAS = ((1e-5, "-"), (1e-9, "--"))


def history_key(sol) -> str | None:
    """The first key of :data:`HISTORY_KEYS` present in ``sol.history``."""

    for key in HISTORY_KEYS:
        if history_series(sol, key) is not None:
            return key
    return None


def solvers_with_history(exclude=(), probe_N: int = 8) -> list[str]:
    """Registered, installed solvers that record a per-iteration history (a key of
    :data:`HISTORY_KEYS`), found by one solve of a tiny default scene (N = ``probe_N``): libraries
    without a history are not run at full size just to find that out."""

    qp = load_scene(DEFAULT_SCENE, {"N": probe_N, "delta": 1e-5}).build()
    out = []
    for name, cls in sorted(solvers().items()):
        if name in exclude or cls.missing() is not None:
            continue
        if history_key(run(name, qp)) is not None:
            out.append(name)
    return out


def picture_solver(name: str | None = None) -> str:
    """``name`` if given (an installed solver), else the reference policy's first exact candidate."""

    if name is not None:
        cls = get_solver(name)
        if cls.missing():
            raise InputError(cls.missing())
        return name
    names = [n for n, _ in candidates()]
    if not names:
        raise InputError("no exact reference solver (a solver declaring Solver.reference) is registered and installed")
    return names[0]


class Cases:
    """Solve each (scene, delta) once with a given solver and remember the QP and the result.

    :meth:`freeze` ends the study: afterwards :meth:`qp` and :meth:`solution` only look up what
    was solved (a missing case raises), so whoever reads the results cannot run a solver."""

    def __init__(self, N: int, progress: Callable[[str], None]):
        self.N = N
        self.progress = progress
        self.qps: dict = {}
        self.spaces: dict[str, Workspace] = {}
        self.sols: dict = {}
        self.frozen = False

    def freeze(self) -> Cases:
        """No more builds or solves: the results are final (returns self)."""
        self.frozen = True
        return self

    def _missing(self, what: str):
        raise RuntimeError(f"{what} is not among the study's results (dualfem.experiments.figures.collect)")

    def qp(self, scene: str, delta: float):

        key = (scene, delta)
        if key not in self.qps:
            if self.frozen:
                self._missing(f"the QP of {scene} at delta={delta:g}")
            if scene not in self.spaces:           # the deltas of a scene share its assembly and factorization
                self.spaces[scene] = Workspace(scene, {"N": self.N})
            self.qps[key] = self.spaces[scene].update(delta=delta).qp
        return self.qps[key]

    def solution(self, solver: str, scene: str, delta: float):
        """The stored Solution of ``solver`` on (scene, delta); never solves."""
        key = (solver, scene, delta)
        if key not in self.sols:
            self._missing(f"the solution of {solver} on {scene} at delta={delta:g}")
        return self.sols[key]

    def solve(self, solver: str, scene: str, delta: float, require_x: bool = False):
        """The Solution of ``solver`` (cached); ``require_x``: raise if it has no x (a pictured solve)."""

        key = (solver, scene, delta)
        if key not in self.sols:
            if self.frozen:
                self._missing(f"the solution of {solver} on {scene} at delta={delta:g}")
            t0 = time.perf_counter()
            self.sols[key] = sol = run(solver, self.qp(scene, delta))
            self.progress(f"{scene} delta={delta:g} {solver}: {sol.status} {sol.iterations} "
                          f"({time.perf_counter() - t0:.1f} s)")
        sol = self.sols[key]
        if require_x and sol.x is None:
            raise RuntimeError(f"{scene} delta={delta:g}: solver {solver} returned no solution "
                               f"({sol.status}: {sol.message})")
        return sol


def picture_row(qp, sol, scene: str, delta: float, caption: str) -> dict:
    """Numbers of one pictured solution: max von Mises (MPa) overall and near the tips, max normal
    jump, closed defect nodes, total contact force (force per unit thickness), KKT error."""

    p = Post(qp, sol)
    tips = qp.geometry.nodes[:, qp.interface.front]
    cen = p.nodes[:, p.triangles].mean(axis=1)
    near = np.min(np.linalg.norm(cen[:, :, None] - tips[:, None, :], axis=0), axis=1) < TIP_RADIUS
    return {"scene": scene, "delta": delta, "caption": caption, "von_mises": float(p.von_mises.max()),
            "von_mises_tips": float(p.von_mises[near].max()) if near.any() else float("nan"),
            "max_jump": float(p.defect["jump_normal"].max()), "closed": int(evaluator.contact_set(qp, sol.x).sum()),
            "m": qp.m, "total_force": float(sol.multipliers.sum()), "kkt": evaluator.kkt_error(sol.residuals)}


def scene_deltas(params: dict) -> list[float]:
    """The fracture parameters of a scene's defects (the scene's delta unless a defect has its own)."""
    tables = params.get("defects") or []
    if not tables:
        return [float(params["delta"])]
    return [float(t.get("delta", params["delta"])) for t in tables]


def scene_caption(path) -> str:
    """The leading comment block of a scene file, as one line (its description)."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# ").strip())
    return " ".join(x for x in lines if x)


def library_runs(solver: str, progress: Callable[[str], None], overrides: dict | None = None,
                 names: list[str] | None = None) -> list[dict]:
    """Each scene of the library (``scenes/*.toml``) solved by ``solver`` at its own mesh size (or
    with ``overrides``, e.g. a coarser ``mesh_size`` for tests): QP, Solution and a picture row
    with the number of defects, their deltas, the unknowns and the solve time."""

    lib = library(dim=2)               # the 2D scenes (3D scenes have no picture here yet)
    unknown = sorted(set(names or ()) - set(lib))
    if unknown:
        raise InputError(f"unknown library scene {unknown[0]!r}; the library has {', '.join(lib) or 'none'}")
    out = []
    for name in names or list(lib):
        prob = load_scene(name, dict(overrides or {}))
        t0 = time.perf_counter()
        qp = prob.build()
        t_build = time.perf_counter() - t0
        sol = run(solver, qp)
        t_solve = time.perf_counter() - t0 - t_build
        progress(f"scene {name}: {qp.n} unknowns, {sol.status} ({t_build:.1f} s build, {t_solve:.1f} s solve)")
        if sol.x is None:
            raise RuntimeError(f"library scene {name}: solver {solver} returned no solution "
                               f"({sol.status}: {sol.message})")
        deltas = scene_deltas(prob.params)
        row = picture_row(qp, sol, name, deltas[0], scene_caption(lib[name]))
        row.update({"deltas": deltas, "defects": len(deltas), "n": qp.n, "status": str(sol.status),
                    "mesh": prob.params.get("mesh"), "mesh_size": prob.params.get("mesh_size"),
                    "tip_size": prob.params.get("tip_size"), "build_s": t_build, "solve_s": t_solve,
                    "closed_per_defect": [int(c) for c in np.bincount(
                        qp.interface.defect_id, weights=evaluator.contact_set(qp, sol.x), minlength=len(deltas))],
                    "nodes_per_defect": [int(c) for c in np.bincount(qp.interface.defect_id, minlength=len(deltas))]})
        out.append({"name": name, "qp": qp, "sol": sol, "row": row})
    return out


def method_runs(cases: Cases, exact: str, sweep, method: str = PAPER_SOLVER) -> dict:
    """The paper's method on its loads at every delta of ``sweep``: iteration counts and its agreement
    with ``exact``."""

    counts, agree = {}, []
    for scene in LOADS:
        for d in sweep:
            s = cases.solve(method, scene, d)
            counts[(scene, d)] = {"outer": s.iterations.get("outer", "?"), "inner": s.iterations.get("inner", "?"),
                                  "ok": s.ok, "status": str(s.status)}
            ref = cases.solve(exact, scene, d) if s.x is not None else None
            if ref is not None and ref.x is not None and exact != method:
                c = evaluator.compare(cases.qp(scene, d), s.x, s.multipliers, ref.x, ref.multipliers)
                agree.append({"scene": scene, "delta": d, "x_energy": c["x_energy"], "multipliers": c["multipliers"],
                              "contact_mismatch": c["contact_mismatch"]})
    return {"counts": counts, "agree": agree}


def other_runs(cases: Cases, others: list[str]) -> dict:
    """The other history solvers on the paper's loads at :data:`OTHER_DELTAS`: which key each records."""
    measures: dict[str, str] = {}
    no_hist: set[str] = set()
    for scene in LOADS:
        for name in others:
            for d, _ in OTHER_DELTAS:
                key = history_key(cases.solve(name, scene, d))
                if key is None:
                    no_hist.add(name)
                else:
                    measures[name] = key
    return {"measures": measures, "no_history": sorted(no_hist - set(measures))}


def collect(N: int = 64, solver: str | None = None, sweep=SWEEP, history_solvers: list[str] | None = None,
            progress: Callable[[str], None] = print, scenes: bool = True,
            scene_overrides: dict | None = None) -> dict:
    """Every solve the figures report needs (see the module docstring); ``scenes``: the scene
    library too (:func:`library_runs`, with ``scene_overrides``). ``data["method"]`` holds the
    paper's method's runs (None if that solver is not registered); ``data["cases"]`` is frozen."""

    exact = picture_solver(solver)
    cases = Cases(N, progress)
    rows = [picture_row(cases.qp(sc, d), cases.solve(exact, sc, d, True), sc, d, cap) for sc, d, cap in DEFORMED]
    for d in sweep:
        cases.solve(exact, PAPER_SCENE, d, True)
    for d in (1e-1, 1e-5):         # the faces figure (paper Fig. 6)
        cases.solve(exact, PAPER_SCENE, d, True)
    data = {"N": N, "exact": exact, "sweep": list(sweep), "rows": rows, "cases": cases, "method": None,
            "scene": PAPER_SCENE, "loads": list(LOADS),
            "scenes": library_runs(exact, progress, scene_overrides) if scenes else []}
    reg = solvers()
    method = PAPER_SOLVER
    if method in reg:
        others = history_solvers if history_solvers is not None else solvers_with_history(exclude=(method,))
        data["method"] = {"solver": method, "defaults": dict(reg[method].defaults), "others": list(others),
                          **method_runs(cases, exact, sweep, method), **other_runs(cases, others)}
        if history_solvers is None:
            installed = {n for n, c in reg.items() if c.missing() is None}
            data["method"]["no_history"] = sorted(set(data["method"]["no_history"])
                                                  | (installed - set(others) - {method}))
    cases.freeze()
    return data
