"""The spaces the generalized-Newton inner loop of Uzawa on the modified Lagrangian runs in
(``solvers/uzawa.py``; moved here verbatim from it to keep that plugin one concept per module).

Each space offers the same operations on the unknowns it works in: ``start()`` (the unconstrained
minimizer K^-1 F), ``qgrad(z)`` (Kz - F), ``qform(d)`` (d'Kd), ``norm2(z)`` (the inner test's squared
norm), ``newton(coef, rhs)`` (the solve with K + B' diag(coef) B), ``full(z)`` (the vector on all
unknowns), ``mu_min(w)`` (the smallest eigenvalue of the weighted dual compliance W^1/2 D W^1/2 on its
range, with a dict saying how it was computed) and ``factorizations`` (how many numeric
factorizations it made).

* :class:`ReducedSpace`: dense, on the local unknowns I of the exact reduction (the dense operator);
* :class:`FullSpace`: the textbook sparse path on all unknowns (``linalg="full"``);
* :class:`SparseSpace`: sparse on all unknowns with one analysis (the matrix-free operator).

The three compute the same iterates to rounding (``solvers/uzawa.py``'s module docstring says why).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.numerics.linalg import LocalReduction, sparse_factor
from dualfem.numerics.newton_matrix import NewtonMatrix

EPS = float(np.finfo(float).eps)

#: the matrix-free path computes mu_min densely (one block of m products) up to this many rows
DENSE_EIG_MAX = 32


def armijo_step(Gd: float, dQd: float, remainder, w: np.ndarray, r: float, p: dict) -> float | None:
    """The Armijo step along a generalized Newton direction d of the modified Lagrangian M (the paper's inner loop,
    with or without friction): s = 1, divided by ``p["step_factor"]`` until M(x - s d) - M(x) = -s Gd + s^2/2 dQd +
    w'remainder(s) / (2 r) <= -armijo_c s Gd, at most ``p["max_backtracks"]`` times; None when none was accepted.
    ``Gd`` = grad'd (> 0), ``dQd`` = d'Qd, ``remainder(s)`` the per-row remainder of the penalty's linearization at
    step s (a law's own, in a cancellation-free form)."""
    s = 1.0
    for _ in range(int(p["max_backtracks"])):
        dM = -s * Gd + 0.5 * s * s * dQd + float(w @ remainder(s)) / (2.0 * r)
        if dM <= -p["armijo_c"] * s * Gd:
            return s
        s /= p["step_factor"]
    return None


class ReducedSpace:
    """Dense linear algebra on the local unknowns I (exact reduction).

    A Newton matrix Q + B_A' C_A B_A (C_A = diag(coef) on the active set A) is never formed: with
    Q = L L' and V = L^-1 B' (so that the Delassus matrix is D = B Q^-1 B' = V'V), the
    Sherman-Morrison-Woodbury identity gives its solve as
    ``d = L'^-1 (h - V_A t)``,  h = L^-1 g,  t = (C_A^-1 + D_AA)^-1 V_A' h,
    with L, V and D shared with the reduction (and with the certificate). Per active set one
    |A| x |A| Cholesky factorization (|A| <= m = |I| / 4) instead of one of |I| x |I|: 1/64 of the
    work or less; per step two triangular solves, as with a factor of the Newton matrix.
    C_A^-1 + D_AA is symmetric positive definite and its conditioning is D's, however large C_A.
    """

    kind = "dense"

    def __init__(self, qp, norm: str, factor: str | None = None, reduction: LocalReduction | None = None):

        if norm != "energy":
            raise InputError("parameter 'inner_norm' of solver 'uzawa' must be 'energy' with "
                             "linalg='reduced' ('euclidean' needs linalg='full')")
        self.red = red = reduction if reduction is not None else LocalReduction(qp, factor=factor)
        self.Q, self.q, self.B = red.S, red.g, red.BI
        self.c0 = red.c0
        self._chol_S = red.S_cho
        self._cache: dict[bytes, tuple] = {}
        self.factorizations = 0

    def start(self) -> np.ndarray:
        return la.cho_solve(self._chol_S, self.q, check_finite=False)

    def dual_compliance(self, w: np.ndarray) -> np.ndarray:
        """G W with G = B K^-1 B' (jump per nodal force): the Hessian of the dual in l."""
        return self.red.delassus() * w[None, :]

    def mu_min(self, w: np.ndarray) -> tuple[float, dict]:
        """(smallest eigenvalue of W^1/2 G W^1/2, how): a dense symmetric eigensolver on the m x m matrix."""
        GW = self.dual_compliance(w)
        sw = np.sqrt(w)
        sym = (GW / w[None, :]) * sw[:, None] * sw[None, :]   # W^1/2 G W^1/2
        return _range_min(np.linalg.eigvalsh(0.5 * (sym + sym.T))), {"mu_min_method": "dense eigvalsh"}

    def qgrad(self, z):
        return self.Q @ z - self.q

    def qform(self, d):
        return float(d @ (self.Q @ d))

    def norm2(self, z):
        return float(z @ (self.Q @ z) - 2.0 * self.c0)

    def newton(self, coef: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Solve (Q + B' diag(coef) B) d = rhs; coef = r*w on the active set, 0 elsewhere."""
        L = self._chol_S[0]
        h = la.solve_triangular(L, rhs, lower=True, check_finite=False)
        A = np.flatnonzero(coef)
        if A.size:
            key = coef.tobytes()
            fac = self._cache.get(key)
            if fac is None:
                cap = self.red.delassus()[np.ix_(A, A)]
                cap[np.diag_indices_from(cap)] += 1.0 / coef[A]
                fac = la.cho_factor(cap, lower=True, check_finite=False)
                self.factorizations += 1
                if len(self._cache) >= 64:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[key] = fac
            VA = self.red.half_delassus()[:, A]
            h = h - VA @ la.cho_solve(fac, VA.T @ h, check_finite=False)
        return la.solve_triangular(L, h, lower=True, trans="T", check_finite=False)

    def full(self, z):
        return self.red.full(z)


def _range_min(ev: np.ndarray) -> float:
    """The smallest eigenvalue of the dual compliance on its range: dependent or duplicated rows of B
    (multipliers not unique) give eigenvalues 0 to rounding (below m eps max, numpy's rank threshold),
    whose directions change no x; the dual is strongly concave on the rest, and r is chosen from that."""
    top = float(ev.max(initial=0.0))
    kept = ev[ev > ev.size * EPS * top]
    return float(kept.min()) if kept.size else float(ev.min(initial=0.0))


class FullSpace:
    """Textbook sparse linear algebra on all unknowns (refactorizes every Newton step)."""

    kind = "full"

    def __init__(self, qp, norm: str, factor: str | None = None):
        self.Q, self.q, self.B = qp.K.tocsr(), qp.F, qp.B.tocsr()
        self.qp, self.norm, self.factor = qp, norm, factor
        self.factorizations = 0

    def start(self):
        self.factorizations += 1
        return sparse_factor(self.Q, self.factor).solve(self.q)

    def qgrad(self, z):
        return self.Q @ z - self.q

    def qform(self, d):
        return float(d @ (self.Q @ d))

    def norm2(self, z):
        return float(z @ (self.Q @ z)) if self.norm == "energy" else float(z @ z)

    def newton(self, coef, rhs):
        H = (self.Q + self.B.T @ sp.diags(coef) @ self.B).tocsr()
        self.factorizations += 1
        return sparse_factor(H, self.factor).solve(rhs)

    def full(self, z):
        return z

    def mu_min(self, w):
        return ReducedSpace(self.qp, "energy", self.factor).mu_min(w)


class SparseSpace:
    """Sparse linear algebra on all unknowns with one analysis (the matrix-free operator's path).

    The Newton matrices K + B' diag(coef) B share the pattern of K + B'B
    (:class:`dualfem.numerics.newton_matrix.NewtonMatrix`): analyzed once, one numeric factorization
    per new active set (``keep`` factors kept). The start K^-1 F and the products D v of the
    Lanczos estimate of mu_min use the operator's factorization of K (shared with the certificate
    through the QP's store). Every quantity of the inner and outer tests is the full-space one,
    equal to the reduced space's (module docstring of solvers/uzawa.py), so the iterates are the
    dense path's to rounding.
    """

    kind = "matrix_free"

    def __init__(self, qp, op, factor: str | None = None, keep: int = 4):
        self.qp, self.op = qp, op
        self.Q, self.q, self.B = qp.K.tocsr(), np.asarray(qp.F, float), op.B
        self.nm = op.newton_matrix(keep) if not getattr(op, "exact", True) \
            else NewtonMatrix(qp.K, qp.B, factor, keep=keep)

    @property
    def factorizations(self) -> int:
        return self.nm.counters.factorizations

    def start(self):
        return self.op.k_solve(self.q)

    def qgrad(self, z):
        return self.Q @ z - self.q

    def qform(self, d):
        return float(d @ (self.Q @ d))

    def norm2(self, z):
        return float(z @ (self.Q @ z))

    def newton(self, coef, rhs):
        return self.nm.solve(coef, rhs)

    def full(self, z):
        return z

    def mu_min(self, w, tol: float = 1e-2):
        """(estimate of the smallest eigenvalue of W^1/2 D W^1/2, how): Lanczos (ARPACK ``eigsh``,
        which="SA") on products with the matrix-free operator, each one K-solve. Its Ritz value is an
        upper bound of mu_min, accurate to about ``tol`` relative (solvers/uzawa.py: why that is enough)."""
        from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

        op, m = self.op, self.qp.m
        sw = np.sqrt(w)
        before = op.counters.applications
        t0 = time.perf_counter()
        if m <= DENSE_EIG_MAX:      # a few rows: the whole matrix is one block of m products
            sym = sw[:, None] * op.apply(sw[:, None] * np.eye(m))
            mu = _range_min(np.linalg.eigvalsh(0.5 * (sym + sym.T)))
            how = f"dense eigvalsh (m <= {DENSE_EIG_MAX})"
        else:
            A = LinearOperator((m, m), matvec=lambda v: sw * op.apply(sw * np.ravel(v)), dtype=float)
            v0 = np.ones(m) / np.sqrt(m)
            how = f"Lanczos (eigsh SA, tol {tol:g})"
            try:
                mu = float(eigsh(A, k=1, which="SA", tol=tol, v0=v0, return_eigenvectors=False,
                                 maxiter=max(1000, 10 * m))[0])
            except ArpackNoConvergence as exc:   # a Ritz value is still an upper bound of mu_min
                if not np.size(exc.eigenvalues):
                    raise
                mu = float(np.min(exc.eigenvalues))
                how += ", not converged: the last Ritz value"
        return mu, {"mu_min_method": how, "mu_min_applications": op.counters.applications - before,
                    "mu_min_time_s": time.perf_counter() - t0}
