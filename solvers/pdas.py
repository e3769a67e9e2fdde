"""Semismooth Newton / primal-dual active set (PDAS) on the complementarity form of the contact QP.

Everything happens on the contact dual through a :class:`dualfem.numerics.dual_operator.DualOperator`
(``operator``: ``dense``, the exact reduction onto the defect unknowns with D a dense matrix;
``matrix_free``, one sparse factorization of K and one solve per product D v; ``auto`` picks by size
and memory). The multipliers' problem is the linear complementarity problem

    gap(mu) = D mu + b0 >= 0,   mu >= 0,   mu . gap = 0,     D = BI S^-1 BI',  b0 = BI S^-1 g,

(D is the m x m Delassus matrix: symmetric positive definite, not an M-matrix in general), which
is written as the nonsmooth equation  Phi(mu) = mu - max(0, mu - c gap(mu)) = min(mu, c gap(mu)) = 0.
A semismooth Newton step from mu with active set A = {j : mu_j - c gap_j > 0} lands on the
Newton point  mu_A = -D_AA^-1 b0_A, mu_(not A) = 0  (the primal-dual active-set step).

Globalization (elasticity is not an M-matrix problem, so plain active-set steps can cycle):

* ``globalize = "armijo"`` (default): backtracking on the merit theta(mu) = 1/2 |Phi(mu)|^2
  with the sufficient-decrease test theta(mu + t d) <= (1 - 2 sigma t) theta(mu) (the Newton
  direction d satisfies Phi + G d = 0, so the directional derivative of theta is -2 theta). If
  no step passes down to 2^-max_backtracks, the full step is taken once per active set
  (non-monotone safeguard). A second full step with a set already used would repeat the same
  Newton point, i.e. a cycle; then the iteration switches, from max(mu, 0), to Bertsekas'
  projected Newton method on the dual energy q(mu) = 1/2 mu'D mu + b0'mu over mu >= 0
  (Armijo search along the projection arc; globally convergent, and it ends with full Newton
  steps on the final active set, so it is still exact). Only if that fails to decrease q does
  the solve stop, with ``Status.STAGNATION``. Every step counts as one Newton iteration.
* ``globalize = "none"``: plain PDAS (full steps); a repeated active set (a cycle) stops the
  solve with ``Status.STAGNATION``.

``c`` (units force / length) defaults to 1 / mean(diag D), which puts mu and c*gap on one scale;
it only affects damped steps (from a Newton point the next active set does not depend on c).

The Newton systems ``D_AA mu_A = -b0_A`` are solved by a dense Cholesky factorization (dense
operator) or, matrix-free, by Jacobi-preconditioned CG with the operator, warm-started from the
current forces (``newton="cg"``, the default; its iterations in ``info["cg_iterations"]``; preconditioned in face by
FETI's Dirichlet preconditioner of :mod:`dualfem.numerics.dual_precond`, ``precond``), or by one
sparse factorization of the Newton matrix K + B_A'C B_A per active set (one analysis for all, MKL
PARDISO) with augmented-Lagrangian steps (``newton="factor"``; ``info["al_steps"]``,
``info["newton_factorizations"]``). The two tie in time (docs/measurements.md); cg keeps no extra factor.

**Friction** (a QP with Tresca / Coulomb blocks, :mod:`dualfem.core.laws`): the dual operator is that of all blocks
stacked (:func:`dualfem.numerics.friction_dual.stacked_qp`, the same factorization of K) and the solve is
Hüeber-Stadler-Wohlmuth's semismooth Newton with contact / open and stick / slip sets
(:mod:`dualfem.numerics.friction_newton`; 2D boxes, 3D discs); Coulomb monolithic (``coulomb="newton"``: the
radius mu_f lambda inside the Newton system) or by the fixed point over Tresca solves (``coulomb="fixed_point"``,
:mod:`dualfem.numerics.coulomb`). Counters: ``iterations`` (newton, active_set_changes; the fixed point's),
``info`` (n_contact, n_stick, n_slip, gmres_iterations matrix-free). Not converged: ``max_iter``, never solved.

Multipliers are the nodal contact forces mu >= 0 with ``K x - F = B' mu``; x is recovered as
``K^-1 (F + B'mu)`` (dense: ``xI = S^-1 (g + BI' mu)`` and one solve with the cached factor of K_fixed),
then (dense operator) refined on the final active set.
"""
from __future__ import annotations

import sys
import time

import numpy as np
import scipy.linalg as sla

from dualfem.dual_solver import OPERATORS, DualOperatorSolver
from dualfem.numerics.coulomb import coulomb_fixed_point
from dualfem.numerics.dual_operator import FACE_METHODS
from dualfem.numerics.dual_precond import dirichlet_by_default, dirichlet_inverse
from dualfem.numerics.factor import from_param
from dualfem.numerics.friction_dual import FrictionLayout, friction_operator, layout_refusal
from dualfem.numerics.friction_newton import semismooth_newton
from dualfem.numerics.polish import refine_on_active_set
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status

#: relative accuracy of the matrix-free operator's CG on the Newton systems D_AA mu_A = -b0_A
FACE_RTOL = 1e-14
#: the smallest stopping tolerance of the matrix-free path (see PDASSolver._tol)
MATRIX_FREE_TOL = 1e-11


@register_solver
class PDASSolver(DualOperatorSolver):
    """Semismooth Newton (primal-dual active set) on the reduced dual LCP, globalised."""

    name = "pdas"
    family = "dual"
    #: friction (Tresca, Coulomb): HSW's semismooth Newton on the stacked dual (dualfem.numerics.friction_newton)
    accepts = ("signorini", "tresca", "coulomb")
    description = "semismooth Newton / primal-dual active set on the defect unknowns (exact)"
    tolerance = 1e-9
    exact = True
    #: the first reference solver: exact and the fastest; a reference refines to the rounding floor
    reference = True
    reference_rank = 0
    reference_params = {"refine_tol": 1e-16}
    defaults = {
        "max_iter": 100,
        "tol": 1e-13,
        "c": 0.0,
        "globalize": "armijo",
        "sigma": 1e-4,
        "max_backtracks": 30,
        "refine": 1,              # at most this many refinement steps on the final active set
        "refine_tol": 2.5e-10,    # ... each taken only if its exact size |dx|_K / |x|_K exceeds this
                                  # (a quarter of the declared 1e-9: that size IS the certified error
                                  # of the unrefined x; 1e-16: always, to the rounding floor, as the
                                  # reference does)
        "factor": "auto",         # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
        "operator": "auto",       # dual operator: dense reduction, matrix_free (K-solves), auto (by size, memory)
        "precond": "auto",        # matrix-free CG on the Newton systems: auto = dirichlet (FETI's, per crack; 2D) or
                                  # jacobi (3D) | dirichlet | jacobi
        "layers": 4,              # precond=dirichlet: rings of elements of the local Schur complements
        "newton": "cg",           # matrix-free Newton systems D_AA mu_A = -b0_A: "cg" (Jacobi-PCG with D, warm-
                                  # started) or "factor" (one factorization of K + B_A'C B_A per set, augmented-
                                  # Lagrangian steps, CG polish): 269 k unknowns, 3,200 defect nodes, 4 Newton
                                  # steps: cg 8.2 s (149 K-solves), factor 7.9 s (4 factorizations, 95 solves)
                                  # on a loaded machine: a tie; cg keeps no extra factor (memory)
        "time_limit": 600.0,      # seconds of solve time (checked once per Newton step)
        "coulomb": "newton",      # Coulomb friction: "newton" (monolithic: the radius mu_f lambda inside the Newton
                                  # system) or "fixed_point" (dualfem.numerics.coulomb over Tresca Newton solves)
        "verbose": False,         # print one line per Newton step to stderr
    }

    ranges = {"c": "[0, inf)", "globalize": ("armijo", "none"), "sigma": "(0, 0.5)", "max_backtracks": "[1, inf)",
              "refine": "[0, inf)", "refine_tol": "(0, inf)", "factor": None,
              "operator": OPERATORS, "newton": FACE_METHODS,
              "precond": ("auto", "dirichlet", "jacobi"), "layers": "[1, inf)",
              "coulomb": ("newton", "fixed_point")}   # c = 0: automatic

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # Newton converges quadratically to the exact Newton point: the stopping test only
        # needs to be below the requested accuracy; keep it at least as strict as the default.
        # refinement: taken when the step (= the certified error of the unrefined x) exceeds a
        # quarter of the requested accuracy
        return {"tol": min(float(tol) * 1e-3, cls.defaults["tol"]),
                "refine_tol": min(float(tol) * 0.25, cls.defaults["refine_tol"])}

    def _projected_newton_step(self, mu, gap, c):
        """One step of Bertsekas' projected Newton method on q(mu) = 1/2 mu'D mu + b0'mu, mu >= 0.

        ``gap`` = D mu + b0 is the gradient of q. Unknowns at (or within eps of) their bound with
        a positive gradient are held; Newton on the rest, scaled gradient on the held ones, and an
        Armijo search along the projection arc. Returns (new mu, step, #free) or None.
        """
        op, p = self.op, self.params
        dD = op.diagonal()
        w = np.linalg.norm(mu - np.maximum(mu - c * gap, 0.0))
        eps = min(w, 1e-3 * max(np.abs(mu).max(initial=0.0), 1e-300))
        held = (mu <= eps) & (gap > 0)
        free = ~held
        d = np.zeros_like(mu)
        d[held] = -gap[held] / dD[held]
        if free.any():
            d[free] = self._face_solve(free, -gap[free])
        q0 = op.dual_energy(mu)
        t = 1.0
        for _ in range(int(p["max_backtracks"]) + 1):
            mt = np.maximum(mu + t * d, 0.0)
            qt = op.dual_energy(mt)
            dec = -t * gap[free] @ d[free] + gap[held] @ (mu[held] - mt[held])
            if q0 - qt >= p["sigma"] * dec and (q0 - qt > 0 or np.array_equal(mt, mu)):
                return mt, t, int(free.sum())
            t *= 0.5
        return None

    def _refine(self, x, mu, steps):
        """Iterative refinement on the final active set (:func:`dualfem.numerics.polish.refine_on_active_set`)."""

        return refine_on_active_set(self.qp, self.op.reduction, x, mu, steps, float(self.params["refine_tol"]))

    # ------------------------------------------------------------------ solve
    def skip(self, qp) -> str | None:
        if qp.blocks:
            refusal = layout_refusal(qp)
            if refusal is not None:
                return refusal
        return super().skip(qp)

    def setup(self, qp) -> None:
        if qp.blocks:                      # friction: the dual operator of all blocks stacked (same factorization)
            self.qp = qp
            self.op = friction_operator(qp, self.params["operator"], from_param(self), self.tolerance)
            self.reduction = None          # the stacked QP's reduction is not the QP's (its B differs)
            return
        super().setup(qp)
        if self.op.kind == "matrix_free":
            self.op.face = self.params["newton"]
            auto = self.params["precond"] == "auto"        # FETI's Dirichlet in 2D, Jacobi in 3D
            if self.params["precond"] == "dirichlet" or (auto and dirichlet_by_default(qp)):
                self.op.face_preconditioner = dirichlet_inverse(qp, int(self.params["layers"]))

    def _tol(self) -> float:
        """The stopping tolerance: ``tol``; matrix-free at least :data:`MATRIX_FREE_TOL`: the Newton points
        are known to the face solves' accuracy (CG to :data:`FACE_RTOL`), and the gaps D mu + b0 are
        computed through K-solves whose rounding differs from the factorization of the Newton systems by
        ~1e-12 relative (docs/measurements.md)."""
        tol = float(self.params["tol"])
        return tol if self.op.kind == "dense" else max(tol, MATRIX_FREE_TOL)

    def _stop(self, res: float, k: int, deadline: float, projected: bool) -> tuple[Status, str] | None:
        """(status, message) when the iteration ends before Newton step k + 1, else None."""
        p = self.params
        if res <= self._tol():
            extra = " (after a cycle, by projected Newton)" if projected else ""
            return Status.SOLVED, f"converged: |min(mu, c gap)| = {res:.1e} (relative){extra}"
        if k >= p["max_iter"]:
            return Status.MAX_ITER, f"no convergence in {p['max_iter']} Newton steps"
        if time.perf_counter() > deadline:
            return Status.TIME_LIMIT, f"time limit {p['time_limit']:g} s after {k} Newton steps"
        return None

    def _armijo(self, mu: np.ndarray, d: np.ndarray, theta: float, phi) -> tuple[float, str]:
        """Step length along d by backtracking on the merit 1/2 |Phi|^2 (sufficient decrease sigma)."""
        p, t = self.params, 1.0
        for _ in range(int(p["max_backtracks"]) + 1):
            mt = mu + t * d
            Pt = phi(mt, self.op.apply(mt) + self.op.b0)
            if 0.5 * Pt @ Pt <= (1.0 - 2.0 * p["sigma"] * t) * theta:
                return t, "full"
            t *= 0.5
        return 1.0, "safeguard"

    def _newton_point(self, mu: np.ndarray, gap: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
        """The semismooth Newton (PDAS) point for the active set A = {mu - c gap > 0}, and A."""
        A = (mu - c * gap) > 0
        mu_n = np.zeros(mu.size)
        if A.any():
            mu_n[A] = self._face_solve(A, -self.op.b0[A], x0=mu[A])
        return mu_n, A

    def _face_solve(self, A: np.ndarray, rhs: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """D_AA^-1 rhs; where D_AA is singular (dependent or duplicated rows of B: the multipliers are not
        unique, which is normal) and D is dense, the minimum-norm solution (least squares, numpy's rank
        threshold m eps): it splits a force evenly over duplicated rows. Raises what the operator raises
        otherwise."""
        try:
            return self.op.face_solve(A, rhs, x0=x0, rtol=FACE_RTOL)
        except (np.linalg.LinAlgError, ValueError):
            D = getattr(self.op, "D", None)
            if self.op.kind != "dense" or D is None:
                raise
            DA = D[np.ix_(A, A)]
            return sla.lstsq(DA, rhs, cond=A.sum() * np.finfo(float).eps)[0]

    def _polish(self, mu: np.ndarray) -> np.ndarray:
        """The exact Newton point of the converged active set, kept only if consistent (forces >= 0
        on the set, gaps >= 0 off it, to rounding: :meth:`~dualfem.numerics.dual_operator.DualOperator.
        face_minimiser`); else mu clipped at 0."""
        try:
            mu_p = self.op.face_minimiser(mu, self.params["tol"], rtol=FACE_RTOL)
        except (np.linalg.LinAlgError, ValueError):     # singular face (dependent rows): keep the Newton point
            mu_p = None
        return np.maximum(mu, 0.0) if mu_p is None else mu_p

    def _solve_friction(self) -> Solution:
        """Tresca / Coulomb friction: HSW's semismooth Newton (:mod:`dualfem.numerics.friction_newton`)."""
        p, op = self.params, self.op
        layout = FrictionLayout.of(self.qp)
        c = p["c"] if p["c"] > 0 else (1.0 / op.diagonal().mean() if op.b0.size else 1.0)
        deadline = time.perf_counter() + p["time_limit"]
        if layout.coulomb.any() and p["coulomb"] == "fixed_point":
            return self._coulomb_fixed_point(c, deadline)
        r = semismooth_newton(op, layout, c, self._tol(), int(p["max_iter"]), deadline=deadline)
        if r.converged:
            status = Status.SOLVED
        else:
            status = Status.TIME_LIMIT if time.perf_counter() > deadline else Status.MAX_ITER
        x = op.x_of(r.mu)
        self.report_iterate(r.steps, lambda: x, r.mu)
        return Solution(solver=self.name, status=status, x=x, multipliers=r.mu,
                        iterations={"newton": r.steps, "active_set_changes": r.changes}, history=r.history,
                        message=r.message,
                        info={"c": c, "active_set_changes": r.changes, **{f"n_{k}": v for k, v in r.sets.items()},
                              "gmres_iterations": r.gmres_iterations, "friction": "semismooth newton (HSW)",
                              "n_local": int(self.qp.local_dofs.size), **op.info()})

    def _coulomb_fixed_point(self, c: float, deadline: float) -> Solution:
        """Coulomb by the fixed point g <- mu_f lambda / w (:mod:`dualfem.numerics.coulomb`), each Tresca problem by
        the semismooth Newton warm-started from the previous answer."""
        op, p, failed = self.op, self.params, []
        counts = {"newton": 0, "active_set_changes": 0}

        def solve_tresca(qpt, warm):
            r = semismooth_newton(op, FrictionLayout.of(qpt), c, self._tol(), int(p["max_iter"]), deadline=deadline,
                                  mu0=None if warm is None else warm[1])
            counts["newton"] += r.steps
            counts["active_set_changes"] += r.changes
            if not r.converged:
                failed.append(r.message)
            return op.x_of(r.mu), r.mu, {}

        fp = coulomb_fixed_point(self.qp, solve_tresca, 1e-11, 50)
        status = Status.SOLVED if fp.status == "solved" and not failed else Status.MAX_ITER
        message = (f"Coulomb fixed point {fp.status} in {fp.iterations} Tresca solves by semismooth Newton"
                   + (f"; an inner solve failed: {failed[-1]}" if failed else ""))
        return Solution(solver=self.name, status=status, x=fp.x, multipliers=fp.mu,
                        iterations={**counts, **fp.summary()}, message=message,
                        info={"c": c, "friction": "coulomb fixed point over semismooth newton",
                              "coulomb_changes": fp.changes, **op.info()})

    def solve(self) -> Solution:
        if self.qp.blocks:
            return self._solve_friction()
        p = self.params
        op, b0 = self.op, self.op.b0
        c = p["c"] if p["c"] > 0 else (1.0 / op.diagonal().mean() if b0.size else 1.0)
        mu = np.zeros(b0.size)
        # scale of Phi for the stopping test: forces c*|gap| and |mu| at the unconstrained point
        scale0 = max(c * np.abs(b0).max(initial=0.0), 1e-300)

        def phi(mu_, gap_):
            return np.minimum(mu_, c * gap_)

        def state(mu_):          # gaps, the complementarity function Phi and the merit 1/2 |Phi|^2 at mu_
            g = op.apply(mu_) + b0
            P = phi(mu_, g)
            return g, P, 0.5 * P @ P

        gap, Phi, theta = state(mu)
        used_full: set[bytes] = set()
        last_key = b""
        history: list[dict] = []
        k, projected = 0, False
        deadline = time.perf_counter() + p["time_limit"]
        self.report_iterate(0, lambda: op.x_of(mu), mu)        # the start: mu = 0
        while True:
            res = np.abs(Phi).max(initial=0.0) / max(scale0, np.abs(mu).max(initial=0.0))
            stop = self._stop(res, k, deadline, projected)
            if stop is not None:
                status, message = stop
                break
            k += 1
            if projected:
                step = self._projected_newton_step(mu, gap, c)
                if step is None:
                    status = Status.STAGNATION
                    message = (f"projected Newton found no decrease of the dual energy at step {k} "
                               f"(residual {res:.1e})")
                    k -= 1
                    break
                mu, t, nA = step
                how = "projected"
            else:
                try:
                    mu_n, A = self._newton_point(mu, gap, c)
                except (np.linalg.LinAlgError, ValueError) as exc:
                    status, message = Status.NUMERICAL_ERROR, f"Newton system singular: {exc}"
                    break
                nA, d, key = int(A.sum()), mu_n - mu, np.packbits(A).tobytes()
                t, how = self._armijo(mu, d, theta, phi) if p["globalize"] == "armijo" else (1.0, "full")
                # with CG face solves (matrix-free) the same set again is a refinement of its Newton point
                # (warm-started), not a cycle
                refining = self.op.kind != "dense" and key == last_key
                last_key = key
                if t == 1.0 and key in used_full and not refining:
                    if p["globalize"] == "none":
                        status = Status.STAGNATION
                        message = (f"cycling: the active set of {nA} nodes repeats at Newton step {k} "
                                   f"(plain PDAS; use globalize=armijo)")
                        k -= 1
                        break
                    projected = True        # a cycle: switch to the monotone method
                    mu = np.maximum(mu, 0.0)
                    k -= 1
                    gap, Phi, theta = state(mu)
                    history.append({"iter": k, "kind": "cycle detected: switch to projected Newton"})
                    continue
                if t == 1.0:
                    used_full.add(key)
                    mu = mu_n
                else:
                    mu = mu + t * d
                    how = "damped"
            gap, Phi, theta = state(mu)
            self.report_iterate(k, lambda mu=mu: op.x_of(mu), mu)
            history.append({"iter": k, "active": nA, "step": t, "kind": how,
                            "residual": float(np.abs(Phi).max(initial=0.0) / max(scale0, np.abs(mu).max(initial=0.0)))})
            if p["verbose"]:
                print(f"pdas: step {k} {how} t={t:g} active {nA} residual {history[-1]['residual']:.2e}",
                      file=sys.stderr)
        return self._finish(status, mu, message, k, history, c)

    def _finish(self, status: Status, mu: np.ndarray, message: str, k: int, history: list[dict],
                c: float) -> Solution:
        """x from the contact forces (polished and refined when solved) and the Solution."""
        if status == Status.SOLVED:
            mu = self._polish(mu)
        x = self.op.x_of(mu)
        refined = 0
        if status == Status.SOLVED and self.op.reduction is not None:
            x, mu, refined = self._refine(x, mu, int(self.params["refine"]))
        return Solution(solver=self.name, status=status, x=x, multipliers=mu,
                        iterations={"newton": k}, history=history, message=message,
                        info={"c": c, "refinement_steps": refined, "n_active": int((mu > 0).sum()),
                              "n_local": int(self.qp.local_dofs.size), **self.op.info(),
                              "precond": ("dirichlet" if self.op.face_preconditioner is not None else "jacobi")
                              if self.op.kind == "matrix_free" else "none",
                              "reduction_time_s": getattr(self.op.reduction, "time_s", {})})
