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

Linear algebra (``operator``: ``dense`` | ``matrix_free`` | ``auto``, by size and memory,
:mod:`dualfem.numerics.dual_operator`; the method runs at every size):

* ``dense``: on the defect unknowns I (:class:`dualfem.numerics.linalg.LocalReduction`), P_rho is
  ``1/2 xI'S xI - g'xI + rho/2 sum_j w_j ((-BI xI)_j^+)^2``; its generalized Hessian on the
  active set A = {j : (BI xI)_j < 0} is ``S + rho BI_A' W_A BI_A``, applied through the Woodbury
  identity with one Cholesky factorization of S (made in setup) and the m x m Delassus matrix
  ``D = BI S^-1 BI'``: the Newton system costs one |A| x |A| solve of ``D_AA + (rho W_A)^-1``.
  Cost: the factorization of K_fixed with its Schur complement, O(|I|^2 m) for D, dense work per
  step; memory 8 (2 |I|^2 + |I| m + m^2) bytes.
* ``matrix_free``: on all unknowns, P_rho(x) = 1/2 x'Kx - F'x + rho/2 sum_j w_j ((-Bx)_j^+)^2. The
  Newton matrices ``K + rho B_A' W_A B_A`` share the pattern of K + B'B
  (:class:`dualfem.numerics.newton_matrix.NewtonMatrix`: analyzed once, one numeric sparse
  factorization per active set and rho, the last ``keep_factors`` kept); the exact line search is
  the same walk with d'Kd, Bx and Bd. Cost: one factorization of K (the operator's, shared with the
  certificate), one analysis, one numeric factorization per Newton step whose active set or rho is
  new (about the cost of K's), a few K-solves per polish; memory: two sparse factors. The iterates
  are those of the dense path to rounding (every one after the first is optimal in the non-local
  unknowns); the Newton loop's stop tests use the full-space x'Kx, so it may stop a step earlier or
  later than the dense path's, and the polish makes the answers equal (tested to 1e-10).

Line search: exact, on the convex piecewise-quadratic restriction t -> P_rho(x + t d) (walk the
breakpoints where a node enters or leaves contact); Armijo backtracking, the textbook choice, can
stall at the kink gap = 0 (docs/measurements.md) and is only a fallback. Stop: when the Newton
decrement -grad'd <= 1e-20 x'Sx (about 1e-10 relative in the energy norm), when the step is at
rounding level, or when a full step keeps the active set (exact on a quadratic piece). At large rho
the gradient itself stalls far above rounding in the stiff directions, so it is not the stopping test
(``newton_tol`` is only a shortcut).
After each Newton solve the minimiser on the final active set is recomputed stably,
``(D_AA + (rho W_A)^-1) mu_A = -b0_A`` then ``xI = S^-1 (g + BI_A' mu_A)``, so the penalty
force and the penetration ``mu_A / (rho w_A)`` are not differences of rounded displacements.
Matrix-free, the same system is solved by iterative refinement: residuals with the operator (one
K-solve), corrections with its exact inverse ``C - C B_A H^-1 B_A' C`` (C = rho W_A, H the Newton
matrix of A: one solve with its kept factor), from the Newton matrix's answer ``-C B_A H^-1 F``;
2-4 steps (``info["polish_refinements"]``), then ``x = K^-1 (F + B'mu)``. Stop tests relative to
|x| use the defect unknowns' largest displacement on both paths.

Friction blocks (Tresca, Coulomb): regularized friction with the same rho, Coulomb by the fixed point over
Tresca solves; :mod:`dualfem.numerics.friction_penalty`.

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

from dualfem.dual_solver import OPERATORS, DualOperatorSolver
from dualfem.evaluator import load_energy, load_length
from dualfem.numerics.factor import from_param
from dualfem.numerics.friction_penalty import solve_friction
from dualfem.numerics.friction_spaces import DenseFrictionSpace, Layout, SparseFrictionSpace
from dualfem.numerics.newton_matrix import NewtonMatrix
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status

#: most refinement steps of the matrix-free polish (each one K-solve and one Newton-matrix solve)
POLISH_STEPS = 8


class _DenseSpace:
    """The penalty problem on the defect unknowns I (exact reduction; the dense operator)."""

    kind = "dense"

    def __init__(self, op, qp):
        red = op.reduction
        self.qp, self.op, self.red = qp, op, red
        self.Q, self.q, self.B = red.S, red.g, red.BI
        self.cho = red.S_cho
        self.D, self.b0 = op.D, op.b0
        self.factorizations = 0

    def start(self):
        return sla.cho_solve(self.cho, self.q)

    def direction(self, grad, A, rho):
        """The Newton direction: (S + rho BA' W BA) d = -grad, by Woodbury with S = L L'."""
        w = self.qp.weights
        z = sla.cho_solve(self.cho, -grad)
        if not A.any():
            return z
        BA = self.B[A]
        M = self.D[np.ix_(A, A)] + np.diag(1.0 / (rho * w[A]))
        y = sla.solve(M, BA @ z, assume_a="pos")
        self.factorizations += 1
        return z - sla.cho_solve(self.cho, BA.T @ y)

    def polish(self, x, rho):
        """(x, mu, A) of the minimiser of P_rho on the active set A of x (see PenaltySolver._polish)."""
        w = self.qp.weights
        A = (self.B @ x) < 0
        mu = np.zeros(self.qp.m)
        if A.any():
            M = self.D[np.ix_(A, A)] + np.diag(1.0 / (rho * w[A]))
            mu[A] = sla.solve(M, -self.b0[A], assume_a="pos")
            self.factorizations += 1
        return sla.cho_solve(self.cho, self.q + self.B.T @ mu), mu, A

    def full(self, x):
        return self.red.full(x)

    def size(self, v):
        """max |v| over the defect unknowns (the scale of the stop tests)."""
        return float(np.abs(v).max(initial=0.0))

    def info(self):
        return {}


class _SparseSpace:
    """The penalty problem on all unknowns (the matrix-free operator's path).

    Newton matrices K + rho B_A' W_A B_A by :class:`dualfem.numerics.newton_matrix.NewtonMatrix` (one
    analysis, a numeric factorization per active set and rho); the start K^-1 F, the gaps b0 and the
    products D v of the polish by the operator's factorization of K.
    """

    kind = "matrix_free"

    def __init__(self, op, qp, factor=None, keep: int = 4):
        self.qp, self.op = qp, op
        self.Q, self.q, self.B = qp.K.tocsr(), np.asarray(qp.F, float), op.B
        self.nm = op.newton_matrix(keep) if not getattr(op, "exact", True) \
            else NewtonMatrix(qp.K, qp.B, factor, keep=keep)
        self.I = np.asarray(qp.local_dofs) if np.size(qp.local_dofs) else slice(None)
        self.refinements = 0

    @property
    def factorizations(self):
        return self.nm.counters.factorizations

    def start(self):
        return self.op.k_solve(self.q)

    def direction(self, grad, A, rho):
        return self.nm.solve(np.where(A, rho * self.qp.weights, 0.0), -grad)

    def polish(self, x, rho):
        """(x, mu, A): the penalty forces on the active set A of x solve the well-conditioned dual
        system ``(D_AA + C^-1) mu_A = -b0_A`` (C = rho W_A), by iterative refinement whose residuals use
        the operator (one K-solve each) and whose corrections use the exact inverse in exact arithmetic
        ``(D_AA + C^-1)^-1 = C - C B_A H^-1 B_A' C`` (H = K + B_A' C B_A, the Newton matrix of A: one
        solve with its kept factorization); it starts from the Newton matrix's own answer
        ``mu_A = -C B_A H^-1 F``. At large rho that answer (and every product with C) is a difference of
        rounded displacements; the refinement recovers the forces to the accuracy of the dual system.
        Then ``x = K^-1 (F + B'mu)``, so the penetration is ``mu_A / (rho w_A)`` exactly, as on the dense path.
        """
        qp, op, B = self.qp, self.op, self.B
        A = (B @ x) < 0
        mu = np.zeros(qp.m)
        if A.any():
            coef = np.where(A, rho * qp.weights, 0.0)
            C = coef[A]
            BA = B[np.flatnonzero(A)]

            def correction(res):           # (D_AA + C^-1)^-1 res in exact arithmetic
                v = C * res
                return v - C * (BA @ self.nm.solve(coef, BA.T @ v))

            mu[A] = -C * (BA @ self.nm.solve(coef, self.q))
            b0A = op.b0[A]
            last = np.inf
            for _ in range(POLISH_STEPS):
                res = -b0A - mu[A] / C - op.apply(mu)[A]
                dmu = correction(res)
                self.refinements += 1
                mu[A] += dmu
                size = float(np.abs(dmu).max(initial=0.0))
                if size <= 1e-15 * float(np.abs(mu[A]).max(initial=0.0)) or size >= 0.5 * last:
                    break
                last = size
        return op.x_of(mu), mu, A

    def full(self, x):
        return x

    def size(self, v):
        """max |v| over the defect unknowns (the dense path's scale of the stop tests)."""
        return float(np.abs(v[self.I]).max(initial=0.0))

    def info(self):
        return {**self.nm.info(), "polish_refinements": self.refinements}


@register_solver
class PenaltySolver(DualOperatorSolver):
    """Quadratic penalty of the non-penetration constraint with rho-continuation."""

    name = "penalty"
    family = "dual"
    accepts = ("signorini", "tresca", "coulomb")
    description = "quadratic penalty, semismooth Newton + line search, continuation in rho (inexact)"
    exact = False
    #: relative energy-norm error of x against the QP's own solution x*, the modelling error included: it
    #: follows the relative penetration (<= ``tol``; measured: docs/measurements.md)
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
        "operator": "auto",       # dense (reduction onto the defect unknowns), matrix_free (sparse Newton
                                  # matrices, one analysis), auto (by size and memory)
        "keep_factors": 4,        # matrix_free: numeric factorizations of Newton matrices kept (by active set)
        "time_limit": 600.0,      # seconds of solve time (checked between Newton steps)
        "verbose": False,         # print one line per penalty stage to stderr
        "coulomb_max_iter": 50,   # Coulomb friction (by the fixed point over Tresca solves): most Tresca solves
    }
    renamed = {"penetration_tol": "tol", "max_newton": "max_iter"}
    ranges = {"rho0_factor": "(0, inf)", "rho_growth": "(1, inf)", "rho_max_factor": "(0, inf)",
              "newton_tol": "(0, inf)", "sigma": "(0, 0.5)", "max_backtracks": "[1, inf)", "factor": None,
              "operator": OPERATORS, "keep_factors": "[1, inf)", "coulomb_max_iter": "[1, inf)"}

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # the x error follows the relative penetration; ask for 100x less penetration than tol
        return {"tol": float(tol) * 1e-2}

    def setup(self, qp) -> None:
        super().setup(qp)                 # self.op: dense or matrix_free
        self.friction = bool(qp.blocks)
        if self.friction:                 # numerics/friction_penalty.py: regularized friction
            self.lay = Layout(qp)
            self.space = SparseFrictionSpace(qp, self.lay, from_param(self))
            if self.op.kind == "dense":
                try:
                    self.space = DenseFrictionSpace(qp, self.lay, reduction=self.op.reduction)
                except ValueError:    # a friction row off the reduction's local unknowns: stay sparse
                    pass
        else:
            self.space = _DenseSpace(self.op, qp) if self.op.kind == "dense" else \
            _SparseSpace(self.op, qp, from_param(self), keep=int(self.params["keep_factors"]))
        kd = qp.K.diagonal()[np.asarray(qp.local_dofs)]
        # no constraint (m = 0, an uncracked body): no penalty term, rho only labels the messages
        self.rho0 = self.params["rho0_factor"] * float(np.median(kd)) / float(np.median(qp.weights)) \
            if qp.m and kd.size else 1.0
        # the scales of the stop tests have the evaluator's floors (the length and the energy the load sets),
        # so that a solution x* = 0 (a crack pushed shut, nothing else loaded) has a scale of its own
        self._length, self._energy2 = load_length(qp), load_energy(qp) ** 2

    def _size(self, xI) -> float:
        """max(|x_I|_inf, the load's length): the scale of the penetration and step tests."""
        return max(self.space.size(xI), self._length, 1e-300)

    # ------------------------------------------------------------------ pieces
    def _objective(self, xI, rho):
        sp_ = self.space
        gap = sp_.B @ xI
        pen = np.minimum(gap, 0.0)
        return 0.5 * xI @ (sp_.Q @ xI) - sp_.q @ xI + 0.5 * rho * np.sum(self.qp.weights * pen * pen)

    def _exact_step(self, xI, d, rho, slope0):
        """Exact minimiser t* > 0 of the convex piecewise quadratic t -> P_rho(xI + t d).

        With g = BI xI, b = BI d, phi'(t) = phi'(0) + t d'Sd + sum_j rho w_j b_j (min(0, g_j + t b_j)
        - min(0, g_j)): piecewise linear and nondecreasing; walk its breakpoints -g_j / b_j.
        Backtracking alone stalls here (steps of 1e-12) when a node sits at the kink gap = 0.
        """
        w = self.qp.weights
        g = self.space.B @ xI
        b = self.space.B @ d
        dSd = float(d @ (self.space.Q @ d))
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
        sp_, w, p = self.space, self.qp.weights, self.params
        S, BI, g = sp_.Q, sp_.B, sp_.q
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
            # Newton direction: (S + rho BA' W BA) d = -grad (dense: Woodbury with S = L L';
            # matrix-free: a sparse factorization of K + rho BA' W BA)
            d = sp_.direction(grad, A, rho)
            slope = grad @ d
            xs = self._size(xI)
            # Newton decrement -grad'd = |d|_H^2: relative to x'Sx it measures the squared
            # relative energy-norm distance to the minimiser; 1e-20 -> ~1e-10 (the stiff
            # directions make |grad| itself stall far above rounding when rho is large)
            xSx = max(float(xI @ (S @ xI)), self._energy2, 1e-300)
            if slope >= 0 or -slope <= 1e-20 * xSx or sp_.size(d) <= 1e-13 * xs:
                # the Newton step is at rounding level of x (or no longer a descent direction
                # because of rounding): xI is the minimiser to working precision
                return xI, steps, True
            t = self._exact_step(xI, d, rho, grad @ d)
            if not (t > 0 and np.isfinite(t)):
                return xI, steps, bool(sp_.size(d) <= 1e-10 * xs)
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
                    return xI, steps, bool(sp_.size(d) <= 1e-10 * xs)
            xI = xI + t * d
            self.report_iterate(self._steps_before + steps, lambda xI=xI: sp_.full(xI),   # Newton steps in all
                                lambda xI=xI: rho * w * np.maximum(-(BI @ xI), 0.0))   # stages; penalty forces
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
        w = self.qp.weights
        xn, mu, A = self.space.polish(xI, rho)
        gap = self.space.B @ xn
        xs = self._size(xn)
        if np.any(mu[A] <= 0) or np.any(gap[~A] < -1e-12 * xs):
            return None
        pen = float((mu[A] / (rho * w[A])).max(initial=0.0))
        return xn, mu, pen

    # ------------------------------------------------------------------ solve
    def _solve_friction(self) -> Solution:
        """Regularized friction (numerics/friction_penalty.py); Coulomb by the fixed point over Tresca solves."""
        qp, space = self.qp, self.space
        local = None if space.kind == "dense" else np.asarray(qp.local_dofs)
        r = solve_friction(qp, space, self.lay, self.params, self.rho0, self._length, self._energy2, local)
        return Solution(solver=self.name, status=Status(r.status), x=r.x, multipliers=r.mu, message=r.message,
                        iterations=r.iterations, history=r.history,
                        info={**self.op.info(), "factorizations": space.factorizations, "space": space.kind,
                              "rho0": self.rho0, **r.info})

    def solve(self) -> Solution:
        if self.friction:
            return self._solve_friction()
        p, sp_, w = self.params, self.space, self.qp.weights
        xI = sp_.start()                                # unconstrained minimiser
        self._deadline = time.perf_counter() + p["time_limit"]
        rho = self.rho0
        rho_max = self.rho0 * p["rho_max_factor"]
        history: list[dict] = []
        total, stage = 0, 0
        status, message = Status.INACCURATE, ""
        mu = np.zeros(self.qp.m)
        pen = float("nan")
        self.report_iterate(0, lambda: sp_.full(xI), mu)        # the start: the unconstrained minimiser
        while True:
            stage += 1
            self._steps_before = total
            xI, steps, ok = self._newton(xI, rho, history, stage)
            total += steps
            if not ok:
                status = Status.MAX_ITER
                message = f"Newton did not converge at rho = {rho:.3g} ({steps} steps)"
                if time.perf_counter() > self._deadline:
                    status, message = Status.TIME_LIMIT, f"time limit {p['time_limit']:g} s at rho = {rho:.3g}"
                mu = rho * w * np.maximum(-(sp_.B @ xI), 0.0)
                break
            pol = self._polish(xI, rho)
            if pol is None:   # active set not settled to rounding: keep the Newton iterate
                mu = rho * w * np.maximum(-(sp_.B @ xI), 0.0)
                pen = float(max(0.0, -(sp_.B @ xI).min(initial=0.0)))
            else:
                xI, mu, pen = pol
            xs = self._size(xI)
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
        x = sp_.full(xI)
        return Solution(
            solver=self.name, status=status, x=x, multipliers=mu,
            iterations={"newton": total, "continuation": stage}, history=history, message=message,
            info={**self.op.info(), **sp_.info(), "factorizations": sp_.factorizations,
                  "operator_factorizations": self.op.counters.factorizations,
                  "rho": rho, "rho0": self.rho0, "penetration": pen,
                  "penetration_rel": pen / max(np.abs(x).max(initial=0.0), self._length, 1e-300)},
        )

