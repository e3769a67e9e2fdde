"""my_fista: FISTA on the contact dual through dualfem's dual operator (a dual-solver plugin template).

Copy this file to ``solvers/my_fista.py`` of a dualfem checkout (in-tree plugin) or into your own
package with an entry point in the group ``dualfem.solvers`` (third-party plugin); rename the
class and ``name``. See docs/plugins.md.

Method: the dual of ``min 1/2 x'Kx - F'x s.t. Bx >= 0`` is ``min over mu >= 0 of
1/2 mu'D mu + b0'mu`` with ``D = B K^-1 B'`` and ``b0 = B K^-1 F``; its gradient ``D mu + b0`` is
the gap ``B x(mu)``. FISTA (Beck & Teboulle 2009) takes projected steps ``1/L`` (``L`` >= |D|_2)
from an extrapolated point, restarting the momentum when it points uphill (O'Donoghue & Candes
2015). Deriving from ``DualOperatorSolver`` gives the parameters ``operator`` and ``factor``, the
``skip`` (no operator fits the memory) and the ``setup`` that builds ``self.op``.
"""
from __future__ import annotations

import time

import numpy as np

from dualfem.dual_solver import DualOperatorSolver
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import positive


@register_solver
class MyFista(DualOperatorSolver):
    name = "my_fista"
    family = "dual"       # colour and marker in every figure follow from it
    description = "FISTA with restarts on the dual operator (template from docs/plugins.md)"
    defaults = {"tol": 1e-10, "max_iter": 100000, "time_limit": 60.0}   # + operator, factor
    tolerance = 1e-6      # promised relative error of x (energy norm) at default settings
    exact = True

    def validate(self) -> None:
        super().validate()                                  # operator and factor
        positive(self, "tol", "max_iter", "time_limit")

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": 1e-2 * tol}

    def solve(self) -> Solution:
        op, p = self.op, self.params
        t0 = time.perf_counter()
        step = 1.0 / (1.05 * op.norm_estimate())           # the power iteration estimates |D| from below
        mu = y = np.zeros(op.m)
        t, it, status = 1.0, 0, Status.MAX_ITER
        fs = max(np.abs(self.qp.F).max(initial=0.0), 1e-300)
        while it < p["max_iter"]:
            x = op.x_of(mu)
            gap = self.qp.B @ x
            # the evaluator's scale-free primal and complementarity residuals (dualfem/evaluator.py)
            ls = max(np.abs(x).max(initial=0.0), 1e-300)
            if max(-gap.min(initial=0.0) / ls, np.abs(mu * gap).max(initial=0.0) / (fs * ls)) <= p["tol"]:
                status = Status.SOLVED
                break
            if time.perf_counter() - t0 > p["time_limit"]:
                status = Status.TIME_LIMIT
                break
            new = np.maximum(0.0, y - step * (op.b0 + op.apply(y)))
            if (new - mu) @ (y - new) > 0:                  # momentum uphill: restart
                t, y = 1.0, mu
                continue
            t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
            y = new + ((t - 1.0) / t_next) * (new - mu)
            mu, t = new, t_next
            it += 1
        return Solution(solver=self.name, status=status, x=op.x_of(mu), multipliers=mu,
                        iterations={"gradient": it}, message=f"{status} after {it} iterations",
                        info=op.info())
