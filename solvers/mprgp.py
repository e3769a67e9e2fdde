"""MPRGP: Dostal's modified proportioning with reduced gradient projections, on the contact dual.

With the Delassus matrix ``D = B K^-1 B'`` (symmetric positive definite, m x m) and the gaps at
zero contact force ``b0 = B K^-1 F`` (:meth:`dualfem.numerics.linalg.LocalReduction.dual`: the gaps at
forces mu are ``D mu + b0``), the contact forces minimise

    q(mu) = 1/2 mu'D mu + b0'mu   over  mu >= 0,         gradient g(mu) = D mu + b0 = the gaps,

and ``x = K^-1 (F + B'mu)`` (one K-solve). MPRGP (Dostal & Schoeberl 2005; Dostal, *Optimal
quadratic programming algorithms*, 2009) splits the gradient into the free gradient
``phi`` (components with mu_j > 0) and the chopped gradient ``beta`` (``min(g_j, 0)`` where
mu_j = 0); the projected gradient is ``g^P = phi + beta``. Each iteration is one of

* a **CG step** along the conjugate direction p when it stays feasible;
* an **expansion step**: the largest feasible CG step, then a projected gradient step of fixed
  length alpha in (0, 2/|D|] along the free gradient (adds constraints to the active set);
* a **proportioning step**: a minimisation along beta when ``|beta|^2 > Gamma^2 phi~'phi``
  (frees constraints; ``phi~`` is the free gradient reduced so that a step alpha stays feasible).

Stopping test (scale-free): ``|g^P(mu)| <= tol |b0|``. |D| is estimated by power iterations
(``alpha = alpha_factor / |D|_est``). ``b0 = 0`` (no load) gives mu = 0 at once.

Then, as pdas does, the result is polished on its final active set A = {mu > 0}: the exact
minimiser of q on that face (``D_AA mu_A = -b0_A``) is kept if it is consistent (mu_A >= 0,
inactive gaps >= 0), and (dense operator) one iterative-refinement step of the full KKT system
(:func:`dualfem.numerics.polish.refine_on_active_set`) removes the rounding error of the reduction.

Operators: ``operator = "dense"`` (default) uses the dense D of the local reduction (as pdas);
``"matrixfree"`` never forms D: one sparse LU of K (SuperLU) and one K-solve per product
``D v = B K^-1 B'v``, for QPs with many constrained nodes; its face polish uses CG on D_AA.
Multipliers are nodal contact forces (mu >= 0, ``Kx - F = B'mu``).
"""
from __future__ import annotations

import time

import numpy as np

from dualfem.core.registry import register_solver
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.numerics.linalg import MAX_LOCAL, LocalReduction, sparse_factor, too_many_local
from dualfem.numerics.polish import refine_on_active_set


class _Dense:
    """D and b0 from :class:`dualfem.numerics.linalg.LocalReduction` (dense, m x m)."""

    def __init__(self, qp):

        self.red = LocalReduction(qp)
        self.D, self.b0 = self.red.dual()
        self.solves = 0

    def matvec(self, v: np.ndarray) -> np.ndarray:
        return self.D @ v

    def face_solve(self, A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        import scipy.linalg as sla

        return sla.solve(self.D[np.ix_(A, A)], rhs, assume_a="pos")

    def x_of(self, mu: np.ndarray) -> np.ndarray:
        import scipy.linalg as sla

        red = self.red
        return red.full(sla.cho_solve(red.S_cho, red.g + red.BI.T @ mu))


class _MatrixFree:
    """D v = B K^-1 B'v with one sparse factorization of K (no m x m matrix is formed)."""

    def __init__(self, qp):

        self.qp = qp
        self.lu = sparse_factor(qp.K)          # the chosen backend (--factor / DUALFEM_FACTOR / fastest)
        self.solves = 1
        self.b0 = qp.B @ self.lu.solve(qp.F)
        self.D = None

    def matvec(self, v: np.ndarray) -> np.ndarray:
        self.solves += 1
        return self.qp.B @ self.lu.solve(self.qp.B.T @ v)

    def face_solve(self, A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """CG on D_AA (matrix-free) to rounding level."""
        import scipy.sparse.linalg as spla

        idx = np.flatnonzero(A)

        def mv(w):
            v = np.zeros(self.qp.m)
            v[idx] = w
            return self.matvec(v)[idx]

        op = spla.LinearOperator((idx.size, idx.size), matvec=mv, dtype=float)
        sol, info = spla.cg(op, rhs, rtol=1e-14, atol=0.0, maxiter=10 * idx.size + 50)
        if info != 0:
            raise np.linalg.LinAlgError(f"CG on the active face did not converge (info {info})")
        return sol

    def x_of(self, mu: np.ndarray) -> np.ndarray:
        self.solves += 1
        return self.lu.solve(self.qp.F + self.qp.B.T @ mu)


def norm_estimate(matvec, m: int, iters: int) -> float:
    """|D| by power iterations from a fixed positive start vector (a lower estimate)."""
    v = np.ones(m) / np.sqrt(max(m, 1))
    lam = 0.0
    for _ in range(iters):
        w = matvec(v)
        lam = float(np.linalg.norm(w))
        if lam == 0.0:
            return 0.0
        v = w / lam
    return lam


def mprgp(matvec, b0: np.ndarray, alpha: float, gamma: float, tol: float, max_iter: int,
          time_limit: float, verbose: bool = False):
    """MPRGP for min 1/2 mu'D mu + b0'mu, mu >= 0. Returns (mu, counts, status, message, history)."""
    m = b0.size
    mu = np.zeros(m)
    g = b0.copy()                                   # D mu + b0 at mu = 0
    counts = {"cg": 0, "expansion": 0, "proportioning": 0}
    history: list[dict] = []
    target = tol * np.linalg.norm(b0)
    t0 = time.perf_counter()

    def split(mu_, g_):
        free = mu_ > 0
        phi = np.where(free, g_, 0.0)
        beta = np.where(free, 0.0, np.minimum(g_, 0.0))
        return free, phi, beta

    free, phi, beta = split(mu, g)
    p = phi.copy()
    k = 0
    while True:
        gp = np.linalg.norm(phi + beta)
        if gp <= target:
            rel = gp / max(np.linalg.norm(b0), 1e-300)
            return mu, counts, Status.SOLVED, f"converged: |g^P| = {rel:.1e} |b0|", history
        if k >= max_iter:
            return mu, counts, Status.MAX_ITER, f"no convergence in {max_iter} iterations (|g^P|/|b0| = " \
                f"{gp / np.linalg.norm(b0):.1e})", history
        if time.perf_counter() - t0 > time_limit:
            return mu, counts, Status.TIME_LIMIT, f"time limit {time_limit:g} s after {k} iterations", history
        k += 1
        phit = np.where(free, np.minimum(mu / alpha, phi), 0.0)
        if beta @ beta <= gamma ** 2 * (phit @ phi):
            if not p.any():
                p = phi.copy()
            Ap = matvec(p)
            pAp = p @ Ap
            a_cg = (g @ p) / pAp
            pos = p > 0
            a_f = np.min(mu[pos] / p[pos]) if pos.any() else np.inf
            if a_cg <= a_f:
                mu = mu - a_cg * p
                g = g - a_cg * Ap
                free, phi, beta = split(mu, g)
                p = phi - ((phi @ Ap) / pAp) * p
                counts["cg"] += 1
                kind = "cg"
            else:
                mu = np.maximum(mu - a_f * p, 0.0)
                g = g - a_f * Ap
                free, phi, _ = split(mu, g)
                mu = np.maximum(mu - alpha * phi, 0.0)
                g = matvec(mu) + b0
                free, phi, beta = split(mu, g)
                p = phi.copy()
                counts["expansion"] += 1
                kind = "expansion"
        else:
            Ad = matvec(beta)
            a = (g @ beta) / (beta @ Ad)
            mu = np.maximum(mu - a * beta, 0.0)
            g = g - a * Ad
            free, phi, beta = split(mu, g)
            p = phi.copy()
            counts["proportioning"] += 1
            kind = "proportioning"
        if verbose:
            history.append({"iter": k, "kind": kind, "active": int((~free).sum()),
                            "proj_grad": float(np.linalg.norm(phi + beta))})


@register_solver
class MPRGPSolver(Solver):
    """MPRGP on the reduced contact dual, with a final face polish (exact)."""

    name = "mprgp"
    description = "MPRGP (Dostal's modified proportioning / reduced gradient projections) on the dual (exact)"
    tolerance = 1e-9
    exact = True
    defaults = {
        "tol": 1e-12,             # stop at |g^P(mu)| <= tol |b0| (projected gradient of the dual)
        "max_iter": 10000,
        "time_limit": 600.0,      # seconds of solve time
        "verbose": False,         # keep a per-iteration history
        "operator": "dense",      # "dense": D from the local reduction; "matrixfree": one K-solve per product
        "gamma": 1.0,             # proportioning parameter Gamma > 0
        "alpha_factor": 1.8,      # expansion steplength alpha = alpha_factor / |D|_est, in (0, 2]
        "power_iter": 20,         # power iterations for |D|
        "refine": 1,              # iterative-refinement steps of the final KKT system (dense operator)
    }

    ranges = {"operator": ("dense", "matrixfree"), "gamma": "(0, inf)", "alpha_factor": "(0, 2]",
              "power_iter": "[1, inf)", "refine": "[0, inf)"}

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": min(float(tol) * 1e-3, cls.defaults["tol"])}

    def skip(self, qp) -> str | None:
        return too_many_local(qp, MAX_LOCAL) if self.params["operator"] == "dense" else None

    def setup(self, qp) -> None:
        self.qp = qp
        self.op = _Dense(qp) if self.params["operator"] == "dense" else _MatrixFree(qp)
        self.reduction = getattr(self.op, "red", None)
        m = qp.m
        self.norm = norm_estimate(self.op.matvec, m, int(self.params["power_iter"])) if m else 0.0

    def solve(self) -> Solution:
        p, op, qp = self.params, self.op, self.qp
        b0 = op.b0
        if qp.m == 0 or not np.any(b0):
            mu = np.zeros(qp.m)
            return Solution(solver=self.name, status=Status.SOLVED, x=op.x_of(mu), multipliers=mu,
                            iterations={"cg": 0, "expansion": 0, "proportioning": 0},
                            message="no load on the constraints (b0 = 0): mu = 0")
        alpha = p["alpha_factor"] / self.norm
        mu, counts, status, message, history = mprgp(op.matvec, b0, alpha, p["gamma"], p["tol"],
                                                     int(p["max_iter"]), p["time_limit"], p["verbose"])
        info: dict = {"alpha": alpha, "norm_D_est": self.norm, "operator": p["operator"]}
        if status == Status.SOLVED:
            mu, info["face_polish"] = self._face_polish(mu, b0)
        x = op.x_of(mu)
        if status == Status.SOLVED and p["operator"] == "dense" and p["refine"] > 0:
            x, mu, info["refinement_steps"] = self._refine(x, mu, int(p["refine"]))
        info["k_solves"] = getattr(op, "solves", 0)
        info["n_active"] = int((mu > 0).sum())
        return Solution(solver=self.name, status=status, x=x, multipliers=mu, iterations=counts,
                        history=history, message=message, info=info)

    def _face_polish(self, mu: np.ndarray, b0: np.ndarray) -> tuple[np.ndarray, bool]:
        """Exact minimiser of q on the face {mu_j = 0 off A}, kept if consistent."""
        A = mu > 0
        mu_p = np.zeros_like(mu)
        try:
            if A.any():
                mu_p[A] = self.op.face_solve(A, -b0[A])
        except (np.linalg.LinAlgError, ValueError):
            return mu, False
        gap = self.op.matvec(mu_p) + b0
        if np.all(mu_p >= 0) and np.all(gap[~A] >= -self.params["tol"] * np.abs(b0).max()):
            return mu_p, True
        return mu, False

    def _refine(self, x, mu, steps):
        """Iterative refinement on the final active set (:func:`dualfem.numerics.polish.refine_on_active_set`)."""

        return refine_on_active_set(self.qp, self.op.red, x, mu, steps)
