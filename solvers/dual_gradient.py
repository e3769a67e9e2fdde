"""Projected gradient on the dual: the template solver (simple, exact in the limit, slow).

For ``min 1/2 x'Kx - F'x  s.t.  Bx >= 0`` the Lagrangian ``1/2 x'Kx - F'x - mu'Bx`` is minimized
over x by ``x(mu) = K^-1 (F + B'mu)``, which leaves the dual problem

    minimize over mu >= 0    f(mu) = 1/2 (F + B'mu)' K^-1 (F + B'mu),    grad f(mu) = B x(mu).

The iteration ``mu <- max(0, mu - t B x(mu))`` is projected gradient with the fixed step
``t = 1 / L``, ``L = lambda_max(B K^-1 B')`` (estimated once by Lanczos). With ``accelerate``
(default) it is FISTA with O'Donoghue-Candes gradient restarts. Because x is affine in mu, the
primal iterate at the extrapolated point is a combination of the last two primal iterates, so each
iteration costs exactly one solve with the (once factorized) K.

Honest about cost: the number of iterations grows with the condition number kappa of the
Delassus matrix ``B K^-1 B'`` (plain gradient ~ kappa, accelerated ~ sqrt(kappa) per digit); on
the thin-defect and Signorini scenes kappa grows about linearly with N (iteration counts:
``dualfem report plugins``, docs/measurements.md); its accuracy is set by ``tol`` alone. It is no
rival for active-set or semismooth Newton methods on fine meshes or ill-conditioned dual problems,
and it exists as a readable reference and as the starting point of ``docs/plugins.md``; ``skip``
refuses QPs with more than ``max_n`` unknowns.

Tresca friction (a QP with Tresca blocks): the same iteration on all blocks stacked (G = qp.G for B, the
multipliers [lambda; t]), the projection onto lambda >= 0 and the friction discs ||t_j|| <= g_j w_j
(:class:`dualfem.numerics.friction_dual.FrictionLayout`), the stopping test the evaluator's residuals with the
laws (:func:`dualfem.core.evaluator.residuals`: primal and complementarity, friction's included). Coulomb is not
taken (its radius moves with lambda: skipped with a reason by ``accepts``; pdas and mprgp solve it).

Stopping test: the evaluator's own scale-free residuals (:mod:`dualfem.evaluator`) of
``(x(mu), mu)``. Stationarity and dual feasibility hold by construction (up to the solve's
round-off), so the test is ``primal <= tol`` and ``complementarity <= tol``. Without convergence
the status is ``MAX_ITER`` or ``TIME_LIMIT`` and the last iterate is returned (the runner still
attaches its true residuals).
"""
from __future__ import annotations

import sys
import time

import numpy as np
import scipy.sparse.linalg as sla

from dualfem.core import evaluator
from dualfem.evaluator import load_length
from dualfem.numerics.factor import from_param
from dualfem.numerics.friction_dual import FrictionLayout, layout_refusal
from dualfem.numerics.linalg import sparse_factor
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver


@register_solver
class DualGradient(Solver):
    """Projected (optionally accelerated) gradient method on the dual of the contact QP."""

    name = "dual_gradient"
    family = "dual"
    #: Tresca friction by projection onto the discs; not Coulomb (skipped with a reason)
    accepts = ("signorini", "tresca")
    description = "projected gradient / FISTA on the dual (template solver; slow, small QPs only)"
    defaults = {
        "tol": 1e-10,          # stopping threshold on the evaluator's primal & complementarity residuals
        "max_iter": 20000,
        "time_limit": 60.0,    # seconds of solve time
        "verbose": False,      # print the residuals every 100 iterations to stderr
        "accelerate": True,    # FISTA with gradient restart; False: plain projected gradient
        "step_safety": 1.0,    # step = step_safety / L; must be in (0, 2)
        "max_n": 20000,        # skip QPs with more unknowns than this
        "factor": "auto",      # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
    }
    tolerance = 1e-6
    exact = True

    ranges = {"accelerate": bool, "step_safety": "(0, 2)", "max_n": "[1, inf)", "factor": None}

    def validate(self) -> None:
        from_param(self)

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # the KKT residual threshold needed for a relative error ~tol in x is smaller than tol
        return {"tol": min(1e-2 * tol, 1e-4)}

    def skip(self, qp) -> str | None:
        if qp.n > self.params["max_n"]:
            return (f"dual_gradient is a slow reference method (one sparse solve per iteration, iterations growing "
                    f"with the mesh): n = {qp.n} > max_n = {self.params['max_n']} (raise max_n to force it)")
        return layout_refusal(qp) if qp.blocks else None

    def setup(self, qp) -> None:
        self.qp = qp
        self._lu = sparse_factor(qp.K, from_param(self))
        self._length = load_length(qp)        # the evaluator's length floor: a solution x* = 0 has a scale
        B = self.G = qp.G                     # qp.B itself without friction blocks
        self.layout = FrictionLayout.of(qp) if qp.blocks else None
        if qp.m == 0:
            self.L = 1.0
            return
        M = B.shape[0]
        op = sla.LinearOperator((M, M), dtype=float,
                                matvec=lambda v: B @ self._lu.solve(np.asarray(B.T @ np.ravel(v))))
        if M <= 3:
            D = np.column_stack([op.matvec(e) for e in np.eye(M)])
            self.L = float(np.linalg.eigvalsh(0.5 * (D + D.T)).max())
        else:
            self.L = float(sla.eigsh(op, k=1, which="LA", tol=1e-3, return_eigenvectors=False,
                                     v0=np.ones(M))[0])
        if not np.isfinite(self.L) or self.L <= 0:
            raise RuntimeError(f"the Delassus matrix B K^-1 B' has largest eigenvalue {self.L}: K is not SPD")

    def _x(self, mu: np.ndarray) -> np.ndarray:
        return self._lu.solve(self.qp.F + self.G.T @ mu)

    def _project(self, mu: np.ndarray) -> np.ndarray:
        """mu onto the dual set: mu >= 0; with friction also each t_j onto its Tresca disc."""
        if self.layout is None:
            return np.maximum(0.0, mu)
        return self.layout.project(mu, self.layout.bound)

    def _residuals(self, x: np.ndarray, mu: np.ndarray) -> tuple[float, float]:
        """The evaluator's primal and complementarity residuals (same scales, recomputed cheaply)."""
        qp = self.qp
        if qp.blocks:                     # friction: the evaluator's own residuals, laws included
            res = evaluator.residuals(qp, x, mu)
            return float(res["primal"]), float(res["complementarity"])
        gap = qp.B @ x
        Bmu = qp.B.T @ mu
        fs = max(np.abs(qp.F).max(initial=0.0), np.abs(qp.F + Bmu).max(initial=0.0),
                 np.abs(Bmu).max(initial=0.0), 1e-300)
        ls = max(np.abs(x).max(initial=0.0), self._length, 1e-300)
        primal = max(0.0, -gap.min(initial=0.0)) / ls
        compl = float(np.abs(mu * gap).max(initial=0.0)) / (fs * ls)
        return primal, compl

    def solve(self) -> Solution:
        p = self.params
        t_start = time.perf_counter()
        step = p["step_safety"] / self.L
        tol, max_iter = p["tol"], int(p["max_iter"])
        limit = p["time_limit"]
        mu = np.zeros(self.G.shape[0])
        x = self._x(mu)
        mu_old, x_old = mu, x
        theta = 1.0
        history: list[dict] = []
        status, restarts = Status.MAX_ITER, 0
        primal, compl = self._residuals(x, mu)
        it = 0
        self.report_iterate(0, x, mu)
        if max(primal, compl) <= tol:
            status = Status.SOLVED
        while status != Status.SOLVED and it < max_iter:
            if time.perf_counter() - t_start > limit:
                status = Status.TIME_LIMIT
                break
            it += 1
            if p["accelerate"]:
                theta_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * theta * theta))
                beta = (theta - 1.0) / theta_new
                y = mu + beta * (mu - mu_old)
                xy = x + beta * (x - x_old)          # x is affine in mu: no extra solve
            else:
                theta_new, y, xy = theta, mu, x
            mu_new = self._project(y - step * (self.G @ xy))
            x_new = self._x(mu_new)
            if p["accelerate"] and (y - mu_new) @ (mu_new - mu) > 0:
                theta_new = 1.0                      # gradient restart (O'Donoghue & Candes 2015)
                restarts += 1
            mu_old, x_old, mu, x, theta = mu, x, mu_new, x_new, theta_new
            primal, compl = self._residuals(x, mu)
            self.report_iterate(it, x, mu)
            if it % 100 == 0 or it <= 10:
                history.append({"iter": it, "primal": primal, "complementarity": compl})
                if p["verbose"]:
                    print(f"dual_gradient: {it} primal {primal:.2e} complementarity {compl:.2e}", file=sys.stderr)
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(mu))):
                status = Status.NUMERICAL_ERROR
                break
            if max(primal, compl) <= tol:
                status = Status.SOLVED
        msg = {Status.SOLVED: f"converged: primal {primal:.1e}, complementarity {compl:.1e} <= tol {tol:.1e}",
               Status.MAX_ITER: f"not converged after max_iter = {max_iter} iterations "
                                f"(primal {primal:.1e}, complementarity {compl:.1e} > tol {tol:.1e})",
               Status.TIME_LIMIT: f"time_limit = {p['time_limit']} s reached after {it} iterations "
                                  f"(primal {primal:.1e}, complementarity {compl:.1e})",
               Status.NUMERICAL_ERROR: "iterate became NaN/inf"}[status]
        return Solution(solver=self.name, status=status, x=x, multipliers=mu,
                        iterations={"gradient": it, "restarts": restarts}, history=history,
                        message=msg, info={"L": self.L, "step": step})
