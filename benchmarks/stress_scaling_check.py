"""Side test behind a finding of reports/stability.md: objective scaling vs variable scaling.

``dualfem.numerics.scaling.scale`` multiplies the objective by c = 1 / max|D F| (D = diag(K)^-1/2), so the
scaled Hessian c D K D grows like 1 / (load magnitude) and depends on the units. The alternative
here scales the unknowns instead, x = s D y with s = max|D F|: P = D K D (unit diagonal), q = -D F / s
(unit size), whatever the load or the units. This script solves the stress grid's load and units
scenes (N = 16) with Clarabel and OSQP under both scalings (by swapping the ``scale`` function the
two plugin modules use) and prints status and relative energy-norm error against pdas.

    python benchmarks/stress_scaling_check.py
"""
from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp

import dualfem.numerics.scaling as S
import solvers.clarabel_ as C
import solvers.osqp_ as O
from dualfem.core import evaluator
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.experiments.stress import BASE, LOAD_SCALES, UNITS, scene_in_units


def variable_scaling(qp, enable=True):
    """x = s D y, multipliers mu = s R nu: P = D K D, q = -D F / s, rows of R B D of unit norm."""
    if not enable:
        return S.scale(qp, False)
    d = 1.0 / np.sqrt(qp.K.diagonal())
    Dm = sp.diags(d)
    qd = d * qp.F
    s = max(np.abs(qd).max(initial=0.0), 1e-300)
    A = (qp.B @ Dm).tocsr()
    rn = np.abs(A).max(axis=1).toarray().ravel()
    r = 1.0 / np.where(rn > 0, rn, 1.0)
    A = (sp.diags(r) @ A).tocsr()
    return S.ScaledQP((Dm @ qp.K @ Dm).tocsc(), -qd / s, A, d * s, r * s, 1.0)


def main() -> None:
    warnings.simplefilter("ignore")
    base = {**BASE, "N": 16}
    qp0 = load_scene("f2", base).build()
    ref = run("pdas", qp0)
    cases = [(f"load x {ls:g}", {**base, "load_scale": ls}, ls, ls) for ls in LOAD_SCALES]
    cases += [(f"units {u}", scene_in_units(base, fs, fl), fl, fs * fl) for u, (fs, fl) in UNITS.items()]
    print(f"{'scene':16s} {'solver':9s} {'objective scaling (now)':28s} variable scaling")
    for label, scene, fx, fmu in cases:
        qp = load_scene("f2", scene).build()
        for name, mod in (("clarabel", C), ("osqp", O)):
            cells = []
            for fn in (S.scale, variable_scaling):
                mod.scale = fn
                try:
                    sol = run(name, qp)
                finally:
                    mod.scale = S.scale
                err = (evaluator.compare(qp0, sol.x / fx, sol.multipliers / fmu, ref.x, ref.multipliers)["x_energy"]
                       if sol.x is not None else float("nan"))
                cells.append(f"{str(sol.status):16s} {err:8.1e}")
            print(f"{label:16s} {name:9s} {cells[0]:28s} {cells[1]}")


if __name__ == "__main__":
    main()
