"""The runs behind ``reports/paper_tables.md``: the paper's Tables 1-3 with dualfem's ``uzawa``.

Runs only; :mod:`dualfem.reports.paper` renders. Everything returned is plain JSON-able data
(saved to ``reports/paper_tables.json`` by the report command), so the report can be re-rendered
without re-running (``dualfem report paper --render-only``).

* :func:`tables`: ``uzawa`` with the paper's settings (r = 1e7, tol_outer = 1e-5, tol_inner = 1e-7,
  Armijo step divided by 2 or 1.1) on every cell of Tables 1-3, for each mesh size N and plane
  assumption; one record per distinct run.
* :func:`auto`: ``uzawa_auto`` on the Table 2 cells for one setting.
* :func:`inner_norms`: the same Table 1 cells with four variants of the *inner* (Newton) stop test
  (see :data:`INNER_VARIANTS`), to measure how the count m depends on that test alone.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

from dualfem.experiments.runner import run
from dualfem.experiments.workspace import Workspace

# ---------------------------------------------------------------- the paper's names, in one place
# The report studies that reproduce the paper (this module, :mod:`dualfem.experiments.figures`) and
# their renderers take every scene and solver name of the paper from here.
#: the paper's three loads (presets of the thin_defect problem plugin)
LOADS = ("f1", "f2", "f3")
#: the scene of the paper's Tables 2-3 and Figs 3-6
PAPER_SCENE = "f2"
#: the load that pulls the faces apart (the first Uzawa iteration ends the method: m = k = 1)
OPEN_LOAD = "f3"
#: the paper's method (solver plugin) and the same method with r taken from the QP (its remedy for small delta)
PAPER_SOLVER = "uzawa"
REMEDY_SOLVER = "uzawa_auto"
#: (scene, delta, caption) of the deformed-body pictures (paper Figs 2, 3, 4, 7)
PAPER_FIGURES = (("f1", 1e-5, "Fig. 2: f1 (pressing down), faces closed"),
                 ("f2", 1e-7, "Fig. 3 (left): f2, delta = 1e-7, faces nearly glued"),
                 ("f2", 1e-5, "Fig. 3 (right): f2, delta = 1e-5, a stress concentrator at the crack tip"),
                 ("f2", 1e-1, "Fig. 4: f2, delta = 1e-1, a crack"),
                 ("f3", 1e-1, "Fig. 7: f3 (pulling up), faces fully apart"))

# The paper's tables (Zhiltsov & Maksimova 2023, section 5): (k_MU, m_MN)
PAPER_T1 = {("f1", 1e-7): (18, 24), ("f1", 1e-5): (22, 33), ("f1", 1e-1): (23, 28),
            ("f2", 1e-7): (22, 24), ("f2", 1e-5): (11, 16), ("f2", 1e-1): (19, 24),
            ("f3", 1e-7): (1, 2), ("f3", 1e-5): (1, 2), ("f3", 1e-1): (1, 2)}
DELTAS = [1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9]
PAPER_T2 = dict(zip(DELTAS, zip([26, 21, 19, 17, 15, 50, 18, 111, 899], [32, 27, 26, 22, 21, 53, 20, 112, 900])))
PAPER_T3 = dict(zip(DELTAS, zip([8, 12, 8, 11, 10, 11, 19, 121, 888], [13, 17, 13, 16, 15, 14, 21, 122, 889])))
T1_DELTAS = [1e-7, 1e-5, 1e-1]
PAPER_TOL_INNER = 1e-7
#: the paper's outer stop: max_j |l^{k+1}_j - l^k_j| <= 1e-5 in stress units (MPa), an absolute test
PAPER_OUTER = {"tol_mode": "absolute", "tol": 1e-5}

#: the inner stop tests compared by :func:`inner_norms`: name -> (uzawa parameters, description).
#: The paper prints ||t^{m+1} - t^m|| / ||t^{m+1}|| < 1e-7 in the norm of V^h. ``uzawa`` measures it
#: in the energy norm (x'Kx, its default) or the Euclidean norm (``inner_norm="euclidean"``, which
#: needs ``linalg="full"``). Testing the ratio of the *squared* norms against 1e-7 is the same as
#: testing the ratio of the norms against sqrt(1e-7): that variant needs no solver change, only
#: ``tol_inner = sqrt(1e-7)``.
INNER_VARIANTS: dict[str, tuple[dict, str]] = {
    "energy": ({"linalg": "reduced", "inner_norm": "energy", "tol_inner": PAPER_TOL_INNER},
               "energy norm, ratio < 1e-7 (dualfem's default)"),
    "euclidean": ({"linalg": "full", "inner_norm": "euclidean", "tol_inner": PAPER_TOL_INNER},
                  "Euclidean norm, ratio < 1e-7"),
    "energy_sq": ({"linalg": "reduced", "inner_norm": "energy", "tol_inner": math.sqrt(PAPER_TOL_INNER)},
                  "energy norm, squared ratio < 1e-7"),
    "euclidean_sq": ({"linalg": "full", "inner_norm": "euclidean", "tol_inner": math.sqrt(PAPER_TOL_INNER)},
                     "Euclidean norm, squared ratio < 1e-7"),
}

Progress = Callable[[str], None] | None


def fmt_delta(d: float) -> str:
    return f"1e{int(round(math.log10(d)))}"


def cells() -> list[tuple[str, str, float, float]]:
    """(table, load, delta, Armijo step factor) of every cell of Tables 1-3."""
    out = [("T1", load, d, 2.0) for load in LOADS for d in T1_DELTAS]
    out += [("T2", PAPER_SCENE, d, 2.0) for d in DELTAS] + [("T3", PAPER_SCENE, d, 1.1) for d in DELTAS]
    return out


class _Meshes:
    """One :class:`~dualfem.experiments.workspace.Workspace` per (N, plane), the last one only: the
    loads and deltas of a table are updates of its assembly and factorization."""

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.ws: Workspace | None = None

    def qp(self, load: str, N: int, delta: float, plane: str):
        if self.key != (N, plane) or self.ws is None:
            self.key, self.ws = (N, plane), Workspace(load, {"N": N, "plane": plane})
        return self.ws.update(delta=delta, load=load).qp


def _run(load: str, N: int, delta: float, plane: str, solver: str, params: dict,
         meshes: _Meshes | None = None) -> dict:
    qp = (meshes or _Meshes()).qp(load, N, delta, plane)
    t0 = time.perf_counter()
    sol = run(solver, qp, params)
    steps = [s for h in sol.history for s in h.get("steps", [])]
    return {"k": sol.iterations.get("outer"), "m": sol.iterations.get("inner"), "status": str(sol.status),
            "time": time.perf_counter() - t0, "steps": len(steps), "short_steps": sum(s < 1 for s in steps)}


def tables(Ns, planes, solver: str = PAPER_SOLVER, progress: Progress = None) -> list[dict]:
    """One record {N, plane, load, delta, factor, k, m, status, time, steps, short_steps} per distinct run."""
    out: dict[tuple, dict] = {}
    todo = cells()
    total, done = len(Ns) * len(planes) * len(todo), 0
    meshes = _Meshes()
    for N in Ns:
        for plane in planes:
            for table, load, d, factor in todo:
                key = (N, plane, load, d, factor)
                if key not in out:
                    out[key] = {"N": N, "plane": plane, "load": load, "delta": d, "factor": factor,
                                **_run(load, N, d, plane, solver, {"step_factor": factor, **PAPER_OUTER}, meshes)}
                done += 1
                if progress:
                    r = out[key]
                    progress(f"[{done}/{total}] N={N} {plane} {table} {load} delta={fmt_delta(d)}: "
                             f"k={r['k']} m={r['m']} {r['status']}")
    return list(out.values())


def index(records: list[dict]) -> dict[tuple, dict]:
    """{(N, plane, load, delta, factor): record} of :func:`tables` records."""
    return {(r["N"], r["plane"], r["load"], r["delta"], r["factor"]): r for r in records}


def distance(res: dict[tuple, dict], N: int, plane: str) -> float:
    """Mean |log10(k_ours / k_paper)| over all 27 cells of Tables 1-3 (outer counts)."""
    errs = [abs(math.log10(res[(N, plane, load, d, 2.0)]["k"] / k)) for (load, d), (k, _) in PAPER_T1.items()]
    for tab, f in ((PAPER_T2, 2.0), (PAPER_T3, 1.1)):
        errs += [abs(math.log10(res[(N, plane, PAPER_SCENE, d, f)]["k"] / k)) for d, (k, _) in tab.items()]
    return sum(errs) / len(errs)


def closest(records: list[dict]) -> tuple[int, str]:
    """The (N, plane) whose outer counts are closest to the paper's (smallest :func:`distance`)."""
    res = index(records)
    settings = sorted({(r["N"], r["plane"]) for r in records})
    return min(settings, key=lambda s: (round(distance(res, *s), 3), s))


def auto(N: int, plane: str, progress: Progress = None) -> list[dict]:
    """:data:`REMEDY_SOLVER` on :data:`PAPER_SCENE` at every delta of Table 2: records {delta, k, m, status, ...}."""
    out, meshes = [], _Meshes()
    for d in DELTAS:
        out.append({"delta": d, **_run(PAPER_SCENE, N, d, plane, REMEDY_SOLVER, {}, meshes)})
        if progress:
            progress(f"{REMEDY_SOLVER} N={N} {plane} delta={fmt_delta(d)}: k={out[-1]['k']} m={out[-1]['m']}")
    return out


def inner_norms(Ns, plane: str = "strain", variants=tuple(INNER_VARIANTS), progress: Progress = None) -> list[dict]:
    """Table 1 cells (f1/f2/f3 x three delta, step factor 2) with each inner stop test of
    :data:`INNER_VARIANTS`; records {N, plane, load, delta, variant, k, m, status, time, ...}."""
    out, meshes = [], _Meshes()
    for N in Ns:
        for load in LOADS:
            for d in T1_DELTAS:
                for v in variants:
                    out.append({"N": N, "plane": plane, "load": load, "delta": d, "variant": v,
                                **_run(load, N, d, plane, PAPER_SOLVER, {"step_factor": 2.0, **PAPER_OUTER,
                                                                    **INNER_VARIANTS[v][0]}, meshes)})
                    if progress:
                        progress(f"inner test {v}: N={N} {load} delta={fmt_delta(d)}: "
                                 f"k={out[-1]['k']} m={out[-1]['m']} {out[-1]['status']}")
    return out


def collect(Ns, planes, inner_Ns=None, progress: Progress = None) -> dict:
    """Everything the report shows, as one JSON-able dict (see the module docstring)."""
    t0 = time.perf_counter()
    recs = tables(Ns, planes, progress=progress)
    N_best, plane_best = closest(recs)
    data = {"Ns": list(Ns), "planes": list(planes), "tables": recs,
            "auto": {"N": N_best, "plane": plane_best, "runs": auto(N_best, plane_best, progress)}}
    inner_Ns = [n for n in Ns if n <= 128] if inner_Ns is None else list(inner_Ns)
    data["inner"] = {"plane": plane_best, "variants": {k: v[1] for k, v in INNER_VARIANTS.items()},
                     "runs": inner_norms(inner_Ns, plane_best, progress=progress)}
    data["elapsed_s"] = time.perf_counter() - t0
    return data
