"""The runs behind ``reports/plugins.md``: the Signorini problem plugin and the template solver.

Runs only; :mod:`dualfem.reports.plugins` renders. :func:`collect` returns plain JSON-able data
(numbers, strings, lists):

* ``solvers``: the Signorini scene (``problems/signorini.py``) solved by every registered,
  installed solver: status, iterations, time (s), relative energy-norm difference to the
  reference, contact nodes, total contact force sum(mu) (force per unit thickness) and the
  global equilibrium |punch + sum(mu)| / |sum(mu)|;
* ``flat``: the flat foundation, whose exact contact pressure E' indent / height is known;
* ``figure``: the deformed body on its obstacle and the contact pressure mu / w along the bottom
  for three indentations, by every exact solver;
* ``cost``: the template solver ``dual_gradient`` (plain and accelerated) against the mesh size
  on the default scene, next to the reference solver.

The reference is the first installed candidate of the one reference policy
(:func:`dualfem.experiments.reference.candidates`: the solvers declaring ``Solver.reference``).
"""
from __future__ import annotations

import sys
from collections.abc import Callable

import numpy as np

from dualfem.core import evaluator
from dualfem.core.evaluator import kkt_error
from dualfem.core.registry import solvers
from dualfem.core.scene import DEFAULT_SCENE, load_scene
from dualfem.core.solution import Status
from dualfem.experiments.reference import candidates
from dualfem.experiments.runner import run

#: the plugins this study measures, named once: the second problem plugin's scenes (presets of
#: problems/signorini.py) and the template solver of docs/plugins.md
SIGNORINI_SCENE = "signorini"
SIGNORINI_FLAT_SCENE = "signorini_flat"
TEMPLATE_SOLVER = "dual_gradient"
INDENTS = (0.002, 0.005, 0.01)


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def reference_solver() -> str:
    """The reference policy's first installed exact candidate."""

    names = [n for n, _ in candidates()]
    if not names:
        raise RuntimeError("no exact reference solver (a solver declaring Solver.reference) is installed")
    return names[0]


def _kkt(sol) -> float:

    return kkt_error(sol.residuals) if sol.residuals else float("nan")


def every_solver(prob, qp, ref, avail, progress: Callable[[str], None]) -> list[dict]:
    """One record per installed solver on the Signorini QP (see the module docstring)."""

    out = []
    for name in avail:
        s = run(name, qp)
        progress(f"signorini N={prob.params['N']} {name}: {s.status} {s.iterations}")
        if s.x is None or s.status == Status.SKIPPED:
            out.append({"solver": name, "status": str(s.status), "message": s.message, "ok": False})
            continue
        d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
        punch, _ = prob.punch_force(s.x)
        tot = float(s.multipliers.sum())
        out.append({"solver": name, "status": str(s.status), "iterations": dict(s.iterations), "ok": True,
                    "time_s": s.time_s["setup"] + s.time_s["solve"], "kkt": _kkt(s), "x_error": d["x_energy"],
                    "contact": int(evaluator.contact_set(qp, s.x).sum()), "m": qp.m, "sum_mu": tot,
                    "equilibrium": abs(punch + tot) / max(abs(tot), 1e-300)})
    return out


def flat(ref_name: str, Ns) -> list[dict]:
    """The flat foundation: max relative error of the pressure mu / w against the exact one."""

    out = []
    for n_ in Ns:
        for plane in ("strain", "stress"):
            fp = load_scene(SIGNORINI_FLAT_SCENE, {"N": n_, "plane": plane})
            fq = fp.build()
            fs = run(ref_name, fq)
            out.append({"N": n_, "plane": plane, "exact": fp.flat_pressure(),
                        "error": float(np.abs(fq.pressure(fs.multipliers) / fp.flat_pressure() - 1).max()),
                        "contact": int(evaluator.contact_set(fq, fs.x).sum()), "m": fq.m})
    return out


def figure_data(prob, qp, ref, ref_name: str, exact: list[str]) -> dict:
    """Deformed mesh (displacements in the foundation's frame), obstacle and pressures per indentation."""

    p = prob.params
    X, nd = qp.geometry.nodes, qp.geometry.node_dofs
    u = np.zeros_like(X)
    full = prob.displacement(ref.x)
    for c in range(2):
        has = nd[c] >= 0
        u[c, has] = full[nd[c, has]]
    u[1] -= p["indent"]          # from the punch's frame to the foundation's (a rigid translation)
    xs = np.linspace(0, p["width"], 400)
    cn = qp.maps["contact_nodes"]
    pressures = []
    for indent in INDENTS:
        qk = load_scene(SIGNORINI_SCENE, {"N": p["N"], "indent": indent}).build()
        for name in exact:
            s = run(name, qk)
            if s.ok:
                pressures.append({"indent": indent, "solver": name, "x": qk.maps["contact_x"].tolist(),
                                  "pressure": qk.pressure(s.multipliers).tolist()})
    return {"nodes": X.tolist(), "u": u.tolist(), "triangles": qp.geometry.cells.T.tolist(),
            "obstacle_x": xs.tolist(), "gap": prob._gap(xs).tolist(), "height": p["height"],
            "contact_nodes": cn[evaluator.contact_set(qp, ref.x)].tolist(), "reference": ref_name,
            "exact": exact, "pressures": pressures}


def cost(fast: str, sizes, progress: Callable[[str], None]) -> list[dict]:
    """The template solver (plain, accelerated) and ``fast`` on the default scene (delta = 1e-5) for each N
    of ``sizes``."""

    out = []
    for n_ in sizes:
        q2 = load_scene(DEFAULT_SCENE, {"N": n_}).build()
        r = run(fast, q2)
        a = run(TEMPLATE_SOLVER, q2, {"max_n": 10**7})
        b = run(TEMPLATE_SOLVER, q2, {"accelerate": False, "max_n": 10**7})
        d = evaluator.compare(q2, a.x, a.multipliers, r.x, r.multipliers)["x_energy"] \
            if (r.ok and a.x is not None) else float("nan")
        progress(f"{DEFAULT_SCENE} N={n_}: plain {b.iterations} accelerated {a.iterations}")
        out.append({"N": n_, "n": q2.n, "x_error": d,
                    **{f"{k}_{f}": v for k, s in (("plain", b), ("accel", a), ("fast", r))
                       for f, v in (("iterations", s.iterations.get("gradient")), ("status", str(s.status)),
                                    ("time_s", s.time_s["setup"] + s.time_s["solve"]))}})
    return out


def collect(N: int = 32, sizes=(16, 32, 64, 128), progress: Callable[[str], None] = _progress) -> dict:
    """Everything :mod:`dualfem.reports.plugins` shows (see the module docstring)."""

    avail = {n: c for n, c in sorted(solvers().items()) if c.missing() is None}
    ref_name = reference_solver()
    prob = load_scene(SIGNORINI_SCENE, {"N": N})
    qp = prob.build()
    ref = run(ref_name, qp)
    p = prob.params
    fast = ref_name          # the first reference solver: exact, and declared first because it is the fastest
    return {"N": N, "reference": ref_name, "fast": fast, "n": qp.n, "m": qp.m, "scene_name": DEFAULT_SCENE,
            "template": TEMPLATE_SOLVER,
            "scene": {k: p[k] for k in ("width", "height", "E", "nu", "plane", "indent", "obstacle")},
            "solvers": every_solver(prob, qp, ref, avail, progress), "flat": flat(ref_name, (8, N)),
            "figure": figure_data(prob, qp, ref, ref_name, [n for n, c in avail.items() if c.exact]),
            "cost": cost(fast, sizes, progress)}
