"""Penny-shaped crack against its closed forms, for a list of meshes (the validation of 3D scenes).

    python benchmarks/penny.py [--levels 2:0.25 1.5:0.15 1:0.1] [--solver pdas] [--json out.json]

The scene is the library's ``penny`` (scenes/penny.toml: a disk crack of radius a = 1 at the centre of
a cube of side 10, E = 1000, nu = 0.3, no supports: only the rigid-body motions are removed), each level
``mesh_size:tip_size[:surface_size]``. Three load cases, each by ``remote_stress`` on the free sides:

* tension sigma_zz = sigma = 1: the opening against w(r) = 8 (1 - nu^2) sigma / (pi E) sqrt(a^2 - r^2)
  (Sneddon), relative L2 error over r <= 0.8 a with the nodal areas as weights;
* compression sigma_zz = -1: the largest normal jump over max |x| (closed: ~1e-16) and the mean contact
  pressure sum(mu) / sum(w) against |sigma|;
* compression -1 plus shear sigma_xz = tau = 0.5, delta = 1e3 (free slip): the slip u+_x - u-_x against
  8 (1 - nu) tau / (pi (2 - nu) G) sqrt(a^2 - r^2) (Segedin), relative L2 error over r <= 0.8 a.

The closed forms are for an infinite body: a cube of side 10 a leaves a finite-size effect of ~1-2 %.
Prints one markdown row per level and case (unknowns, defect nodes, times, errors).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

E, NU, A, SIGMA, TAU, C = 1000.0, 0.3, 1.0, 1.0, 0.5, 5.0
G = E / (2 * (1 + NU))


def parse_level(text: str) -> tuple[float, float, float]:
    parts = [float(x) for x in text.split(":")] + [0.0, 0.0]
    return parts[0], parts[1], parts[2]


def _l2(qp, r, value, exact) -> float:
    k = r <= 0.8 * A
    w = qp.weights[k]
    return float(np.sqrt(np.sum(w * (value[k] - exact[k]) ** 2) / np.sum(w * exact[k] ** 2)))


def scene(case: str, h: float, tip: float, surface: float = 0.0) -> dict:
    """The penny scene's parameters for one load case and mesh level."""
    stress = {"tension": [[0, 0, 0], [0, 0, 0], [0, 0, SIGMA]],
              "compression": [[0, 0, 0], [0, 0, 0], [0, 0, -SIGMA]],
              "shear": [[0, 0, TAU], [0, 0, 0], [TAU, 0, -SIGMA]]}[case]
    return {"mesh_size": h, "tip_size": tip, "surface_size": surface, "E": E, "nu": NU, "delta": 1e3,
            "remote_stress": [[float(x) for x in row] for row in stress]}


def errors(case: str, qp, sol) -> dict:
    """The case's errors against the closed forms (module docstring): ``error`` and ``w0_ratio`` (tension) or
    ``closure`` (compression, shear); nothing without an answer."""
    if sol.x is None:
        return {}
    nodes = qp.geometry.nodes
    lo, up = qp.interface.lower, qp.interface.upper
    r = np.hypot(nodes[0, lo] - C, nodes[1, lo] - C)
    root = np.sqrt(np.maximum(A * A - r * r, 0.0))
    jump = qp.B @ sol.x
    closure = float(np.abs(jump).max() / np.abs(sol.x).max())
    if case == "tension":
        w = 8 * (1 - NU ** 2) * SIGMA / (np.pi * E) * root
        return {"error": _l2(qp, r, jump, w), "w0_ratio": float(jump.max() / w.max())}
    if case == "compression":
        return {"closure": closure, "error": float(sol.multipliers.sum() / qp.weights.sum() / SIGMA - 1.0)}
    nd = qp.geometry.node_dofs
    slip = sol.x[nd[0, up]] - sol.x[nd[0, lo]]
    exact = 8 * (1 - NU) * TAU / (np.pi * (2 - NU) * G) * root
    return {"error": _l2(qp, r, slip, exact), "closure": closure}


def solve_case(case: str, h: float, tip: float, solver: str, surface: float = 0.0) -> dict:
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    t0 = time.perf_counter()
    qp = load_scene("penny", scene(case, h, tip, surface)).build()
    t_build = time.perf_counter() - t0
    sol = run(solver, qp)
    t_solve = time.perf_counter() - t0 - t_build
    return {"case": case, "mesh_size": h, "tip_size": tip, "surface_size": surface, "n": qp.n, "m": qp.m,
            "status": str(sol.status), "build_s": t_build, "solve_s": t_solve, **errors(case, qp, sol)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", nargs="+", default=["2:0.25", "1.5:0.15", "1:0.1"],
                    help="mesh levels mesh_size:tip_size[:surface_size] (default: 2:0.25 1.5:0.15 1:0.1)")
    ap.add_argument("--cases", nargs="+", default=["tension", "compression", "shear"],
                    choices=["tension", "compression", "shear"])
    ap.add_argument("--solver", default="pdas")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    a = ap.parse_args(argv)
    rows = []
    print("| case | mesh_size | tip_size | surface_size | unknowns | defect nodes | status | build s | solve s | error "
          "| note |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for text in a.levels:
        h, tip, surface = parse_level(text)
        for case in a.cases:
            row = solve_case(case, h, tip, a.solver, surface)
            rows.append(row)
            what = {"tension": "opening, rel. L2 (r <= 0.8 a)", "compression": "mean pressure / abs(sigma) - 1",
                    "shear": "slip, rel. L2 (r <= 0.8 a)"}[case]
            note = (f"max w / w(0) = {row['w0_ratio']:.3f}" if "w0_ratio" in row else
                    f"max abs(jump) / max abs(x) = {row['closure']:.1e}" if "closure" in row else "")
            err = f"{row['error']:+.4f} ({what})" if "error" in row else "-"
            print(f"| {case} | {h:g} | {tip:g} | {surface:g} | {row['n']:,} | {row['m']:,} | {row['status']} | "
                  f"{row['build_s']:.1f} | {row['solve_s']:.1f} | {err} | {note} |", flush=True)
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
