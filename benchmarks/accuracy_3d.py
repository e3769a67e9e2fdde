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
so far, each with its estimate and certification; full run: to 150 k unknowns).
"""
from __future__ import annotations

import time

import numpy as np
from scipy.special import ellipe

E, NU = 1000.0, 0.3
CRACKS = {"penny": 1.0, "ellipse": 0.5}          # b / a
BOXES3 = (10.0, 20.0, 40.0)


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
    est = estimate(qp, sol.x, sol.multipliers)
    return {"case": crack, "disc": label, "L": L, "unknowns": int(qp.n), "status": str(sol.status),
            "time_s": t1 - t0 + sol.time_s.get("setup", 0) + sol.time_s.get("solve", 0),
            "eta": est.eta, "eta_rel": est.relative, **errors3(crack, L, qp, sol.x, est.eta, scale)}


def study3(crack: str, quick: bool) -> tuple[dict, list[dict]]:
    """The bias per box and the rows of every discretization."""
    bias = {}
    for L in BOXES3:
        bias[L] = row3(crack, L, scene3(crack, L, mesh_size=2.0, tip_size=0.1), 1.0, "bias")["fit"]
        print(f"bias {crack} L={L:g}: s_L = {bias[L]:.5f}", flush=True)
    ref = bias[10.0] / bias[BOXES3[-1]]
    rows = []
    n = 2 if quick else 4
    for h in (1.0, 0.7, 0.5, 0.35)[:n]:
        rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=h, tip_size=h), ref, "uniform"))
    for growth, tips in ((0.3, (0.2, 0.1, 0.05, 0.025)[:n]), (0.1, (0.2, 0.1, 0.05)[:n - 1])):
        for tip in tips:
            rows.append(row3(crack, 10.0, scene3(crack, 10.0, mesh_size=2.0, tip_size=tip, size_growth=growth),
                             ref, f"graded {growth:g}"))
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
