"""The 3D part of benchmarks/accuracy.py: the penny and an elliptic crack (b/a = 0.5) under tension.

A crack of semi-axes a = 1 and b (b = a: the penny) at the centre of a cube of side L, E = 1000, nu = 0.3,
delta = 1e3, the remote tension sigma_zz = 1 on the free sides (no support: the rigid-body motions removed).
Irwin's (Green & Sneddon's) opening: w = 4 (1 - nu^2) sigma b / (E E(k)) sqrt(1 - x^2/a^2 - y^2/b^2),
E(k) the complete elliptic integral of the second kind, k^2 = 1 - b^2 / a^2 (Sneddon's penny for b = a). Error:
the opening's relative L2 error over rho = sqrt(x^2/a^2 + y^2/b^2) <= 0.8 (the nodal areas as weights). The box's
bias: the fitted factor s_L on one mesh (mesh_size 2 a, tip_size 0.1 a, size_growth 0.3) for L = 10 a, 20 a,
40 a; errors against s_L / s_40 times the closed form. The energy-norm error ||u - u_h|| = sqrt(2 (Pi_h - Pi))
relative to the crack's part sqrt(2 W): Pi = Pi_0 - W, Pi_0 the uncracked cube's energy (exact for P1),
W = pi a b sigma w_0 / 3 the crack's energy (w_0 the closed-form opening at the centre; the penny's
8 (1 - nu^2) sigma^2 a^3 / (3 E)) times s_L / s_40; the estimator's effectivity index eta / ||u - u_h|| on every
mesh. Discretizations: uniform (mesh_size = tip_size = h),
graded (mesh_size 2 a, tip_size halved from 0.2 a) with size_growth 0.3 and 0.1, adaptive (the steps of
:func:`dualfem.experiments.adaptive.adapt` from mesh_size 2 a, tip_size 0.25 a, step_growth 3; time: the steps
so far, each with its estimate and certification; full run: to 150 k unknowns), ``P2 graded 0.3`` (quadratic
tetrahedra, ``element = "P2"``:
mesh_size 2 a, tip_size halved from 0.4 a, size_growth 0.3; ``P2 graded 0.5``: size_growth 0.5, tip_size 0.1 a ...
0.02 a; the opening's error at every defect pair, vertices
and mid-edge nodes, with their weights). Time: meshing, assembly, factorization and solve (``time_s``);
``total_s`` adds the certification.

    python benchmarks/accuracy_3d.py --report reports     # the 3D rows only, the 2D rows of accuracy.json kept
    python benchmarks/accuracy_3d.py --report reports --p2-only       # the P2 rows alone, the rest kept
    python benchmarks/accuracy_3d.py --report reports --merge-only    # reports/accuracy/three_d.json into it
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.special import ellipe

E, NU = 1000.0, 0.3
CRACKS = {"penny": 1.0, "ellipse": 0.5}          # b / a
BOXES3 = (10.0, 20.0, 40.0)
P2_TIPS = (0.4, 0.2, 0.1, 0.05)
#: P2 on meshes that grow faster away from the front (size_growth 0.5) and are finer at it: per unknown the better
#: of the two on the ellipse (measured: 0.86 % at 138 k against 1.15 % at 132 k with size_growth 0.3)
P2_TIPS_05 = (0.1, 0.05, 0.035, 0.025, 0.02)


def scene3(crack: str, L: float, **mesh):
    from dualfem.scene import load_scene

    b = CRACKS[crack]
    c = [L / 2] * 3
    shape = {"shape": "disk", "center": c, "normal": [0.0, 0.0, 1.0], "radius": 1.0} if b == 1.0 else \
        {"shape": "ellipse", "center": c, "normal": [0.0, 0.0, 1.0], "axes": [1.0, b], "direction": [1.0, 0.0, 0.0]}
    return load_scene("penny", {"width": L, "depth": L, "height": L, "E": E, "nu": NU, "delta": 1e3,
                                "remote_stress": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                                "defects": [shape], **mesh})


def opening(crack: str, L: float, qp, x) -> tuple[float, float]:
    """(relative L2 error of the opening over rho <= 0.8, fitted factor computed / closed form)."""
    b = CRACKS[crack]
    nodes = qp.geometry.nodes
    lo = qp.interface.lower
    X, Y = nodes[0, lo] - L / 2, nodes[1, lo] - L / 2
    rho = np.sqrt(X ** 2 + (Y / b) ** 2)
    exact = 4 * (1 - NU ** 2) * b / (E * ellipe(1 - b * b)) * np.sqrt(np.maximum(1 - rho ** 2, 0.0))
    jump = qp.B @ x
    k = rho <= 0.8
    w = qp.weights[k]
    fit = float(np.sum(w * jump[k] * exact[k]) / np.sum(w * exact[k] ** 2))
    return float(np.sqrt(np.sum(w * (jump[k] - exact[k]) ** 2) / np.sum(w * exact[k] ** 2))), fit


def energy3(crack: str, L: float, qp, x, scale: float) -> tuple[float, float]:
    """(||u - u_h|| in the energy norm, the same relative to the crack's part sqrt(2 W)), W times ``scale``."""
    b = CRACKS[crack]
    w0 = 4 * (1 - NU ** 2) * b / (E * ellipe(1 - b * b))            # the opening at the centre, sigma = 1
    W = scale * np.pi * b * w0 / 3
    pi_exact = -0.5 * L ** 3 / E - W                                  # sigma_zz = 1: sigma : C^-1 sigma = 1 / E
    e2 = 2 * (-0.5 * float(qp.F @ x) - pi_exact)
    e = float(np.sqrt(e2)) if e2 > 0 else float("nan")
    return e, e / float(np.sqrt(2 * W))


def errors3(crack: str, L: float, qp, x, eta: float, scale: float) -> dict:
    """The row's errors: opening (relative L2), energy (absolute, relative), the effectivity eta / energy."""
    err, fit = opening(crack, L, qp, np.asarray(x) / scale)
    e, rel = energy3(crack, L, qp, x, scale)
    return {"jump_error": err, "fit": fit, "energy_error": e, "energy_rel": rel, "effectivity": eta / e}


def row3(crack: str, L: float, pr, scale: float, label: str) -> dict:
    from dualfem.experiments.runner import run
    from dualfem.numerics.estimator import estimate

    t0 = time.perf_counter()
    qp = pr.build()
    t1 = time.perf_counter()
    sol = run("pdas", qp)
    t_total = time.perf_counter() - t0
    if qp.geometry.element == "P1":     # the estimator is P1's in 3D (P2 tetrahedra: no estimate, no effectivity)
        est = estimate(qp, sol.x, sol.multipliers)
        eta, eta_rel = est.eta, est.relative
    else:
        eta = eta_rel = float("nan")
    return {"case": crack, "disc": label, "L": L, "unknowns": int(qp.n), "status": str(sol.status),
            "time_s": t1 - t0 + sol.time_s.get("setup", 0) + sol.time_s.get("solve", 0),
            "total_s": t_total, "eta": eta, "eta_rel": eta_rel, **errors3(crack, L, qp, sol.x, eta, scale),
            **(penny_k(qp, sol.x, scale) if crack == "penny" and qp.geometry.element == "P2" else {})}


def penny_k(qp, x, scale: float) -> dict:
    """K_I along the penny's front (interaction integral, :func:`dualfem.post.sif_integral3d.interaction3d`) against
    2 sigma sqrt(a / pi): the mean and the largest pointwise relative error, against the closed form (``_raw``) and
    against it times the box's bias ``scale`` (= s_10 / s_40 of the opening), and the seconds it took."""
    from dualfem.post.sif_integral3d import interaction3d

    t0 = time.perf_counter()
    k = interaction3d(qp, x).K_I / (2 / np.sqrt(np.pi))
    return {"k_amp_raw": float(k.mean() - 1), "k_worst_raw": float(np.abs(k - 1).max()),
            "k_amp": float(k.mean() / scale - 1), "k_worst": float(np.abs(k / scale - 1).max()),
            "k_s": time.perf_counter() - t0}


def p2_levels(n: int) -> list[tuple[str, float, float]]:
    """(label, size_growth, tip_size) of the P2 rows: ``n`` levels of size_growth 0.3, ``n + 1`` of 0.5."""
    return [("P2 graded 0.3", 0.3, t) for t in P2_TIPS[:n]] + [("P2 graded 0.5", 0.5, t) for t in P2_TIPS_05[:n + 1]]


def study3(crack: str, quick: bool, p2_only: bool = False, bias: dict | None = None) -> tuple[dict, list[dict]]:
    """The bias per box (measured, or ``bias`` {L: s_L} as given) and the rows of every discretization (``p2_only``:
    of P2 alone)."""
    if bias is None:
        bias = {}
        for L in BOXES3:
            bias[L] = row3(crack, L, scene3(crack, L, mesh_size=2.0, tip_size=0.1), 1.0, "bias")["fit"]
            print(f"bias {crack} L={L:g}: s_L = {bias[L]:.5f}", flush=True)
    ref = bias[10.0] / bias[BOXES3[-1]]
    rows = []
    n = 2 if quick else 4
    if p2_only:
        for label, growth, tip in p2_levels(n):
            rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=2.0, tip_size=tip, size_growth=growth,
                                                 element="P2"), ref, label))
            r = rows[-1]
            print(f"{crack} {r['disc']} n={r['unknowns']} opening={r['jump_error']:.2e} t={r['time_s']:.1f}s "
                  f"total={r['total_s']:.1f}s", flush=True)
        return {str(k): v for k, v in bias.items()}, rows
    for h in (1.0, 0.7, 0.5, 0.35)[:n]:
        rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=h, tip_size=h), ref, "uniform"))
    for growth, tips in ((0.3, (0.2, 0.1, 0.05, 0.025)[:n]), (0.1, (0.2, 0.1, 0.05)[:n - 1])):
        for tip in tips:
            rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=2.0, tip_size=tip, size_growth=growth),
                             ref, f"graded {growth:g}"))
    for label, growth, tip in p2_levels(n):
        rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=2.0, tip_size=tip, size_growth=growth,
                                             element="P2"), ref, label))
    from dualfem.experiments.adaptive import adapt

    t0 = time.perf_counter()
    start = scene3(crack, 10.0, mesh_size=2.0, tip_size=0.25)
    for step in adapt(start, target_error=1e-4, max_unknowns=15_000 if quick else 150_000, max_steps=7,
                      step_growth=3.0):
        rows.append({"case": crack, "disc": "adaptive", "L": 10.0, "unknowns": step.unknowns,
                     "status": str(step.solution.status), "time_s": time.perf_counter() - t0,
                     "eta": step.estimate.eta, "eta_rel": step.estimate.relative,
                     **errors3(crack, 10.0, step.qp, step.x, step.estimate.eta, ref)})
    for r in rows:
        print(f"{crack} {r['disc']:>11} n={r['unknowns']:>7} opening={r['jump_error']:.2e} "
              f"energy={r['energy_rel']:.2e} eff={r['effectivity']:.2f} t={r['time_s']:.1f}s", flush=True)
    return {str(k): v for k, v in bias.items()}, rows


def main(argv: list[str] | None = None) -> int:
    """Re-run the 3D part of reports/accuracy.md: its rows and box bias replaced in accuracy.json, the 2D rows
    kept, the report rendered again (benchmarks/accuracy_report.py)."""
    ap = argparse.ArgumentParser(description="the 3D rows of reports/accuracy.md")
    ap.add_argument("--report", type=Path, default=Path("dualfem-results/reports"))
    ap.add_argument("--quick", action="store_true", help="the coarse levels only")
    ap.add_argument("--merge-only", action="store_true", help="no run: merge the last 3D results "
                    "(accuracy/three_d.json) into accuracy.json and render")
    ap.add_argument("--p2-only", action="store_true", help="run the P2 rows alone (the box bias and the P1 rows "
                    "of accuracy.json kept)")
    args = ap.parse_args(argv)
    path, own = args.report / "accuracy.json", args.report / "accuracy" / "three_d.json"
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from accuracy import machine
    from accuracy_report import render

    res = json.loads(path.read_text(encoding="utf-8"))
    t0 = time.perf_counter()
    if args.merge_only:
        three = json.loads(own.read_text(encoding="utf-8"))
    elif args.p2_only:
        three = {"bias3": res["bias3"], "wall_s": 0.0,
                 "rows": [r for r in res["rows"] if r["case"] in CRACKS and not r["disc"].startswith("P2")]}
        for crack in CRACKS:
            bias = {float(k): v for k, v in res["bias3"][crack].items()}
            three["rows"] += study3(crack, args.quick, p2_only=True, bias=bias)[1]
        base = res.get("machine3") or \
            f"P1 rows and the bias: {res['machine']} (whole accuracy run {res['wall_s']:.0f} s)"
        three["machine"] = f"{base.split('; P2 rows')[0]}; P2 rows (--p2-only) {time.perf_counter() - t0:.0f} s " \
                           f"on {machine()}"
    else:
        three = {"bias3": {}, "rows": []}
        for crack in CRACKS:
            three["bias3"][crack], rows = study3(crack, args.quick)
            three["rows"] += rows
        three["wall_s"], three["machine"] = time.perf_counter() - t0, machine()
    if not args.merge_only:
        own.parent.mkdir(parents=True, exist_ok=True)
        own.write_text(json.dumps(three, indent=1), encoding="utf-8")
    res["rows"] = [r for r in res["rows"] if r["case"] not in CRACKS] + three["rows"]
    res["bias3"], res["machine3"] = three["bias3"], f"{three['machine']}; 3D part {three['wall_s']:.0f} s" \
        if three["wall_s"] else three["machine"]
    path.write_text(json.dumps(res, indent=1), encoding="utf-8")
    render(res, args.report / "accuracy.md")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
