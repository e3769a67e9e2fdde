"""Coulomb friction by the fixed point against mu_f, per solver, and stick/slip maps (reports/friction_fixed_point.md).

    nice -n 10 python benchmarks/friction_fixed_point.py --out benchmarks/results/friction_fixed_point --report reports
    python benchmarks/friction_fixed_point.py --render-only --out benchmarks/results/friction_fixed_point \
        --report reports
    python benchmarks/friction_fixed_point.py --quick --out /tmp/ffp --report /tmp/ffp     (smoke test, ~1 min)

Fixed-point counts: the 2D inclined closed crack of the friction study (benchmarks/scenes/friction_crack_2d.toml,
30 degrees, tip_size 0.0005: 31 friction nodes) and its penny (benchmarks/scenes/friction_penny.toml, coarsest
level: 47 nodes), each under a remote stress that puts contact pressure sigma_n = 1 and shear tau = 1.2 on the
crack plane, so the crack slips for every mu_f in 0.1 ... 1.0 (onset of slip at mu_f = 1.2). Coulomb mu_f on
the defect; every solver that takes Coulomb runs on a fresh QP (no factorization shared) and is certified by the
runner. Solvers that solve Coulomb by the fixed point g <- mu_f lambda_nu over Tresca solves
(dualfem.numerics.coulomb: pdas with coulomb=fixed_point, mprgp, penalty, uzawa_auto with coulomb=fixed_point,
clarabel, cvxpy, osqp) report their Tresca solves and the relative change of the threshold per step; the
observed contraction is the largest ratio of successive changes (from the second step on). pdas (monolithic
Coulomb: the radius mu_f lambda inside the semismooth Newton system) and uzawa / uzawa_auto (the threshold
updated inside the Uzawa loop) are shown beside them with their own counters.

Stick/slip maps: Tresca with a threshold that grows across the defect (an expression in x, the scene key
``friction_bound``), so that one part of the defect sticks and the other slips: the 2D crack at 30 degrees under
sigma_n = 1, tau = 0.5 with g = 0.2 ... 0.8 along it, the penny under sigma_n = 1, tau = 0.5 with
g = 0.5 + 0.4 (x - 5) (0.1 ... 0.9 across the disk); solved by pdas, certified. A node slips when its slip
exceeds the evaluator's contact tolerance (CONTACT_RTOL |x|_inf, as in ``dualfem solve``'s friction line).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SIGMA_N, TAU_FP, TAU_MAP = 1.0, 1.2, 0.5
ANGLE = 30.0
MUS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
MUS_3D = (0.1, 0.2, 0.4, 0.6, 0.8, 1.0)
#: (solver, params): the fixed-point solvers, then the ones that do Coulomb otherwise
VARIANTS = (("pdas", {"coulomb": "fixed_point"}), ("mprgp", {}), ("penalty", {}),
            ("uzawa_auto", {"coulomb": "fixed_point"}), ("clarabel", {}), ("cvxpy", {}), ("osqp", {}),
            ("pdas", {}), ("uzawa_auto", {}), ("uzawa", {}))
#: 3D: osqp and the qpsolvers backends do not take discs; cvxpy's norm terms are slow at this size
SKIP_3D = ("cvxpy", "osqp")


def label(name: str, params: dict) -> str:
    return name + "".join(f" ({k}={v})" for k, v in params.items())


def stress_2d(sigma_n: float, tau: float, angle_deg: float = ANGLE) -> list[list[float]]:
    """The remote stress whose traction on the crack plane at ``angle_deg`` is pressure ``sigma_n`` and shear
    ``tau`` (the same pressure along the crack): S = -sigma_n I + tau (t n' + n t')."""
    th = np.radians(angle_deg)
    t, n = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
    S = -sigma_n * np.eye(2) + tau * (np.outer(t, n) + np.outer(n, t))
    return S.tolist()


def stress_3d(sigma_n: float, tau: float) -> list[list[float]]:
    """Pressure ``sigma_n`` and shear ``tau`` (along x) on the penny's plane z = 5."""
    return [[0.0, 0.0, tau], [0.0, 0.0, 0.0], [tau, 0.0, -sigma_n]]


def scene(dim: int, keys: dict, quick: bool = False):
    """The 2D crack or the penny of the friction study with ``keys`` (docstring), built."""
    from dualfem.core.scene import load_scene

    if dim == 2:
        base = {"tip_size": 0.002 if quick else 0.0005}
        return load_scene(str(HERE / "scenes" / "friction_crack_2d.toml"), {**base, **keys}).build()
    base = {"mesh_size": 3.0, "tip_size": 0.5} if quick else {}
    return load_scene(str(HERE / "scenes" / "friction_penny.toml"), {**base, **keys}).build()


def fixed_point_facts(sol) -> dict:
    """Tresca solves, per-step relative changes of the threshold and the observed contraction (the largest
    ratio of successive changes from the second step on) of a Solution, whichever way the solver reports them
    (``info["coulomb_changes"]`` or ``info["coulomb"]["changes"]``); {} for a solver without the fixed point."""
    info = sol.info or {}
    nested = info.get("coulomb") if isinstance(info.get("coulomb"), dict) else {}
    changes = info.get("coulomb_changes", nested.get("changes"))
    if not changes:
        return {}
    changes = [float(c) for c in changes]
    ratios = [b / a for a, b in zip(changes[1:], changes[2:]) if a > 0]
    its = sol.iterations or {}
    steps = its.get("coulomb_iterations", its.get("coulomb", len(changes)))
    return {"steps": int(steps), "changes": changes, "contraction": max(ratios) if ratios else None}


def one(name: str, params: dict, qp) -> dict:
    """One certified run: status, claim, counters, solver time, the fixed point's facts, the certificate."""
    from dualfem.experiments.runner import run

    t0 = time.perf_counter()
    sol = run(name, qp, params)
    cert = sol.info.get("certificate", {}) if sol.info else {}
    return {"solver": label(name, params), "status": str(sol.status), "message": (sol.message or "")[:160],
            "iterations": {k: v for k, v in (sol.iterations or {}).items() if isinstance(v, (int, float))},
            "setup_s": sol.time_s.get("setup"), "solve_s": sol.time_s.get("solve"),
            "wall_s": time.perf_counter() - t0, "certified": cert.get("value"), **fixed_point_facts(sol)}


def sweep(quick: bool, progress=print) -> list[dict]:
    """Every variant at every mu_f on the 2D crack and the penny (fresh QP per run)."""
    from dualfem.problems._friction import with_friction

    rows = []
    for dim, mus in ((2, MUS), (3, MUS_3D)):
        mus = mus[::3] if quick else mus
        keys = {"remote_stress": stress_2d(SIGMA_N, TAU_FP) if dim == 2 else stress_3d(SIGMA_N, TAU_FP)}
        base = scene(dim, keys, quick)
        for mu in mus:
            for name, params in VARIANTS:
                if dim == 3 and name in SKIP_3D:
                    continue
                qp = with_friction(base, "coulomb", mu)
                rec = {"dim": dim, "mu_f": mu, "n": qp.n, "nodes": int(qp.interface.lower.size),
                       **one(name, params, qp)}
                rows.append(rec)
                progress(f"{dim}D mu_f {mu} {rec['solver']}: {rec['status']} steps {rec.get('steps', '-')} "
                         f"contraction {rec.get('contraction')}")
    return rows


def _slips(qp, x: np.ndarray, dim: int) -> np.ndarray:
    """Per friction node: the slip (2D: the tangential jump; 3D: the length of the tangential jump vector)."""
    if dim == 2:
        return qp.interface.jumps(x)[1][:, 0]
    nd, lo, up = qp.geometry.node_dofs, qp.interface.lower, qp.interface.upper
    return np.hypot(x[nd[0, up]] - x[nd[0, lo]], x[nd[1, up]] - x[nd[1, lo]])


def stick_slip_map(dim: int, quick: bool) -> dict:
    """Tresca with a threshold growing across the defect (docstring), solved by pdas: node positions, slip,
    the threshold and the stick mask."""
    from dualfem.core.evaluator import CONTACT_RTOL
    from dualfem.experiments.runner import run

    a = 0.05
    if dim == 2:
        th = np.radians(ANGLE)
        c = a * np.cos(th)        # the crack spans x in 0.5 -+ c: g runs from 0.2 to 0.8 along it
        expr = f"0.5 + 0.3*(x - 0.5)/{float(c)!r}"
        keys = {"remote_stress": stress_2d(SIGMA_N, TAU_MAP), "friction": "tresca", "friction_bound": expr}
    else:
        expr = "0.5 + 0.4*(x - 5)"
        keys = {"remote_stress": stress_3d(SIGMA_N, TAU_MAP), "friction": "tresca", "friction_bound": expr}
    qp = scene(dim, keys, quick)
    sol = run("pdas", qp)
    cert = sol.info.get("certificate", {}) if sol.info else {}
    out = {"dim": dim, "expr": expr, "tau": TAU_MAP, "sigma_n": SIGMA_N, "status": str(sol.status),
           "certified": cert.get("value"), "n": qp.n}
    if sol.x is None:
        return out
    s = _slips(qp, sol.x, dim)
    tol = CONTACT_RTOL * max(float(np.abs(sol.x).max()), 1e-300)
    nodes = qp.geometry.nodes[:, qp.interface.lower]
    if dim == 2:
        out["s"] = (qp.interface.s - a).tolist()
        g = 0.5 + 0.3 * (nodes[0] - 0.5) / (a * np.cos(np.radians(ANGLE)))
    else:
        out["px"], out["py"] = (nodes[0] - 5.0).tolist(), (nodes[1] - 5.0).tolist()
        g = 0.5 + 0.4 * (nodes[0] - 5.0)
    out.update(slip=np.abs(s).tolist(), g=g.tolist(), stick=(np.abs(s) <= tol).tolist(), tol=tol)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/friction_fixed_point")
    ap.add_argument("--report", default="reports")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--quick", action="store_true", help="coarse meshes, a few mu_f (a smoke test)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    data_file = out / "friction_fixed_point.json"
    if not a.render_only:
        from dualfem.experiments.machine import loadavg, machine_info, utc_now

        out.mkdir(parents=True, exist_ok=True)
        data = {"machine": machine_info(), "date": utc_now(), "load_before": loadavg(), "quick": a.quick,
                "sweep": sweep(a.quick), "maps": [stick_slip_map(2, a.quick), stick_slip_map(3, a.quick)]}
        data["load_after"] = loadavg()
        data_file.write_text(json.dumps(data, indent=1))
    sys.path.insert(0, str(HERE))
    from friction_fixed_point_report import render

    render(json.loads(data_file.read_text()), Path(a.report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
