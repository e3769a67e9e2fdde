"""Friction in the paper's method and its relatives: the cost of Tresca and Coulomb against the frictionless solve
(uzawa, uzawa_auto, penalty), Coulomb in the Uzawa loop against the fixed point over Tresca solves, fixed-point
counts against mu_f, and the 2D slip against the closed form (reports/friction_uzawa.md).

    python benchmarks/friction_uzawa.py --out benchmarks/results/friction_uzawa --report reports   (~20 min, 2 cores)
    python benchmarks/friction_uzawa.py --render-only --out benchmarks/results/friction_uzawa --report reports
    python benchmarks/friction_uzawa.py --quick --out /tmp/fu_quick --report /tmp/fu_quick   (smoke test, ~1 min)

Scenes: a closed straight crack (2D plane strain, half-length a = 0.05 in the unit square, gmsh mesh_size 0.005,
tip_size 0.0005; remote sigma_yy = sigma_xx = -1, tau_xy = 0.3; E = 1000, nu = 0.3, delta = 1e3) and the library's
penny crack (3D, radius 1 in a cube of side 10, mesh_size 2, tip_size 0.25, and a finer one, 1.5 and 0.15, cost only;
remote sigma_zz = -1, sigma_xz = 0.3).
Tresca g = 0.1, Coulomb mu_f = 0.2 (both slip: |tau| > g, mu_f sigma_n). Times: setup and solve of a fresh solver
instance on the built QP, median of ``--repeats``; status: one certified run (dualfem.experiments.runner.run).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

E, NU, A2, TAU, G_TRESCA, MU_F = 1000.0, 0.3, 0.05, 0.3, 0.1, 0.2
VARIANTS = [("uzawa", {}), ("uzawa_auto", {}), ("uzawa_auto", {"coulomb": "fixed_point"}), ("penalty", {})]
MU_SWEEP = [0.05, 0.1, 0.2, 0.25, 0.28, 0.3, 0.5]


def scenes(quick: bool = False) -> dict:
    """The 2D crack and the 3D penny (``quick``: coarse meshes, for a smoke test)."""
    from dualfem.core.scene import load_scene
    from dualfem.problems.thin_defect import ThinDefect

    h2, h3 = ((0.05, 0.002), (3.0, 0.5)) if quick else ((0.005, 0.0005), (2.0, 0.25))
    two = ThinDefect(mesh="gmsh", mesh_size=h2[0], tip_size=h2[1], E=E, nu=NU, delta=1e3,
                     remote_stress=[[-1.0, TAU], [TAU, -1.0]], defects=[{"points": [[0.5 - A2, 0.5], [0.5 + A2, 0.5]]}])
    three = load_scene("penny", {"mesh_size": h3[0], "tip_size": h3[1],
                                 "remote_stress": [[0.0, 0.0, TAU], [0.0, 0.0, 0.0], [TAU, 0.0, -1.0]]})
    out = {"2D crack": two.build(), "3D penny": three.build()}
    if not quick:      # a finer penny: the matrix-free operator's choice, so the sparse friction space
        out["3D penny, finer"] = load_scene("penny", {"mesh_size": 1.5, "tip_size": 0.15, "remote_stress": [
            [0.0, 0.0, TAU], [0.0, 0.0, 0.0], [TAU, 0.0, -1.0]]}).build()
    return out


def label(name: str, params: dict) -> str:
    return name + "".join(f" ({k}={v})" for k, v in params.items())


def timed(name: str, params: dict, qp, repeats: int, certify: bool = True) -> dict:
    """Median setup / solve seconds of fresh instances, the raw answer's counters, and one certified status
    (``certify`` False: the claim only, status None)."""
    from dualfem.core import registry
    from dualfem.experiments.runner import run

    setups, solves, sol = [], [], None
    for _ in range(repeats):
        solver = registry.solvers()[name](**params)
        t0 = time.perf_counter()
        solver.setup(qp)
        t1 = time.perf_counter()
        sol = solver.solve()
        setups.append(t1 - t0)
        solves.append(time.perf_counter() - t1)
    cert = run(name, qp, params) if certify else None
    return {"setup_s": float(np.median(setups)), "solve_s": float(np.median(solves)), "claim": str(sol.status),
            "status": str(cert.status) if cert else None, "iterations": dict(sol.iterations),
            "factorizations": sol.info.get("factorizations"), "space": sol.info.get("space", sol.info.get("operator")),
            "certify_s": cert.time_s.get("certify") if cert else None,
            "coulomb_contraction": sol.info.get("coulomb_contraction")}


def cost(qps: dict, repeats: int) -> list[dict]:
    from dualfem.problems._friction import with_friction

    rows = []
    for scene, qp in qps.items():
        cases = {"none": qp, "tresca": with_friction(qp, "tresca", G_TRESCA),
                 "coulomb": with_friction(qp, "coulomb", MU_F)}
        for name, params in VARIANTS:
            for friction, q in cases.items():
                if params and friction != "coulomb":
                    continue
                rec = {"scene": scene, "solver": label(name, params), "friction": friction, "n": q.n, "m": qp.m,
                       **timed(name, params, q, repeats)}
                rows.append(rec)
                print(json.dumps(rec), flush=True)
    return rows


def sweep(qps: dict, mus: list[float]) -> list[dict]:
    from dualfem.problems._friction import with_friction

    rows = []
    for scene, qp in list(qps.items())[:2]:
        for mu in mus:
            q = with_friction(qp, "coulomb", mu)
            for name, params in (("uzawa_auto", {"coulomb": "fixed_point"}), ("uzawa_auto", {}),
                                 ("penalty", {})):
                rec = {"scene": scene, "mu_f": mu, "solver": label(name, params),
                       **timed(name, params, q, 1, certify=False)}
                rows.append(rec)
                print(json.dumps(rec), flush=True)
    return rows


def slip(qp) -> dict:
    """The 2D slip by uzawa_auto for Tresca and Coulomb against 4 (1 - nu^2) (tau - g) / E sqrt(a^2 - x^2)."""
    from dualfem.experiments.runner import run
    from dualfem.problems._friction import with_friction

    xs = qp.interface.s - A2
    out = {"x": xs.tolist()}
    for kind, value, g in (("none", 0.0, 0.0), ("tresca", G_TRESCA, G_TRESCA), ("coulomb", MU_F, MU_F * 1.0)):
        q = qp if kind == "none" else with_friction(qp, kind, value)
        sol = run("uzawa_auto", q)
        s = q.interface.jumps(sol.x)[1][:, 0]
        exact = 4 * (1 - NU ** 2) * (TAU - g) / E * np.sqrt(np.maximum(A2 ** 2 - xs ** 2, 0.0))
        inner = np.abs(xs) <= 0.8 * A2
        err = float(np.linalg.norm(s[inner] - exact[inner]) / np.linalg.norm(exact[inner]))
        out[kind] = {"slip": s.tolist(), "exact": exact.tolist(), "l2": err, "status": str(sol.status)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/friction_uzawa")
    ap.add_argument("--report", default="reports")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--quick", action="store_true", help="coarse meshes, one repeat, three mu_f (a smoke test)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    data_file = out / "friction_uzawa.json"
    if not a.render_only:
        from dualfem.experiments.machine import loadavg, machine_info, utc_now

        out.mkdir(parents=True, exist_ok=True)
        qps = scenes(a.quick)
        repeats = 1 if a.quick else a.repeats
        data = {"machine": machine_info(), "date": utc_now(), "load_before": loadavg(), "repeats": repeats,
                "quick": a.quick, "cost": cost(qps, repeats),
                "sweep": sweep(qps, MU_SWEEP[1:4] if a.quick else MU_SWEEP), "slip": slip(qps["2D crack"])}
        data["load_after"] = loadavg()
        data_file.write_text(json.dumps(data, indent=1))
    sys.path.insert(0, str(Path(__file__).parent))
    from friction_uzawa_report import render

    render(json.loads(data_file.read_text()), Path(a.report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
