"""``example_nnls``: the dual QP solved exactly by Lawson-Hanson NNLS on the dense Delassus matrix.

Dual of ``min 1/2 x'Kx - F'x s.t. Bx >= 0``: ``min over mu >= 0 of 1/2 mu'D mu + c'mu`` with
``D = B K^-1 B'`` and ``c = B K^-1 F``. With ``D = R'R`` (Cholesky) this is the non-negative least
squares problem ``min ||R mu + R^-T c||``, which ``scipy.optimize.nnls`` solves by a finite
active-set method. Forming D costs m sparse solves and m^2 memory, so ``skip`` refuses QPs with
more than ``max_m`` constraints.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse.linalg as sla
from scipy.optimize import nnls

from dualfem.solution import Solution, Status
from dualfem.solver import Solver, positive


class NNLSDual(Solver):
    name = "example_nnls"
    description = "dual QP by dense Cholesky + Lawson-Hanson NNLS (third-party example; small m only)"
    requires = ("scipy",)
    defaults = {"max_m": 2000}
    tolerance = 1e-8
    exact = True

    def validate(self) -> None:
        positive(self, "max_m")

    def skip(self, qp):
        if qp.m > self.params["max_m"]:
            return f"example_nnls forms the dense m x m Delassus matrix: m = {qp.m} > max_m = {self.params['max_m']}"
        return None

    def setup(self, qp) -> None:
        self.qp = qp
        self.lu = sla.splu(qp.K.tocsc(), permc_spec="MMD_AT_PLUS_A")
        Bt = qp.B.T.toarray()
        self.Z = self.lu.solve(Bt) if qp.m else np.zeros((qp.n, 0))   # K^-1 B'
        self.D = qp.B @ self.Z

    def solve(self) -> Solution:
        qp = self.qp
        x0 = self.lu.solve(qp.F)
        if qp.m == 0:
            return Solution(solver=self.name, status=Status.SOLVED, x=x0, multipliers=np.zeros(0))
        c = qp.B @ x0
        try:
            R = la.cholesky(0.5 * (self.D + self.D.T))          # upper: D = R'R
        except la.LinAlgError as exc:
            return Solution(solver=self.name, status=Status.NUMERICAL_ERROR, message=f"Cholesky of D failed: {exc}")
        mu, _ = nnls(R, -la.solve_triangular(R, c, trans="T"), maxiter=50 * qp.m)
        x = x0 + self.Z @ mu
        return Solution(solver=self.name, status=Status.SOLVED, x=x, multipliers=mu,
                        message="nnls: finite active-set method converged")
