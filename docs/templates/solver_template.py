"""my_pg: projected gradient on the dual QP (a solver plugin template for dualfem).

Copy this file to ``solvers/my_pg.py`` of a dualfem checkout (in-tree plugin) or into your own
package with an entry point in the group ``dualfem.solvers`` (third-party plugin); rename the
class and ``name``. See docs/plugins.md.

Method: for ``min 1/2 x'Kx - F'x s.t. Bx >= 0`` the dual is ``min over mu >= 0 of
f(mu) = 1/2 (F + B'mu)' K^-1 (F + B'mu)`` with gradient ``B x(mu)``, ``x(mu) = K^-1 (F + B'mu)``.
Iterate ``mu <- max(0, mu - B x(mu) / L)``, ``L`` = largest eigenvalue of ``B K^-1 B'``.
One solve with the factorized K per iteration; iterations grow with the mesh (slow on purpose:
it is the simplest correct dual method).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse.linalg as sla

from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver, positive


@register_solver
class MyProjectedGradient(Solver):
    name = "my_pg"
    description = "projected gradient on the dual (template from docs/plugins.md)"
    defaults = {"tol": 1e-10, "max_iter": 50000, "time_limit": 60.0}
    tolerance = 1e-6      # promised relative error of x (energy norm) at default settings
    exact = True          # converges to the exact QP solution (no modelling error)

    def validate(self) -> None:
        positive(self, "tol", "max_iter", "time_limit")

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": 1e-2 * tol}

    def skip(self, qp):
        if qp.n > 50000:
            return f"my_pg is a slow reference method: n = {qp.n} > 50000 unknowns"
        return None

    def setup(self, qp) -> None:
        self.qp = qp
        self.lu = sla.splu(qp.K.tocsc(), permc_spec="MMD_AT_PLUS_A")   # K is SPD: factor once
        v = np.ones(qp.m)
        self.L = 1.0
        for _ in range(50):                                             # power iteration for L
            w = qp.B @ self.lu.solve(qp.B.T @ v)
            self.L = max(np.linalg.norm(w), 1e-300)
            v = w / self.L

    def solve(self) -> Solution:
        qp, p = self.qp, self.params
        t0 = time.perf_counter()
        step = 1.0 / self.L                # power iteration underestimates L; any step < 2/L converges
        mu = np.zeros(qp.m)
        status, it = Status.MAX_ITER, 0
        while it < p["max_iter"]:
            x = self.lu.solve(qp.F + qp.B.T @ mu)
            gap = qp.B @ x
            # the evaluator's scale-free primal and complementarity residuals (dualfem/evaluator.py)
            fs = max(np.abs(qp.F).max(initial=0), np.abs(qp.K @ x).max(initial=0), 1e-300)
            ls = max(np.abs(x).max(initial=0), 1e-300)
            if max(-gap.min(initial=0) / ls, np.abs(mu * gap).max(initial=0) / (fs * ls)) <= p["tol"]:
                status = Status.SOLVED
                break
            if time.perf_counter() - t0 > p["time_limit"]:
                status = Status.TIME_LIMIT
                break
            mu = np.maximum(0.0, mu - step * gap)
            it += 1
        return Solution(solver=self.name, status=status, x=x, multipliers=mu,
                        iterations={"gradient": it}, message=f"{status} after {it} iterations")
