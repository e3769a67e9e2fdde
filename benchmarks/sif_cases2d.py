"""The 2D row groups of benchmarks/sif.py beyond the centre crack on tip-graded meshes (reports/sif.md).

* ``edge``: a single edge crack of length a in a strip of width b = 1 and height 6 (examples/bodies/edge_crack.geo
  with H = 6 and a set; a body from a file, its mouth on the left side), tension sigma = 1 on both ends (no
  supports), plane strain, E = 1000, nu = 0.3, delta = 1e3, a/b = 0.1, 0.3, 0.5. Tada, Paris & Irwin, The Stress
  Analysis of Cracks Handbook (3rd ed., 2000), single edge notched strip in tension: K_I = F(a/b) sigma sqrt(pi a),
  F(s) = sqrt(2 / (pi s) tan(pi s / 2)) [0.752 + 2.02 s + 0.37 (1 - sin(pi s / 2))^3] / cos(pi s / 2) (stated
  accurate to 0.5 % for any a/b); K_II = 0 (its error against sigma sqrt(pi a)). The one tip is at x = a (the
  mouth, on the boundary, has none). Tip-graded meshes (mesh_size:tip_size levels) and the adaptive loop's meshes
  from the coarsest level (``refine = "adaptive"`` of a body from a geometry file; each step at most 3 x the
  unknowns of the last, up to 40,000).
* ``adaptive``: the centre cracks of benchmarks/sif.py (``griffith``, ``mixed30``, ``closed``) on the meshes of the
  adaptive loop (:func:`dualfem.experiments.adaptive.adapt`, first mesh mesh_size 0.5, tip_size 0.005, each step
  at most 3 x the unknowns of the last, up to 60,000), one row per step.
* ``rings``: the interaction integral's ring on one tip-graded mesh (mesh_size 0.05, tip_size 2e-4, about 25 k
  unknowns): r_out from a/2 (the default for a centre crack: a quarter of its length) down to a/64, r_in = r_out/2:
  whether the integral's domain or the field makes the error.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

E, NU = 1000.0, 0.3
RATIOS = (0.1, 0.3, 0.5)
LEVELS_EDGE = [(0.1, 0.01), (0.05, 0.004), (0.03, 0.0015), (0.02, 0.001)]
ADAPTIVE_CASES = ("griffith", "mixed30", "closed")
ADAPTIVE_BUDGET = 60_000
RING_FRACTIONS = (0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625)
EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "bodies"


def tada_f(s: float) -> float:
    """Tada's F(a/b) of the single edge notched strip in tension."""
    c = math.pi * s / 2
    return math.sqrt(2 / (math.pi * s) * math.tan(c)) * (0.752 + 2.02 * s + 0.37 * (1 - math.sin(c)) ** 3) / math.cos(c)


def edge_problem(s: float, h: float, tip: float, folder: Path):
    """The edge crack a/b = s as a problem (a body from a file), its exact (K_I, K_II) and the scale of a zero K,
    sigma sqrt(pi a)."""
    from dualfem.registry import get_problem

    geo = folder / f"edge_{s:g}.geo"
    text = (EXAMPLES / "edge_crack.geo").read_text().replace("H = 4;", "H = 6;").replace("a = 0.3;", f"a = {s};")
    geo.write_text(text)
    p = get_problem("file_body")(geometry_file=str(geo), mesh_size=h, tip_size=tip, E=E, nu=NU, delta=1e3,
                                 defects=[{"group": "crack"}],
                                 boundary=[{"group": "top", "traction": [0.0, 1.0]},
                                           {"group": "bottom", "traction": [0.0, -1.0]}])
    k0 = math.sqrt(math.pi * s)
    return p, (tada_f(s) * k0, 0.0), k0


def errors(k, exact, k0: float) -> dict:
    """Per mode the values at every tip and the signed relative error of the worse tip (a zero closed form:
    against ``k0``)."""
    out = {}
    for mode, ex in zip(("K_I", "K_II"), exact, strict=True):
        v = getattr(k, mode)
        scale = abs(ex) if abs(ex) > 1e-12 else k0
        out[mode] = v.tolist()
        out[f"{mode}_err"] = float((v - ex)[np.argmax(np.abs(v - ex))] / scale)
    return out


def sif_methods(qp, x, exact, k0: float, methods) -> dict:
    from dualfem.post.sif_outputs import stress_intensity

    res = {}
    for m in methods:
        t1 = time.perf_counter()
        k = stress_intensity(qp, x, m)
        res[m] = {"sif_s": round(time.perf_counter() - t1, 3), **errors(k, exact, k0)}
    return res


def edge_rows(quick: bool, methods) -> list[dict]:
    from dualfem.experiments.runner import make_solver, run

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in (RATIOS[1:2] if quick else RATIOS):
            for h, tip in (LEVELS_EDGE[:1] if quick else LEVELS_EDGE):
                t0 = time.perf_counter()
                pr, exact, k0 = edge_problem(s, h, tip, Path(tmp))
                qp = pr.build()
                sol = run(make_solver("pdas", {}), qp)
                row = {"dim": 2, "group": "edge", "case": f"edge{s:g}", "a_over_b": s, "mesh_size": h,
                       "tip_size": tip, "unknowns": qp.n, "status": str(sol.status), "exact": list(exact),
                       "wall_s": round(time.perf_counter() - t0, 2), "methods": {}}
                if sol.x is not None:
                    row["methods"] = sif_methods(qp, sol.x, exact, k0, methods)
                rows.append(row)
                print(f"edge a/b={s:g} {h:g}:{tip:g} n={qp.n}: interaction K_I "
                      f"{100 * row['methods'].get('interaction', {}).get('K_I_err', float('nan')):+.2f} %", flush=True)
            rows += edge_adaptive(s, Path(tmp), quick, methods)
    return rows


def edge_adaptive(s: float, folder: Path, quick: bool, methods) -> list[dict]:
    """The edge crack a/b = s on the adaptive loop's meshes from its coarsest level (each step at most 3 x)."""
    from dualfem.experiments.adaptive import adapt

    pr, exact, k0 = edge_problem(s, *LEVELS_EDGE[0], folder)
    rows, t0 = [], time.perf_counter()
    for step in adapt(pr, target_error=1e-4, max_unknowns=10_000 if quick else 40_000, max_steps=5, step_growth=3.0):
        rows.append({"dim": 2, "group": "edge", "case": f"edge{s:g}", "a_over_b": s,
                     "mesh": f"adaptive step {step.index}", "mesh_size": LEVELS_EDGE[0][0],
                     "tip_size": LEVELS_EDGE[0][1], "unknowns": step.unknowns,
                     "status": str(step.solution.status), "exact": list(exact),
                     "wall_s": round(time.perf_counter() - t0, 2),
                     "methods": sif_methods(step.qp, step.x, exact, k0, methods)})
        print(f"edge a/b={s:g} adaptive n={step.unknowns}: interaction K_I "
              f"{100 * rows[-1]['methods']['interaction']['K_I_err']:+.2f} %", flush=True)
    return rows


def adaptive_rows(quick: bool, methods, centre) -> list[dict]:
    """``centre(name)``: (scene params of benchmarks/sif.py's centre crack, exact, k0)."""
    from dualfem.experiments.adaptive import adapt
    from dualfem.scene import load_scene

    rows = []
    for name in (ADAPTIVE_CASES[:1] if quick else ADAPTIVE_CASES):
        params, exact, k0 = centre(name)
        t0 = time.perf_counter()
        scene = load_scene("f2", {**params, "mesh_size": 0.5, "tip_size": 0.005})
        for step in adapt(scene, target_error=1e-4, max_unknowns=10_000 if quick else ADAPTIVE_BUDGET, max_steps=8,
                          step_growth=3.0):
            row = {"dim": 2, "group": "adaptive", "case": name, "mesh": f"adaptive step {step.index}",
                   "mesh_size": 0.5, "tip_size": 0.005, "unknowns": step.unknowns,
                   "status": str(step.solution.status), "wall_s": round(time.perf_counter() - t0, 2),
                   "methods": sif_methods(step.qp, step.x, exact, k0, methods)}
            rows.append(row)
            m = row["methods"]["interaction"]
            print(f"adaptive {name} n={step.unknowns}: interaction K_I {100 * m['K_I_err']:+.2f} %, K_II "
                  f"{100 * m['K_II_err']:+.2f} %", flush=True)
    return rows


def ring_rows(quick: bool, build, a: float) -> list[dict]:
    """``build(name, h, tip)``: (qp, exact) of benchmarks/sif.py's centre crack of half-length ``a``."""
    from dualfem.experiments.runner import make_solver, run
    from dualfem.post.sif_integral import interaction

    rows = []
    for name in (("griffith",) if quick else ("griffith", "mixed30")):
        qp, exact = build(name, 0.05, 2e-4)
        sol = run(make_solver("pdas", {}), qp)
        for f in RING_FRACTIONS:
            k = interaction(qp, sol.x, r_out=f * a)
            rows.append({"dim": 2, "group": "rings", "case": name, "r_out_over_a": f, "mesh_size": 0.05,
                         "tip_size": 2e-4, "unknowns": qp.n, "status": str(sol.status), "wall_s": 0.0,
                         "methods": {"interaction": errors(k, exact, math.sqrt(math.pi * a))}})
    return rows
