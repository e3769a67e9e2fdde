"""K^-1 without a factorization: CG preconditioned by smoothed-aggregation AMG (pyamg) with the rigid-body modes.

Where a sparse factorization of K does not fit (3D: nnz(L) grows like n^1.4, time like n^2;
:mod:`dualfem.numerics.memory`), K^-1 r is computed by conjugate gradients preconditioned by one
V-cycle of a pyamg smoothed-aggregation hierarchy whose near-nullspace is the body's rigid-body modes
(:func:`rigid_body_modes`: 6 in 3D, 3 in 2D, from ``GeometryPart.nodes`` / ``node_dofs``; with them the
iteration count barely grows with n: docs/measurements.md).

:class:`AmgKSolve` owns the hierarchy (built once; kept in the QP's
:class:`~dualfem.numerics.linalg.FactorStore` by :func:`amg_for`, keyed like a factorization of K, so the
dual operator and the certificate share it; never a module global) and solves ``K z = b`` for one
right-hand side or a block (column by column), from a warm start ``x0``, to a relative residual
``|b - K z|_2 <= rtol |b|_2`` that the caller chooses. Every solve records its *true* residual (one
product with K after CG), so an error bound can be formed from it:

    |z - K^-1 b|_K  =  |s|_(K^-1)  <=  |s|_2 / sqrt(lambda_min(K)),      s = b - K z,
    |z - K^-1 b|_2  <=  |s|_2 / lambda_min(K).

:meth:`AmgKSolve.lambda_min` estimates lambda_min(K) by LOBPCG preconditioned with the hierarchy (a Ritz
value: an *upper* estimate of lambda_min, divided by :data:`LAMBDA_SAFETY`): the bounds above are then
estimates, rigorous when the Ritz value is within that factor of the smallest eigenvalue (see
:mod:`dualfem.numerics.certify`).

Inner tolerance (:func:`inner_rtol`): a dual method that declares a relative tolerance ``tol`` gets
K-solves to ``rtol = INNER_RATIO x tol`` (1e-3 x: pdas's 1e-9 -> 1e-12), clipped to
[:data:`RTOL_MIN`, :data:`RTOL_MAX`]; the K-solve error then enters the dual quantities
(D v = B K^-1 B'v, b0, x(mu)) three orders of magnitude below what the solver certifies.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import MissingDependency, install_hint
from dualfem.numerics.pcg import pcg

__all__ = ["AmgKSolve", "AmgCounters", "FullSpaceResult", "amg_for", "full_space_newton", "inner_rtol",
           "rigid_body_modes", "require_pyamg"]

#: the K-solve's relative residual per unit of the outer (dual solver's) relative tolerance
INNER_RATIO = 1e-3
#: clip of the inner tolerance: below RTOL_MIN the true residual of CG in double precision stalls
#: (docs/measurements.md); above RTOL_MAX the dual operator is too noisy
RTOL_MIN, RTOL_MAX = 1e-13, 1e-8
#: the default inner tolerance (pdas's declared 1e-9 x INNER_RATIO)
RTOL = 1e-12
#: CG iterations allowed per solve (a hierarchy that needs more is broken: docs/measurements.md)
MAX_ITER = 500
#: the LOBPCG Ritz value of lambda_min(K) is divided by this before it enters an error bound
LAMBDA_SAFETY = 2.0


def require_pyamg():
    """The pyamg module, or MissingDependency naming the ``amg`` extra."""
    try:
        import pyamg
    except ImportError:
        raise MissingDependency(f"the amg K-solve (operator=amg) needs pyamg: {install_hint('pyamg', 'amg')}") \
            from None
    return pyamg


def inner_rtol(outer_tol: float) -> float:
    """The K-solves' relative residual for a dual solver that declares the relative tolerance ``outer_tol``:
    INNER_RATIO x outer_tol, clipped to [RTOL_MIN, RTOL_MAX]."""
    return float(np.clip(INNER_RATIO * float(outer_tol), RTOL_MIN, RTOL_MAX))


def rigid_body_modes(geometry, n: int) -> np.ndarray | None:
    """(n, k) near-nullspace of elasticity on the unknowns: k = dim translations and dim (dim - 1) / 2
    rotations (6 in 3D, 3 in 2D; rotations about the nodes' centroid, scaled to the size of the body);
    a scalar field (one component per node): the constant. None without a geometry (pyamg's default,
    the constant, is then used)."""
    if geometry is None:
        return None
    X, nd = np.asarray(geometry.nodes, float), np.asarray(geometry.node_dofs)
    ncomp, dim = nd.shape[0], X.shape[0]
    if ncomp != dim:
        return np.ones((n, 1))
    Xc = X - X.mean(axis=1, keepdims=True)
    Xc = Xc / max(float(np.abs(Xc).max()), 1e-300)
    rots = [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (2, 0)]      # u_a = -x_b, u_b = x_a (rotation in a-b)
    M = np.zeros((n, dim + len(rots)))
    for c in range(dim):
        free = nd[c] >= 0
        M[nd[c, free], c] = 1.0
    for k, (a, b) in enumerate(rots):
        fa, fb = nd[a] >= 0, nd[b] >= 0
        M[nd[a, fa], dim + k] = -Xc[b, fa]
        M[nd[b, fb], dim + k] = Xc[a, fb]
    return M


@dataclass
class AmgCounters:
    """Work done with an :class:`AmgKSolve`."""

    solves: int = 0            #: right-hand sides solved (a block of k counts k)
    iterations: int = 0        #: CG iterations in all
    max_iterations: int = 0    #: the most CG iterations of one solve
    time_s: dict = field(default_factory=dict)   #: seconds: setup, solve, lambda_min

    def as_dict(self) -> dict:
        return asdict(self)


class AmgKSolve:
    """K^-1 by AMG-preconditioned CG (module docstring). ``K`` SPD sparse (n x n), ``modes`` (n, k) the
    near-nullspace (:func:`rigid_body_modes`) or None."""

    backend = "amg"

    def __init__(self, K: sp.spmatrix, modes: np.ndarray | None = None, rtol: float = RTOL):
        from dualfem.numerics.threads import ensure_threads

        pyamg = require_pyamg()
        ensure_threads()       # OpenBLAS on one thread: two spinning threads slow CG's vector operations down
        t0 = time.perf_counter()
        self.K = sp.csr_matrix(K, dtype=float)
        self.n = self.K.shape[0]
        self.rtol = float(rtol)
        self.ml = pyamg.smoothed_aggregation_solver(self.K, B=modes, symmetry="hermitian", max_coarse=500,
                                                     coarse_solver="splu")
        self.M = self.ml.aspreconditioner(cycle="V")
        self.counters = AmgCounters()
        self.counters.time_s["setup"] = time.perf_counter() - t0
        #: the true relative residuals |b - K z| / |b| and absolute |b - K z|_2 of the last solve (per column)
        self.last_rel: np.ndarray = np.zeros(0)
        self.last_abs: np.ndarray = np.zeros(0)
        self._lam: float | None = None
        self.info = {"backend": "amg", "levels": len(self.ml.levels), "operator_complexity":
                     float(self.ml.operator_complexity()), "modes": 0 if modes is None else int(modes.shape[1])}

    def _one(self, b: np.ndarray, x0: np.ndarray | None, rtol: float) -> tuple[np.ndarray, float, int]:
        nb = float(np.linalg.norm(b))
        if nb == 0.0:
            return np.zeros(self.n), 0.0, 0
        x, its = pcg(self.K.__matmul__, b, self.M.matvec, x0=x0, rtol=rtol, max_iter=MAX_ITER)
        s = float(np.linalg.norm(b - self.K @ x))
        if s > 10.0 * rtol * nb:            # the recursive residual drifted from the true one: continue from x
            x, more = pcg(self.K.__matmul__, b, self.M.matvec, x0=x, rtol=rtol, max_iter=MAX_ITER)
            its += more
            s = float(np.linalg.norm(b - self.K @ x))
        return x, s, its

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None, rtol: float | None = None) -> np.ndarray:
        """K^-1 b for b of shape (n,) or (n, k) (columns one by one), from ``x0`` (same shape; None: 0), to
        the relative residual ``rtol`` (default: this object's). Records the true residuals."""
        rtol = self.rtol if rtol is None else float(rtol)
        b = np.asarray(b, float)
        t0 = time.perf_counter()
        B2 = b.reshape(self.n, -1)
        X0 = None if x0 is None else np.asarray(x0, float).reshape(self.n, -1)
        out = np.empty_like(B2)
        rel, ab = np.zeros(B2.shape[1]), np.zeros(B2.shape[1])
        for j in range(B2.shape[1]):
            out[:, j], ab[j], its = self._one(B2[:, j], None if X0 is None else X0[:, j], rtol)
            nb = float(np.linalg.norm(B2[:, j]))
            rel[j] = ab[j] / nb if nb > 0 else 0.0
            self.counters.iterations += its
            self.counters.max_iterations = max(self.counters.max_iterations, its)
        self.counters.solves += B2.shape[1]
        self.last_rel, self.last_abs = rel, ab
        ts = self.counters.time_s
        ts["solve"] = ts.get("solve", 0.0) + time.perf_counter() - t0
        return out.reshape(b.shape)

    def lambda_min(self) -> float:
        """An estimate of lambda_min(K) (cached): LOBPCG's smallest Ritz value (a block of 4 vectors,
        preconditioned by the hierarchy) divided by :data:`LAMBDA_SAFETY`."""
        if self._lam is None:
            import scipy.sparse.linalg as spla

            t0 = time.perf_counter()
            rng = np.random.default_rng(0)
            X = rng.standard_normal((self.n, min(4, self.n)))
            if self.n <= 64:
                theta = float(np.linalg.eigvalsh(self.K.toarray())[0])
            else:
                import warnings

                scale = float(np.abs(self.K.diagonal()).max())
                with warnings.catch_warnings():       # not converged to tol: the Ritz value is still an upper one
                    warnings.simplefilter("ignore", UserWarning)
                    w = spla.lobpcg(self.K, X, M=self.M, largest=False, tol=1e-6 * scale, maxiter=100)[0]
                theta = float(np.min(w))
            self._lam = max(theta, 0.0) / LAMBDA_SAFETY
            self.counters.time_s["lambda_min"] = time.perf_counter() - t0
        return self._lam

    def energy_error(self, abs_residual: float | np.ndarray) -> float:
        """The estimated bound |z - K^-1 b|_K <= |s|_2 / sqrt(lambda_min) of a solve with residual norm |s|_2
        (the largest over the given ones)."""
        s = float(np.max(abs_residual, initial=0.0))
        lam = self.lambda_min()
        return float("inf") if lam <= 0 else s / np.sqrt(lam)

    def free(self) -> None:
        """Nothing outside Python's memory to release (API of the factorizations)."""


def amg_for(qp, store=None, rtol: float = RTOL) -> AmgKSolve:
    """The :class:`AmgKSolve` of ``qp.K`` with the QP's rigid-body modes, built once per store (the QP's
    own :class:`~dualfem.numerics.linalg.FactorStore` by default; not counted as a factorization)."""
    from dualfem.numerics.linalg import store_of

    store = store_of(qp) if store is None else store
    K = qp.K if qp.K.format in ("csr", "csc") else qp.K.tocsr()
    key = store.key((K.indptr, K.indices, K.data), f":{K.format}:whole:amg")
    hit = store.get(key)
    if hit is None:
        hit = AmgKSolve(K, rigid_body_modes(qp.geometry, qp.n), rtol)
        store.put(key, hit)      # type: ignore[arg-type]  (the store holds any K-solver by key)
    return hit  # type: ignore[return-value]


# --------------------------------------------------------------------------- full-space semismooth Newton
#: the augmented-Lagrangian penalty of :func:`full_space_newton`: C_j = AL_SCALE / D_jj (lumped) on the active
#: set, so each AL step divides the constraint error by ~1 + AL_SCALE lambda_min(Jacobi-scaled D_AA)
AL_SCALE = 1e3


@dataclass
class FullSpaceResult:
    """What :func:`full_space_newton` returns: the displacements, the contact forces (mu >= 0, K x - F = B'mu
    to the CG residual), whether the active set settled, and the work done."""

    x: np.ndarray
    mu: np.ndarray
    converged: bool
    newton_steps: int = 0
    al_steps: int = 0
    hierarchies: int = 0
    cg_iterations: int = 0
    message: str = ""
    timed_out: bool = False
    #: the active set came back to one of an earlier step that was not the last (no convergence)
    cycled: bool = False
    time_s: dict = field(default_factory=dict)


def lumped_delassus_diagonal(K: sp.csr_matrix, B: sp.csr_matrix) -> np.ndarray:
    """|b_j|^4 / (b_j'K b_j): a lower bound of D_jj = b_j'K^-1 b_j (Cauchy-Schwarz), no solve."""
    bb = np.asarray(B.multiply(B).sum(axis=1)).ravel()
    bKb = np.asarray((B @ K).multiply(B).sum(axis=1)).ravel()
    d = np.where(bKb > 0, bb ** 2 / np.where(bKb > 0, bKb, 1.0), 0.0)
    pos = d[d > 0]
    return np.where(d > 0, d, pos.mean() if pos.size else 1.0)


def full_space_newton(qp, tol: float = 1e-12, rtol: float = 1e-11, max_newton: int = 50, max_al: int = 30,
                      al_scale: float = AL_SCALE, deadline: float | None = None,
                      report: Callable[[int, np.ndarray, np.ndarray], None] | None = None) -> FullSpaceResult:
    """Semismooth Newton (primal-dual active set) on all unknowns, without a factorization and without D.

    Step k: the active set A = {mu - c B x > 0} (c = 1 / mean of the lumped diag D), then the KKT system
    ``K x - B_A' mu_A = F, B_A x = 0`` (mu = 0 off A) by the augmented Lagrangian on
    ``H = K + B_A' C B_A`` (C = ``al_scale`` / D_jj lumped): x = H^-1 (F + B_A' lam), lam <- lam - C B_A x,
    each H^-1 by CG preconditioned with a smoothed-aggregation hierarchy of H (rigid-body modes; one per
    Newton step) to ``rtol``, warm-started, until max|B_A x| <= ``tol`` max|x|. Stops when the active set
    repeats (then mu_A > 0 and B x >= 0 off A: the KKT conditions hold to the inner accuracy). At the end
    ``K x - F - B'mu`` is H's CG residual (step counts and timings: docs/measurements.md).
    ``deadline``: a ``time.perf_counter()`` value after which it stops (``timed_out``) between two AL steps;
    ``report(k, x, mu)``: called with each Newton step's iterate (the solver plugin's iterate hook).
    The solver plugin is ``solvers/newton_amg.py``; the caller certifies the answer
    (:mod:`dualfem.numerics.certify`)."""
    t0 = time.perf_counter()
    K, B, F = sp.csr_matrix(qp.K), sp.csr_matrix(qp.B), np.asarray(qp.F, float)
    modes = rigid_body_modes(qp.geometry, qp.n)
    dD = lumped_delassus_diagonal(K, B)
    c = 1.0 / dD.mean() if dD.size else 1.0
    x = amg_for(qp).solve(F, rtol=rtol)
    mu = np.zeros(qp.m)
    out = FullSpaceResult(x, mu, False)
    seen: set[bytes] = set()
    last = b""
    for k in range(max_newton + 1):
        if report is not None:
            report(k, x, np.maximum(mu, 0.0))
        if deadline is not None and time.perf_counter() > deadline:
            out.timed_out, out.message = True, f"time limit reached after {k} Newton steps"
            break
        A = (mu - c * (B @ x)) > 0
        key = np.packbits(A).tobytes()
        if k and key in seen:
            out.converged = key == last
            out.cycled = not out.converged
            out.message = ("active set settled" if out.converged else
                           f"active set cycles (a set of step {k} met before)")
            break
        if k == max_newton:
            out.message = f"no convergence in {max_newton} Newton steps"
            break
        seen.add(key)
        last = key
        out.newton_steps += 1
        if not A.any():
            x, mu = amg_for(qp).solve(F, x0=x, rtol=rtol), np.zeros(qp.m)
            continue
        C = np.where(A, al_scale / dD, 0.0)
        H = (K + B.T @ sp.diags(C) @ B).tocsr()
        h = AmgKSolve(H, modes, rtol)
        out.hierarchies += 1
        lam = np.where(A, mu, 0.0)
        for _ in range(max_al):
            if deadline is not None and time.perf_counter() > deadline:
                break
            x = h.solve(F + B.T @ lam, x0=x)
            out.al_steps += 1
            r = B @ x
            lam = np.where(A, lam - C * r, 0.0)
            if np.abs(r[A]).max(initial=0.0) <= tol * max(np.abs(x).max(initial=0.0), 1e-300):
                break
        out.cg_iterations += h.counters.iterations
        mu = lam
    out.x, out.mu = x, np.maximum(mu, 0.0)
    out.time_s["total"] = time.perf_counter() - t0
    return out
