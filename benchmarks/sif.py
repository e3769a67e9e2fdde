"""Stress intensity factors against their closed forms (dualfem.post.sif): the validation table of docs/sif.md.

    python benchmarks/sif.py --out benchmarks/results/sif --report reports [--quick] [--render-only]
    python benchmarks/sif.py --out benchmarks/results/sif --report reports --only edge,adaptive,rings

Writes ``OUT/runs.jsonl`` (one line per case and mesh level; ``--only GROUPS`` reruns those row groups and keeps
the others' rows: ``centre``, ``edge``, ``adaptive``, ``rings``, ``three_d``) and renders ``REPORT/sif.md`` with
``REPORT/sif/penny_front.png`` (K along the penny's front against Kassir and Sih) from it. Cases (E = 1000,
nu = 0.3, delta = 1e3: the open crack of classical fracture mechanics; solver pdas):

* 2D, a crack of half-length a = 0.05 at the centre of a 5 x 5 square (a/W = 0.01: the finite body shifts K
  by about +0.03 %), ``remote_stress`` uniaxial sigma = 1 at beta to the crack: Griffith (beta = 90 degrees,
  plane strain and plane stress), K_I = sigma sin^2(beta) sqrt(pi a), K_II = sigma sin(beta) cos(beta)
  sqrt(pi a) (beta = 30, 60 degrees); closed: sigma_22 = -1 with shear tau = 0.3, K_I = 0, K_II = tau sqrt(pi a).
* 3D, the library's penny (radius 1 in a cube of side 10, benchmarks/penny.py's load cases): tension,
  K_I = 2 sigma sqrt(a/pi); compression -1 plus shear sigma_xz = tau = 0.5 (closed, frictionless), Kassir and
  Sih's K_II = 4 tau sqrt(a/pi) cos(theta)/(2 - nu), K_III = 4 (1 - nu) tau sqrt(a/pi) sin(theta)/(2 - nu) (the
  sign of e3 = e1 x e2); an ellipse a = 1, b = 0.5 under tension, Irwin's K_I(phi) = sigma sqrt(pi b)/E(k)
  (sin^2 phi + (b/a)^2 cos^2 phi)^(1/4). The cube of side 10 a adds ~1-2 % (benchmarks/penny.py).

* 2D, an edge crack in a strip against Tada (``edge``), the centre cracks on adaptive meshes (``adaptive``) and the
  interaction integral's ring radius (``rings``): benchmarks/sif_cases2d.py.

Errors: 2D, the signed relative error of the worse tip per mode; 3D, the amplitude's error (the least-squares
multiple of the closed form's shape along the front, minus 1) and the largest pointwise error along the front
relative to the closed form's largest value.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

E, NU, A2, W2, TAU2 = 1000.0, 0.3, 0.05, 5.0, 0.3
LEVELS_2D = [(0.5, 5e-4), (0.1, 5e-4), (0.05, 2e-4), (0.02, 1e-4)]
LEVELS_3D = [(2.0, 0.25), (1.0, 0.08), (1.0, 0.05), (0.8, 0.035), (0.6, 0.025), (0.45, 0.015)]
QUICK_2D, QUICK_3D = LEVELS_2D[:2], LEVELS_3D[:1]
METHODS_2D = ("interaction", "fit", "extrapolate")
METHODS_3D = ("interaction", "fit", "extrapolate")


def centre(name: str) -> tuple[dict, tuple[float, float], float]:
    """(scene parameters, exact (K_I, K_II), the scale of a zero K: sigma sqrt(pi a)) of a 2D centre-crack case."""
    beta = {"griffith": 90.0, "griffith_stress": 90.0, "mixed30": 30.0, "mixed60": 60.0}.get(name)
    K0 = np.sqrt(np.pi * A2)
    if beta is None:
        stress, exact = [[-1.0, TAU2], [TAU2, -1.0]], (0.0, TAU2 * K0)
    else:
        c, s = np.cos(np.radians(beta)), np.sin(np.radians(beta))
        stress, exact = [[c * c, s * c], [s * c, s * s]], (s * s * K0, s * c * K0)
    params = {"mesh": "gmsh", "width": W2, "height": W2, "E": E, "nu": NU, "delta": 1e3,
              "plane": "stress" if name.endswith("_stress") else "strain",
              "defects": [{"points": [[W2 / 2 - A2, W2 / 2], [W2 / 2 + A2, W2 / 2]]}], "remote_stress": stress}
    return params, exact, float(K0)


def case_2d(name: str, h: float, tip: float):
    """(qp, exact (K_I, K_II)) of a 2D case."""
    from dualfem.problems.thin_defect import ThinDefect

    params, exact, _ = centre(name)
    return ThinDefect(**params, mesh_size=h, tip_size=tip).build(), exact


def case_3d(name: str, h: float, tip: float):
    """(qp, exact: dict mode -> callable of the front points (k, 3))) of a 3D case."""
    from scipy.special import ellipe

    from dualfem.core.scene import load_scene

    c = np.array([5.0, 5.0, 5.0])
    tension = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    p = {"mesh_size": h, "tip_size": tip, "E": E, "nu": NU, "delta": 1e3}
    if name == "ellipse":
        a, b = 1.0, 0.5
        p.update(remote_stress=tension, defects=[{"shape": "ellipse", "center": c.tolist(), "normal": [0, 0, 1],
                                                  "axes": [a, b], "direction": [1, 0, 0]}])

        def irwin(P):
            phi = np.arctan2((P[:, 1] - c[1]) / b, (P[:, 0] - c[0]) / a)
            return np.sqrt(np.pi * b) / ellipe(1 - (b / a) ** 2) * (np.sin(phi) ** 2 + (b / a) ** 2
                                                                    * np.cos(phi) ** 2) ** 0.25
        exact = {"K_I": irwin}
    elif name == "penny":
        p["remote_stress"] = tension
        exact = {"K_I": lambda P: np.full(len(P), 2 / np.sqrt(np.pi))}
    else:
        tau = 0.5
        p["remote_stress"] = [[0.0, 0.0, tau], [0.0, 0.0, 0.0], [tau, 0.0, -1.0]]
        amp = 4 * tau / np.sqrt(np.pi) / (2 - NU)

        def th(P):
            return np.arctan2(P[:, 1] - c[1], P[:, 0] - c[0])
        exact = {"K_I": lambda P: np.zeros(len(P)), "K_II": lambda P: amp * np.cos(th(P)),
                 "K_III": lambda P: amp * (1 - NU) * np.sin(th(P))}
    return load_scene("penny", p).build(), exact


def run_case(dim: int, name: str, h: float, tip: float) -> dict:
    from dualfem.experiments.runner import make_solver, run
    from dualfem.post.sif_outputs import stress_intensity

    t0 = time.perf_counter()
    qp, exact = (case_2d if dim == 2 else case_3d)(name, h, tip)
    sol = run(make_solver("pdas", {}), qp)
    row = {"dim": dim, "case": name, "mesh_size": h, "tip_size": tip, "unknowns": qp.n, "status": str(sol.status),
           "wall_s": round(time.perf_counter() - t0, 2), "methods": {}}
    if sol.x is None:
        return row
    for m in (METHODS_2D if dim == 2 else METHODS_3D):
        t1 = time.perf_counter()
        k = stress_intensity(qp, sol.x, m)
        out = {"sif_s": round(time.perf_counter() - t1, 3)}
        if dim == 2:
            for mode, ex in zip(("K_I", "K_II"), exact):
                v = getattr(k, mode)
                scale = abs(ex) if abs(ex) > 1e-12 else np.sqrt(np.pi * A2)     # 0: against |sigma| sqrt(pi a)
                out[mode] = v.tolist()
                out[f"{mode}_err"] = float((v - ex)[np.argmax(np.abs(v - ex))] / scale)     # the worse tip, signed
        else:
            for mode, f in exact.items():
                v, ex = getattr(k, mode), f(k.point)
                scale = np.abs(ex).max() if np.abs(ex).max() > 0 else 2 / np.sqrt(np.pi)   # |sigma| 2 sqrt(a/pi)
                # the amplitude's error (least-squares scale of the closed form's shape, minus 1; a zero closed form:
                # the mean of |K|) and the largest pointwise error
                out[f"{mode}_mean_err"] = float(v @ ex / (ex @ ex) - 1) if np.abs(ex).max() > 0 else \
                    float(np.mean(np.abs(v)) / scale)
                out[f"{mode}_max_err"] = float(np.max(np.abs(v - ex)) / scale)
            out["front"] = {"point": k.point.tolist(), "K_I": k.K_I.tolist(), "K_II": k.K_II.tolist(),
                            "K_III": k.K_III.tolist()} if name == "shear" and m in ("interaction", "fit") else None
        row["methods"][m] = out
    return row


GROUPS = ("centre", "edge", "adaptive", "rings", "three_d")


def group_of(row: dict) -> str:
    """The row group of a runs.jsonl row (rows written before the groups: centre in 2D, three_d in 3D)."""
    return row.get("group") or ("centre" if row["dim"] == 2 else "three_d")


def run_group(group: str, quick: bool):
    """Yield the rows of one group."""
    import sif_cases2d as more

    if group in ("centre", "three_d"):
        lv2, lv3 = (QUICK_2D, QUICK_3D) if quick else (LEVELS_2D, LEVELS_3D)
        jobs = [(2, c, h, t) for c in ("griffith", "griffith_stress", "mixed30", "mixed60", "closed") for h, t in lv2] \
            if group == "centre" else [(3, c, h, t) for c in ("penny", "shear", "ellipse") for h, t in lv3]
        for job in jobs:
            row = run_case(*job)
            print(f"{job}: {row['unknowns']} unknowns, {row['wall_s']} s", file=sys.stderr)
            yield row
    elif group == "edge":
        yield from more.edge_rows(quick, METHODS_2D)
    elif group == "adaptive":
        yield from more.adaptive_rows(quick, METHODS_2D, centre)
    else:
        yield from more.ring_rows(quick, case_2d, A2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/sif")
    ap.add_argument("--report", default="reports")
    ap.add_argument("--quick", action="store_true", help="the coarse levels only")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--only", default=",".join(GROUPS), help="comma-separated row groups to run (the others' rows "
                    f"are kept from OUT/runs.jsonl): {', '.join(GROUPS)}")
    args = ap.parse_args(argv)
    only = [g.strip() for g in args.only.split(",") if g.strip()]
    bad = [g for g in only if g not in GROUPS]
    if bad:
        ap.error(f"--only: unknown group(s) {', '.join(bad)}; groups: {', '.join(GROUPS)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = out / "runs.jsonl"
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if not args.render_only:
        old = [json.loads(line) for line in runs.read_text().splitlines() if line.strip()] if runs.exists() else []
        kept = [r for r in old if group_of(r) not in only]
        with runs.open("w") as fh:
            for row in kept:
                fh.write(json.dumps(row) + "\n")
            for g in GROUPS:
                if g in only:
                    for row in run_group(g, args.quick):
                        fh.write(json.dumps(row) + "\n")
                        fh.flush()
    from sif_report import render

    for path in render([json.loads(line) for line in runs.read_text().splitlines() if line.strip()],
                       Path(args.report), " ".join(["python", "benchmarks/sif.py", *(argv or sys.argv[1:])])):
        print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
