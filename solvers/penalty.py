"""Penalty method: semismooth Newton with line search and continuation in the penalty parameter.

For a penalty parameter rho (units stress / length, like the paper's r) minimise, with no
constraint,

    P_rho(x) = Pi(x) + rho/2 sum_j w_j ((-[x_nu]_j)^+)^2,       [x_nu] = B x,

whose minimiser penetrates by about mu_j / (rho w_j): that penetration is the method's intrinsic
error and is reported (``info["penetration"]``, absolute, and relative to |x|_inf). There is no
multiplier update (that would be the augmented Lagrangian, i.e. the Uzawa plugin); the
multiplier estimate is the penalty force ``mu_j = rho w_j (-[x_nu]_j)^+ >= 0``, which satisfies
``K x - F = B' mu`` at the minimiser exactly, so the evaluator's stationarity, dual and
complementarity residuals are small and its primal residual is the relative penetration.

Linear algebra: on the defect unknowns I (:class:`dualfem.numerics.linalg.LocalReduction`), P_rho is
``1/2 xI'S xI - g'xI + rho/2 sum_j w_j ((-BI xI)_j^+)^2``; its generalized Hessian on the
active set A = {j : (BI xI)_j < 0} is ``S + rho BI_A' W_A BI_A``, applied through the Woodbury
identity with one Cholesky factorization of S (made in setup) and the m x m Delassus matrix
``D = BI S^-1 BI'``: the Newton system costs one |A| x |A| solve of ``D_AA + (rho W_A)^-1``.
Line search: exact, on the convex piecewise-quadratic restriction t -> P_rho(x + t d) (walk the
breakpoints where a node enters or leaves contact); Armijo backtracking, the textbook choice,
stalled with steps of 1e-12 when a node sat at the kink gap = 0 (f2, N = 128, delta = 1e-9) and
is only a fallback. Stop: when the Newton decrement -grad'd <= 1e-20 x'Sx (about 1e-10 relative
in the energy norm), when the step is at rounding level, or when a full step keeps the active
set (exact on a quadratic piece). At large rho the gradient itself stalls far above rounding in
the stiff directions, so it is not the stopping test (``newton_tol`` is only a shortcut).
After each Newton solve the minimiser on the final active set is recomputed stably,
``(D_AA + (rho W_A)^-1) mu_A = -b0_A`` then ``xI = S^-1 (g + BI_A' mu_A)``, so the penalty
force and the penetration ``mu_A / (rho w_A)`` are not differences of rounded displacements.

Continuation: rho_0 = ``rho0_factor`` * median(diag K on I) / median(w) -- the penalty
stiffness rho w of one node equal to the stiffness of its unknowns, taken from the QP itself
(so it works for any QP and any units): of order E/h at large delta; at small delta the
interface term w/delta dominates diag K and rho_0 grows like 1/delta with it. rho is multiplied
by ``rho_growth`` (warm-started Newton each time) until the relative penetration is at most
``tol`` or rho reaches ``rho_max_factor`` * rho_0; in the latter case the status is
``INACCURATE`` (the penetration is then reported, never hidden).
"""
from __future__ import annotations

import sys
import time

import numpy as np
import scipy.linalg as sla

from dualfem.core.registry import register_solver
from dualfem.core.solution import Solution, Status
from dualfem.numerics.factor import from_param
from dualfem.numerics.reduced_dual import ReducedDualSolver


@register_solver
class PenaltySolver(ReducedDualSolver):
    """Quadratic penalty of the non-penetration constraint with rho-continuation."""

    name = "penalty"
    description = "quadratic penalty, semismooth Newton + line search, continuation in rho (inexact)"
    exact = False
    # the x error follows the relative penetration (<= penetration_tol = 1e-10): measured
    # <= 2.5e-10 (energy norm, vs pdas) on f1/f2, delta 1e-9..1e-1, N = 16..128
    tolerance = 1e-8
    defaults = {
        "tol": 1e-10,             # relative penetration max(-Bx) / |x| accepted
        "rho0_factor": 1.0,
        "rho_growth": 100.0,
        "rho_max_factor": 1e14,
        "newton_tol": 1e-12,
        "max_iter": 50,           # Newton steps per penalty stage
        "sigma": 1e-4,
        "max_backtracks": 40,
        "factor": "auto",         # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
        "time_limit": 600.0,      # seconds of solve time (checked between Newton steps)
        "verbose": False,         # print one line per penalty stage to stderr
    }
    renamed = {"penetration_tol": "tol", "max_newton": "max_iter"}
    ranges = {"rho0_factor": "(0, inf)", "rho_growth": "(1, inf)", "rho_max_factor": "(0, inf)",
              "newton_tol": "(0, inf)", "sigma": "(0, 0.5)", "max_backtracks": "[1, inf)", "factor": None}

    def validate(self) -> None:
        from_param(self)

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # the x error follows the relative penetration; ask for 100x less penetration than tol
        return {"tol": float(tol) * 1e-2}

    def setup(self, qp) -> None:
        super().setup(qp)
        kd = qp.K.diagonal()[self.red.I]
        self.rho0 = self.params["rho0_factor"] * float(np.median(kd)) / float(np.median(qp.weights))

    # ------------------------------------------------------------------ pieces
    def _objective(self, xI, rho):
        gap = self.red.BI @ xI
        pen = np.minimum(gap, 0.0)
        return 0.5 * xI @ (self.red.S @ xI) - self.red.g @ xI + 0.5 * rho * np.sum(self.qp.weights * pen * pen)

    def _exact_step(self, xI, d, rho, slope0):
        """Exact minimiser t* > 0 of the convex piecewise quadratic t -> P_rho(xI + t d).

        With g = BI xI, b = BI d, phi'(t) = phi'(0) + t d'Sd + sum_j rho w_j b_j (min(0, g_j + t b_j)
        - min(0, g_j)): piecewise linear and nondecreasing; walk its breakpoints -g_j / b_j.
        Backtracking alone stalls here (steps of 1e-12) when a node sits at the kink gap = 0.
        """
        w = self.qp.weights
        g = self.red.BI @ xI
        b = self.red.BI @ d
        dSd = float(d @ (self.red.S @ d))
        c = rho * w
        # phi'(t) = slope0 + t dSd + sum_j c_j b_j (min(0, g_j + t b_j) - min(0, g_j))
        act = (g < 0) | ((g == 0) & (b < 0))    # penalised just after t = 0
        k = dSd + float(np.sum(c[act] * b[act] ** 2))   # slope of phi' on the current segment
        off = slope0                                     # phi'(0)
        with np.errstate(divide="ignore", invalid="ignore"):
            tb = np.where(b != 0, -g / b, np.inf)
        events = np.flatnonzero((tb > 0) & np.isfinite(tb))
        events = events[np.argsort(tb[events])]
        t0, val = 0.0, off                      # phi'(t0) = val
        for j in events:
            tj = tb[j]
            if k > 0 and val + k * (tj - t0) >= 0:
                return t0 - val / k
            val = val + k * (tj - t0)
            t0 = tj
            # node j changes state at tj: entering the active set adds c_j b_j^2 to the slope
            if act[j]:
                act[j] = False
                k -= c[j] * b[j] ** 2
            else:
                act[j] = True
                k += c[j] * b[j] ** 2
        if k <= 0:
            return float("nan")
        return t0 - val / k

    def _newton(self, xI, rho, history, stage):
        """Minimise P_rho from xI; return (xI, newton steps, converged?)."""
        red, w, p = self.red, self.qp.weights, self.params
        S, BI, g = red.S, red.BI, red.g
        gscale = max(np.abs(g).max(initial=0.0), 1e-300)
        steps = 0
        f = self._objective(xI, rho)
        while True:
            gap = BI @ xI
            force = rho * w * np.maximum(-gap, 0.0)          # penalty force (>= 0)
            grad = S @ xI - g - BI.T @ force
            gn = np.abs(grad).max(initial=0.0) / max(gscale, np.abs(S @ xI).max(initial=0.0))
            if gn <= p["newton_tol"]:
                return xI, steps, True
            if steps >= p["max_iter"] or time.perf_counter() > self._deadline:
                return xI, steps, False
            steps += 1
            A = gap < 0
            # Newton direction: (S + rho BA' W BA) d = -grad, by Woodbury with S = L L'
            z = sla.cho_solve(self.cho, -grad)
            if A.any():
                BA = BI[A]
                M = self.D[np.ix_(A, A)] + np.diag(1.0 / (rho * w[A]))
                y = sla.solve(M, BA @ z, assume_a="pos")
                d = z - sla.cho_solve(self.cho, BA.T @ y)
            else:
                d = z
            slope = grad @ d
            xs = max(np.abs(xI).max(initial=0.0), 1e-300)
            # Newton decrement -grad'd = |d|_H^2: relative to x'Sx it measures the squared
            # relative energy-norm distance to the minimiser; 1e-20 -> ~1e-10 (the stiff
            # directions make |grad| itself stall far above rounding when rho is large)
            xSx = max(float(xI @ (S @ xI)), 1e-300)
            if slope >= 0 or -slope <= 1e-20 * xSx or np.abs(d).max(initial=0.0) <= 1e-13 * xs:
                # the Newton step is at rounding level of x (or no longer a descent direction
                # because of rounding): xI is the minimiser to working precision
                return xI, steps, True
            t = self._exact_step(xI, d, rho, grad @ d)
            if not (t > 0 and np.isfinite(t)):
                return xI, steps, bool(np.abs(d).max(initial=0.0) <= 1e-10 * xs)
            ft = self._objective(xI + t * d, rho)
            # t* comes from phi' (exact for the piecewise quadratic), not from differences of
            # P_rho, which are at rounding level near the minimiser: accept it unless P_rho
            # grew beyond rounding of its terms
            if ft > f + p["sigma"] * t * slope and ft > f + 1e-12 * (abs(f) + xSx):
                # the exact step failed (should not happen): fall back to backtracking (Armijo)
                t = 1.0
                for _ in range(int(p["max_backtracks"]) + 1):
                    ft = self._objective(xI + t * d, rho)
                    if ft <= f + p["sigma"] * t * slope:
                        break
                    t *= 0.5
                else:
                    return xI, steps, bool(np.abs(d).max(initial=0.0) <= 1e-10 * xs)
            xI = xI + t * d
            # stop when the step is at rounding level of x (P_rho is piecewise quadratic: a
            # full step that keeps the active set is exact)
            f = ft
            history.append({"stage": stage, "rho": rho, "step": t, "active": int(A.sum()),
                            "grad": float(gn)})
            if abs(t - 1.0) <= 1e-12 and np.array_equal((BI @ xI) < 0, A):
                return xI, steps, True

    def _polish(self, xI, rho):
        """The minimiser of P_rho on the active set of xI, computed stably; None if inconsistent.

        On the active set A the minimiser solves ``(D_AA + (rho W_A)^-1) mu_A = -b0_A`` for the
        penalty force, then ``xI = S^-1 (g + BA' mu_A)``; its penetration is ``mu_A / (rho w_A)``
        exactly, not a difference of rounded displacements.
        """
        red, w = self.red, self.qp.weights
        A = (red.BI @ xI) < 0
        mu = np.zeros(self.qp.m)
        if A.any():
            M = self.D[np.ix_(A, A)] + np.diag(1.0 / (rho * w[A]))
            mu[A] = sla.solve(M, -self.b0[A], assume_a="pos")
        xn = sla.cho_solve(self.cho, red.g + red.BI.T @ mu)
        gap = red.BI @ xn
        xs = max(np.abs(xn).max(initial=0.0), 1e-300)
        if np.any(mu[A] <= 0) or np.any(gap[~A] < -1e-12 * xs):
            return None
        pen = float((mu[A] / (rho * w[A])).max(initial=0.0))
        return xn, mu, pen

    # ------------------------------------------------------------------ solve
    def solve(self) -> Solution:
        p, red, w = self.params, self.red, self.qp.weights
        xI = sla.cho_solve(self.cho, red.g)             # unconstrained minimiser
        self._deadline = time.perf_counter() + p["time_limit"]
        rho = self.rho0
        rho_max = self.rho0 * p["rho_max_factor"]
        history: list[dict] = []
        total, stage = 0, 0
        status, message = Status.INACCURATE, ""
        mu = np.zeros(self.qp.m)
        pen = float("nan")
        while True:
            stage += 1
            xI, steps, ok = self._newton(xI, rho, history, stage)
            total += steps
            if not ok:
                status = Status.MAX_ITER
                message = f"Newton did not converge at rho = {rho:.3g} ({steps} steps)"
                if time.perf_counter() > self._deadline:
                    status, message = Status.TIME_LIMIT, f"time limit {p['time_limit']:g} s at rho = {rho:.3g}"
                mu = rho * w * np.maximum(-(red.BI @ xI), 0.0)
                break
            pol = self._polish(xI, rho)
            if pol is None:   # active set not settled to rounding: keep the Newton iterate
                mu = rho * w * np.maximum(-(red.BI @ xI), 0.0)
                pen = float(max(0.0, -(red.BI @ xI).min(initial=0.0)))
            else:
                xI, mu, pen = pol
            xs = max(np.abs(xI).max(initial=0.0), 1e-300)
            if p["verbose"]:
                print(f"penalty: stage {stage} rho {rho:.3g} newton {steps} penetration {pen / xs:.1e}",
                      file=sys.stderr)
            if pen <= p["tol"] * xs:
                status = Status.SOLVED
                message = f"penetration {pen / xs:.1e} relative at rho = {rho:.3g}"
                break
            if rho * p["rho_growth"] > rho_max * (1 + 1e-12):
                status = Status.INACCURATE
                message = (f"rho reached its cap {rho:.3g} with penetration {pen / xs:.1e} relative "
                           f"> tol {p['tol']:g}")
                break
            rho *= p["rho_growth"]
        x = self.red.full(xI)
        return Solution(
            solver=self.name, status=status, x=x, multipliers=mu,
            iterations={"newton": total, "continuation": stage}, history=history, message=message,
            info={"rho": rho, "rho0": self.rho0, "penetration": pen,
                  "penetration_rel": pen / max(np.abs(x).max(initial=0.0), 1e-300)},
        )
