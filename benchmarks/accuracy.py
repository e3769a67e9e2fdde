"""Error against unknowns and against time, per discretization (reports/accuracy.md): Griffith, penny, ellipse.

    python benchmarks/accuracy.py --report reports            # 4-17 min on 2 shared cores (nice -n 10)
    python benchmarks/accuracy.py --report reports --render-only
    python benchmarks/accuracy.py --report reports --p2-rows       # the 2D P2 rows only (graded, adaptive)

Two crack problems of half-length a = 1 in a square box of side L under a remote stress on every side (no
support: only the rigid-body motions removed), E = 1000, nu = 0.3, plane strain, delta = 1e3 (faces free):

* ``open``: a horizontal crack under the tension sigma_22 = 1: the opening 4 (1 - nu^2) sigma / E sqrt(a^2 - x^2);
* ``slip``: a crack at 30 degrees, closed by the compression sigma_22 = -1 with the shear sigma_12 = 0.5: the faces
  in contact, the frictionless slip 4 (1 - nu^2) |tau| / E sqrt(a^2 - s^2) (tau the shear on the crack's plane).

Errors: the opening's (slip's) relative L2 error over |s| <= 0.8 a (trapezoid weights of the defect nodes) and
the energy-norm error ||u - u_h|| = sqrt(2 (Pi_h - Pi)) relative to the crack's part of the solution, sqrt(2 W),
W = pi a^2 tau^2 (1 - nu^2) / E (tau = sigma_n for the open crack): Pi = Pi_0 - W, Pi_0 the uncracked box's
energy (exact for P1). The finite box's bias is measured (``bias``: one graded mesh, mesh_size a, the box side
L from 10 a to 200 a, the fitted factor s_L between the computed and the closed-form opening) and removed: every
error is taken against s_L / s_200 times the closed form (and W times it). The estimator
(:mod:`dualfem.numerics.estimator`) is evaluated on every mesh: its effectivity index eta / ||u - u_h||.

Discretizations: ``uniform`` (mesh_size = tip_size = h, box 10 a: a larger box is out of reach uniformly),
``graded 0.3`` (box 100 a, mesh_size 5 a, tip_size halved, size_growth 0.3: today's default), ``graded 0.05``
(the same with size_growth 0.05), ``adaptive`` (box 100 a, each step of :func:`dualfem.experiments.adaptive.adapt`
from mesh_size 5 a, tip_size 0.5 a; time = the steps so far). Quadratic elements (scene key ``element``,
docs/elements.md): ``P2 graded 0.3`` and ``P2-qp graded 0.3`` (P2 and P2-quarter-point on the graded 0.3 meshes,
tip_size a/10 down to a/40), ``P2-qp graded 0.1`` (size_growth 0.1), ``P2 adaptive`` and ``P2-qp adaptive`` (the
adaptive loop on P2, the P2 estimator of :mod:`dualfem.numerics.estimator_p2`); their errors are taken against
the bias measured with P2-quarter-point elements (``bias_p2``: mesh_size min(5 a, L/4), tip_size a/20, size_growth
0.1), whose s_L is smooth in L (about 1 + 5 (a/L)^2). ``--p2-rows`` computes the 2D P2 rows again into an existing
accuracy.json (the other rows kept) and renders the report. On P2 rows the stress intensity
factors (series fit; quarter-point correlation on quarter-point meshes) against sigma sqrt(pi a) times s_100/s_200.
Each answer by pdas, certified by the runner.
3D (the penny and an elliptic crack under tension, uniform and graded meshes): benchmarks/accuracy_3d.py.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

E, NU, A = 1000.0, 0.3, 1.0
ANGLE = {"open": 0.0, "slip": 30.0}
STRESS = {"open": [[0.0, 0.0], [0.0, 1.0]], "slip": [[0.0, 0.5], [0.5, -1.0]]}
BOXES = (10.0, 20.0, 50.0, 100.0, 200.0)
LAM, MU = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))


def scene(case: str, L: float, **mesh):
    from dualfem.scene import load_scene

    t = np.radians(ANGLE[case])
    d = A * np.array([np.cos(t), np.sin(t)])
    c = np.array([L / 2, L / 2])
    return load_scene("f2", {"mesh": "gmsh", "width": L, "height": L, "E": E, "nu": NU, "delta": 1e3,
                             "defects": [{"points": [(c - d).tolist(), (c + d).tolist()]}],
                             "remote_stress": STRESS[case], **mesh})


def resolved(case: str) -> tuple[float, float]:
    """(sigma_n, tau) on the crack's plane: the normal is the tangent turned by +90 degrees."""
    t = np.radians(ANGLE[case])
    tan, nrm = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
    s = np.asarray(STRESS[case])
    return float(nrm @ s @ nrm), float(tan @ s @ nrm)


def jumps(case: str, qp, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s - a: the position along the crack from its centre, the computed jump, the closed form) at the
    defect's doubled nodes: the opening (open) or the slip's magnitude (slip)."""
    it = qp.interface
    nd = qp.geometry.node_dofs
    u = np.zeros(nd.shape[::-1])
    u.T[nd >= 0] = np.asarray(x)[nd[nd >= 0]]
    d = u[it.upper] - u[it.lower]
    s = it.s - A
    sn, tau = resolved(case)
    if case == "open":
        return s, np.sum(d * it.normals, axis=1), 4 * (1 - NU ** 2) * sn / E * np.sqrt(np.maximum(A * A - s * s, 0))
    slip = np.abs(np.sum(d * it.tangents[:, 0, :], axis=1))
    return s, slip, 4 * (1 - NU ** 2) * abs(tau) / E * np.sqrt(np.maximum(A * A - s * s, 0))


def errors(case: str, L: float, qp, x, scale: float) -> dict:
    """Opening/slip L2 error, energy error (relative), against the closed form times ``scale``."""
    s, j, ex = jumps(case, qp, x)
    k = np.abs(s) <= 0.8 * A
    w = qp.weights[k]
    op = float(np.sqrt(np.sum(w * (j[k] - scale * ex[k]) ** 2) / np.sum(w * (scale * ex[k]) ** 2)))
    sn, tau = resolved(case)
    W = scale * np.pi * A ** 2 * (tau if case == "slip" else sn) ** 2 * (1 - NU ** 2) / E
    sig = np.asarray(STRESS[case])
    dens = (np.sum(sig ** 2) - LAM / (2 * (LAM + MU)) * np.trace(sig) ** 2) / (2 * MU)   # sigma : C^-1 sigma
    pi_exact = -0.5 * L * L * dens - W
    e2 = 2 * (-0.5 * float(qp.F @ x) - pi_exact)
    energy = float(np.sqrt(e2)) if e2 > 0 else float("nan")
    return {"jump_error": op, "energy_error": energy, "energy_rel": energy / np.sqrt(2 * W),
            "fit": float(np.sum(w * j[k] * ex[k]) / np.sum(w * ex[k] ** 2))}


def solve_row(case: str, L: float, pr, scale: float, label: str) -> dict:
    from dualfem.experiments.runner import run
    from dualfem.numerics.estimator import estimate

    t0 = time.perf_counter()
    qp = pr.build()
    t1 = time.perf_counter()
    sol = run("pdas", qp)
    p1 = qp.geometry.element == "P1"
    est = estimate(qp, sol.x, sol.multipliers)  # P1 or P2 (numerics/estimator_p2.py)
    row = {"case": case, "disc": label, "L": L, "unknowns": int(qp.n), "status": str(sol.status),
           "build_s": t1 - t0, "solve_s": sol.time_s.get("setup", 0) + sol.time_s.get("solve", 0),
           "eta": est.eta if est else float("nan"), "eta_rel": est.relative if est else float("nan"),
           **errors(case, L, qp, sol.x, scale)}
    row["time_s"] = row["build_s"] + row["solve_s"]
    row["effectivity"] = row["eta"] / row["energy_error"]
    if not p1:
        row.update(sif_errors(case, qp, sol.x, scale))
    return row


def sif_errors(case: str, qp, x, scale: float) -> dict:
    """P2 rows: the stress intensity factors against the closed form times the box's factor ``scale``:
    max over both tips of |K / K_0 - 1| for the mode the load drives (open: K_I = sigma_n sqrt(pi a); slip: |K_II|
    = |tau| sqrt(pi a)) and |K_other| / K_0 for the other, by the series fit and (quarter-point) the classic
    quarter-point correlation (:mod:`dualfem.post.sif_quarter`)."""
    from dualfem.post.sif_quarter import quarter_point, series_fit

    sn, tau = resolved(case)
    k0 = scale * np.sqrt(np.pi * A) * (sn if case == "open" else abs(tau))
    out = {}
    methods = [("series", series_fit)]
    if qp.geometry.element == "P2-quarter-point":
        methods.append(("qp", quarter_point))
    for name, f in methods:
        s = f(qp, x)
        main, other = (s.K_I, s.K_II) if case == "open" else (np.abs(s.K_II), s.K_I)
        out[f"sif_{name}"] = float(np.abs(main / k0 - 1).max())
        out[f"sif_{name}_other"] = float(np.abs(other / k0).max())
    return out


def bias(case: str, element: str = "P1") -> dict[float, float]:
    """s_L: the fitted factor between the computed and the closed-form jump, one near-crack mesh, per box."""
    out = {}
    for L in BOXES:
        mesh = {"mesh_size": 1.0, "tip_size": A / 20, "size_growth": 0.1} if element == "P1" else \
            {"mesh_size": min(5.0, L / 4), "tip_size": A / 20, "size_growth": 0.1, "element": element}
        pr = scene(case, L, **mesh)
        row = solve_row(case, L, pr, 1.0, "bias")
        out[L] = row["fit"]
        print(f"bias {case} L={L:g}: s_L = {row['fit']:.5f} ({row['unknowns']} unknowns)", flush=True)
    return out


def curves(case: str, s: dict[float, float], quick: bool) -> list[dict]:
    from dualfem.experiments.adaptive import adapt

    rows = []
    ref = {L: s[L] / s[BOXES[-1]] for L in s}
    n = 3 if quick else 5
    for h in [A / 2 ** k for k in range(1, n)]:
        rows.append(solve_row(case, 10.0, scene(case, 10.0, mesh_size=h, tip_size=h), ref[10.0], "uniform"))
    for growth, tips in ((0.3, [A / 10 / 2 ** k for k in range(n)]), (0.05, [A / 5 / 2 ** k for k in range(n - 1)])):
        for tip in tips:
            rows.append(solve_row(case, 100.0, scene(case, 100.0, mesh_size=5.0, tip_size=tip, size_growth=growth),
                                  ref[100.0], f"graded {growth:g}"))
    t_sum = 0.0
    start = scene(case, 100.0, mesh_size=5.0, tip_size=0.5)
    t0 = time.perf_counter()
    for step in adapt(start, target_error=1e-4, max_unknowns=30_000 if quick else 150_000, max_steps=4 if quick else 7,
                      step_growth=3.0):
        t_sum = time.perf_counter() - t0
        rows.append({**_step_row(case, step, ref[100.0]), "time_s": t_sum})
    for r in rows:
        print(f"{case} {r['disc']:>11} n={r['unknowns']:>7} jump={r['jump_error']:.2e} energy={r['energy_rel']:.2e} "
              f"eff={r['effectivity']:.2f} t={r['time_s']:.1f}s", flush=True)
    return rows


def curves_p2(case: str, s: dict[float, float], quick: bool) -> list[dict]:
    """The quadratic rows (box 100 a, mesh_size 5 a), their errors against ``s`` (the P2 bias) at L = 100 a."""
    rows, ref = [], s[100.0] / s[BOXES[-1]]
    n = 3 if quick else 4
    for element, growth, label in (("P2", 0.3, "P2 graded 0.3"), ("P2-quarter-point", 0.3, "P2-qp graded 0.3"),
                                   ("P2-quarter-point", 0.1, "P2-qp graded 0.1")):
        for tip in [A / 10 / 2 ** k for k in range(n)]:
            pr = scene(case, 100.0, mesh_size=5.0, tip_size=tip, size_growth=growth, element=element)
            rows.append(solve_row(case, 100.0, pr, ref, label))
    rows += adaptive_p2(case, ref, quick)
    for r in rows:
        print(f"{case} {r['disc']:>16} n={r['unknowns']:>7} jump={r['jump_error']:.2e} energy={r['energy_rel']:.2e} "
              f"eff={r['effectivity']:.2f} t={r['time_s']:.1f}s", flush=True)
    return rows


def adaptive_p2(case: str, ref: float, quick: bool) -> list[dict]:
    """``P2 adaptive`` and ``P2-qp adaptive``: the adaptive loop (P2 estimator, order 2) from mesh_size 5 a,
    tip_size a/2 in the 100 a box, each step certified, its errors against ``ref`` (the P2 bias at 100 a)."""
    from dualfem.errors import InputError
    from dualfem.experiments.adaptive import adapt

    rows = []
    for element, label in (("P2", "P2 adaptive"), ("P2-quarter-point", "P2-qp adaptive")):
        start = scene(case, 100.0, mesh_size=5.0, tip_size=0.5, element=element)
        t0 = time.perf_counter()
        for step in adapt(start, target_error=1e-4, max_unknowns=30_000 if quick else 150_000,
                          max_steps=3 if quick else 6, step_growth=3.0):
            row = {**_step_row(case, step, ref, label), "time_s": time.perf_counter() - t0}
            try:                            # a coarse first mesh has too few pairs near a tip for the fit
                row.update(sif_errors(case, step.qp, step.x, ref))
            except InputError as exc:
                print(f"{label} n={step.unknowns}: no stress intensity factors ({exc})", flush=True)
            rows.append(row)
    return rows


def _step_row(case: str, step, scale: float, label: str = "adaptive") -> dict:
    err = errors(case, 100.0, step.qp, step.x, scale)
    return {"case": case, "disc": label, "L": 100.0, "unknowns": step.unknowns,
            "status": str(step.solution.status),
            "eta": step.estimate.eta, "eta_rel": step.estimate.relative, **err,
            "effectivity": step.estimate.eta / err["energy_error"]}


def p2_rows(path: Path, quick: bool) -> None:
    """``--p2-rows``: the 2D P2 rows of an existing accuracy.json computed again (graded and adaptive), the others
    kept; the P2 bias kept when the file has it (the same meshes), else measured."""
    from accuracy_report import P2_DISCS

    res = json.loads(path.read_text(encoding="utf-8"))
    res["rows"] = [r for r in res["rows"] if not (r["case"] in ANGLE and r["disc"] in P2_DISCS)]
    res.setdefault("bias_p2", {})
    t0 = time.perf_counter()
    for case in ANGLE:
        if case not in res["bias_p2"]:
            res["bias_p2"][case] = {str(k): v for k, v in bias(case, "P2-quarter-point").items()}
        res["rows"] += curves_p2(case, {float(k): v for k, v in res["bias_p2"][case].items()}, quick)
    res["p2_rows"] = {"wall_s": time.perf_counter() - t0, "machine": machine()}
    path.write_text(json.dumps(res, indent=1), encoding="utf-8")


def machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    threads = os.environ.get("OMP_NUM_THREADS", "default")
    return (f"{platform.machine()}, {os.cpu_count()} cores shared with other engineers' jobs, OMP/MKL threads "
            f"{threads}, 1-min load {load:.1f} at the end, Python {platform.python_version()}, "
            f"{time.strftime('%Y-%m-%d')}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report", type=Path, default=Path("dualfem-results/reports"))
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--quick", action="store_true", help="the coarse levels only")
    ap.add_argument("--p2-rows", action="store_true", help="only the 2D P2 rows again, into the existing accuracy.json")
    args = ap.parse_args(argv)
    args.report.mkdir(parents=True, exist_ok=True)
    path = args.report / "accuracy.json"
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if args.p2_rows:
        p2_rows(path, args.quick)
    elif not args.render_only:
        t0 = time.perf_counter()
        res: dict = {"bias": {}, "bias_p2": {}, "rows": []}
        for case in ("open", "slip"):
            b = bias(case)
            res["bias"][case] = {str(k): v for k, v in b.items()}
            res["rows"] += curves(case, b, args.quick)
            b2 = bias(case, "P2-quarter-point")
            res["bias_p2"][case] = {str(k): v for k, v in b2.items()}
            res["rows"] += curves_p2(case, b2, args.quick)
        from accuracy_3d import CRACKS, study3

        res["bias3"] = {}
        for crack in CRACKS:
            res["bias3"][crack], rows = study3(crack, args.quick)
            res["rows"] += rows
        res["wall_s"] = time.perf_counter() - t0
        res["machine"] = machine()
        path.write_text(json.dumps(res, indent=1), encoding="utf-8")
    from accuracy_report import render

    render(json.loads(path.read_text(encoding="utf-8")), args.report / "accuracy.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
