"""``newton_amg``: semismooth Newton on all unknowns whose linear systems are solved by AMG-preconditioned CG.

For bodies whose factorization does not fit (3D above ~10^5 unknowns): no factorization of K and no
dual operator. Each Newton step takes the active set A = {mu - c B x > 0}, then solves the KKT system
``K x - B_A' mu_A = F, B_A x = 0`` by augmented-Lagrangian steps on ``K + B_A' C B_A``, each by CG
preconditioned with a smoothed-aggregation hierarchy built with the rigid-body modes
(:func:`dualfem.numerics.amg.full_space_newton`); it stops when the active set repeats. Needs pyamg
(``pip install 'dualfem[amg]'``) and the QP's mesh (``qp.geometry``: the rigid-body modes).
"""
from __future__ import annotations

import time

import numpy as np

from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver


@register_solver
class NewtonAmg(Solver):
    """Full-space semismooth Newton / augmented Lagrangian with AMG-CG inner solves (no factorization)."""

    name = "newton_amg"
    family = "dual"
    description = "semismooth Newton on all unknowns, AL systems by AMG-preconditioned CG (no factorization: 3D)"
    defaults = {
        "tol": 1e-12,          # the AL steps stop when max |B_A x| <= tol max |x| (the active constraints met)
        "cg_rtol": 1e-11,      # relative residual of each AMG-preconditioned CG solve
        "max_iter": 50,        # Newton steps
        "max_al": 30,          # augmented-Lagrangian steps per Newton step
        "time_limit": 3600.0,  # seconds of solve time
        "verbose": False,
    }
    ranges = {"cg_rtol": "(0, 1e-4]", "max_al": "[1, inf)"}
    requires = ("pyamg",)
    extra = "amg"
    tolerance = 1e-6
    exact = True

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": min(1e-3 * tol, 1e-9), "cg_rtol": min(1e-3 * tol, 1e-8)}

    def skip(self, qp) -> str | None:
        g = qp.geometry
        if g is None or g.node_dofs.shape[0] != g.dim:
            return ("newton_amg needs the QP's mesh with one unknown per displacement component (the rigid-body "
                    "modes of its AMG hierarchy): solve a scene, or a QP file with its map_ arrays")
        return None

    def solve(self) -> Solution:
        from dualfem.numerics.amg import full_space_newton

        qp, p = self.qp, self.params
        t0 = time.perf_counter()
        res = full_space_newton(qp, tol=p["tol"], rtol=p["cg_rtol"], max_newton=int(p["max_iter"]),
                                max_al=int(p["max_al"]), deadline=t0 + float(p["time_limit"]),
                                report=lambda k, x, mu: self.report_iterate(k, x, mu))
        if res.timed_out:
            status = Status.TIME_LIMIT
        elif res.converged:
            status = Status.SOLVED
        elif res.cycled:
            status = Status.STAGNATION
        else:
            status = Status.MAX_ITER
        if p["verbose"]:
            print(f"newton_amg: {res.newton_steps} Newton, {res.al_steps} AL steps, {res.cg_iterations} CG "
                  f"iterations, {res.hierarchies} hierarchies: {res.message}", flush=True)
        return Solution(solver=self.name, status=status, x=res.x, multipliers=np.maximum(res.mu, 0.0),
                        iterations={"newton": res.newton_steps, "al": res.al_steps, "cg": res.cg_iterations},
                        message=res.message,
                        info={"hierarchies": res.hierarchies, "ksolve": "amg"})
