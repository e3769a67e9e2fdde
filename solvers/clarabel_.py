"""Clarabel (interior point) on ``min 1/2 x'Kx - F'x s.t. -Bx + s = 0, s >= 0``.

Clarabel's KKT condition is ``Px + q + A'z = 0`` with ``z >= 0``; with ``A = -B`` and
``q = -F`` this is ``Kx - F = B'z``, so our nodal contact force is ``mu = z``. Only the upper
triangle of K is passed. Clarabel's own residuals are not trusted (Clarabel.cpp issue 36): the
evaluator recomputes them.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.registry import register_solver
from dualfem.scaling import scale
from dualfem.solution import Solution, Status
from dualfem.solver import Solver, positive

_STATUS = {
    "Solved": Status.SOLVED,
    "AlmostSolved": Status.INACCURATE,
    "MaxIterations": Status.MAX_ITER,
    "MaxTime": Status.TIME_LIMIT,
    "PrimalInfeasible": Status.INFEASIBLE,
    "AlmostPrimalInfeasible": Status.INFEASIBLE,
    "DualInfeasible": Status.NUMERICAL_ERROR,
    "AlmostDualInfeasible": Status.NUMERICAL_ERROR,
    "NumericalError": Status.NUMERICAL_ERROR,
    "InsufficientProgress": Status.STAGNATION,
}


@register_solver
class ClarabelSolver(Solver):
    """Clarabel with its gap/feasibility tolerances, iteration cap and time limit exposed."""

    name = "clarabel"
    description = "Clarabel (interior point, Rust) via its Python interface"
    requires = ("clarabel",)
    tolerance = 1e-6
    defaults = {
        "tol_gap_abs": 1e-10,
        "tol_gap_rel": 1e-10,
        "tol_feas": 1e-10,
        "tol_ktratio": 1e-8,
        "max_iter": 200,
        "time_limit": 0.0,
        "equilibrate_enable": True,
        "direct_solve_method": "qdldl",
        "verbose": False,
        "scale": True,
    }

    def validate(self) -> None:
        positive(self, "tol_gap_abs", "tol_gap_rel", "tol_feas", "tol_ktratio", "max_iter")

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol}

    def setup(self, qp) -> None:
        import clarabel

        self.qp = qp
        settings = clarabel.DefaultSettings()
        for k, v in self.params.items():
            if k == "scale" or (k == "time_limit" and v <= 0):
                continue
            setattr(settings, k, v)
        self._scaled = s = scale(qp, self.params["scale"])
        self._solver = clarabel.DefaultSolver(sp.triu(s.P, format="csc"), s.q, (-s.A).tocsc(), np.zeros(qp.m),
                                              [clarabel.NonnegativeConeT(qp.m)], settings)

    def solve(self) -> Solution:
        sol = self._solver.solve()
        name = str(sol.status).split(".")[-1]
        status = _STATUS.get(name, Status.ERROR)
        x, z = self._scaled.unscale(np.array(sol.x), np.array(sol.z))
        return Solution(
            solver=self.name, status=status, x=x, multipliers=z,
            iterations={"ipm": int(sol.iterations)}, message=f"clarabel: {name}",
            info={"obj_val": float(sol.obj_val), "solve_time_internal": float(sol.solve_time)},
        )
