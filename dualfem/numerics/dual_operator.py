"""The dual (Delassus) operator of the contact QP, with a dense and a matrix-free implementation.

For ``min 1/2 x'Kx - F'x  s.t.  Bx >= 0`` (K SPD, m constraint rows) the contact forces mu >= 0
solve the dual problem on

    D = B K^-1 B'   (m x m, SPD: gaps per unit force),     b0 = B K^-1 F  (the gaps at mu = 0),

and the displacements follow from ``x(mu) = K^-1 (F + B'mu)``. Every dual solver (pdas, mprgp,
uzawa, penalty) needs only these, through one interface, :class:`DualOperator`:

* ``apply(v)``: D v for v of shape (m,) or (m, k) (a block is one solve with k right-hand sides);
* ``b0``, ``x_of(mu)``, ``k_solve(r)`` (K^-1 r), ``k_quad(r)`` (r'K^-1 r and B K^-1 r, for the
  certificate);
* ``diagonal()``: diag(D) (exact when dense, an estimate when matrix-free), ``norm_estimate()``;
* ``face_solve(A, rhs, x0)``: D_AA^-1 rhs on a set A of rows (the Newton systems of the
  active-set methods and of the certificate);
* ``counters``: operator applications, K-solves, factorizations, face solves and their CG
  iterations (PERMON-style: every result carries them).

Two implementations:

* :class:`DenseDualOperator` (``"dense"``): the exact reduction onto the local unknowns I
  (:class:`dualfem.numerics.linalg.LocalReduction`: the Schur complement S_I, then D as a dense
  m x m matrix): everything after the setup is dense linear algebra on m-sized blocks. Memory
  ~ 8 (2 |I|^2 + |I| m + m^2) bytes on top of the factorization of K_fixed, so it stops at
  :data:`dualfem.numerics.linalg.MAX_LOCAL` local unknowns.
* :class:`MatrixFreeDualOperator` (``"matrix_free"``): one sparse factorization of the whole K
  (the QP's :class:`~dualfem.numerics.linalg.FactorStore`, shared with the certificate); each
  product D v is one solve. No m x m matrix exists; D_AA^-1 is applied by preconditioned CG
  (Jacobi, warm-started), whose iterations are counted. Its K-solves (``ksolve``) are the factorization
  (``"factor"``) or, where no factorization of K fits (3D), CG preconditioned by smoothed-aggregation AMG
  with the rigid-body modes (``"amg"``, :mod:`dualfem.numerics.amg`; the ``operator="amg"`` of the dual
  solvers) to a relative residual ``k_rtol`` (:func:`dualfem.numerics.amg.
  inner_rtol` of the solver's declared tolerance: 1e-3 x it), so D v, b0 and x(mu) are known to about that
  accuracy (:attr:`DualOperator.accuracy`) instead of to rounding.

:func:`make_operator` builds the one asked for; ``"auto"`` picks by size and memory
(:func:`choose_operator`): dense while the local unknowns |I| satisfy |I|^2 <= :data:`CROSSOVER_RATIO` n
(and |I| <= :data:`CROSSOVER_LOCAL`) and the dense blocks fit in memory, matrix-free otherwise, and
matrix-free with AMG K-solves (``"amg"``) when no factorization of K fits (the memory model knows the
dimension: :func:`dualfem.numerics.memory.factor_bytes`); a refusal names the sizes, the estimates, the
memory available and the other operators.
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np
import scipy.linalg as sla

from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.numerics.factor import backend_class, registered
from dualfem.numerics.linalg import factor_whole
from dualfem.numerics.operator_choice import (  # noqa: F401 (public here, as before the split)
    CROSSOVER_LOCAL,
    CROSSOVER_RATIO,
    OPERATORS,
    check_operator,
    choose_operator,
    dense_extra_bytes,
    estimates,
    qp_dim,
)
from dualfem.numerics.pcg import pcg

#: how the matrix-free operator applies K^-1: a sparse factorization, or AMG-preconditioned CG
KSOLVES = ("factor", *registered(direct=False))
#: how the matrix-free operator applies D_AA^-1 (MatrixFreeDualOperator.face)
FACE_METHODS = ("cg", "factor")
#: the factorized face solve's penalty C = AL_SCALE / diag(D): each step divides the error by ~ 1 + AL_SCALE
#: lambda_min (lambda_min of the Jacobi-scaled D_AA), at a conditioning of K + B_A'C B_A ~ AL_SCALE times
#: K's; the steps are residual-based, so only the rate depends on it
AL_SCALE = 1e4
AL_MAX_STEPS = 30
#: rows whose exact D_jj calibrates the matrix-free diagonal estimate (one block solve with this many columns)
DIAG_SAMPLES = 8


def power_norm(matvec, m: int, iters: int) -> float:
    """|D|_2 of an SPD operator by ``iters`` power iterations from a fixed positive start vector (a lower
    estimate; 0 when a product vanishes or m = 0)."""
    v = np.ones(m) / np.sqrt(max(m, 1))
    lam = 0.0
    for _ in range(iters if m else 0):
        w = matvec(v)
        lam = float(np.linalg.norm(w))
        if lam == 0.0:
            return 0.0
        v = w / lam
    return lam


@dataclass
class OperatorCounters:
    """Work done through an operator (PERMON-style counters; every result reports them)."""

    applications: int = 0      #: products D v (a block of k vectors counts k)
    solves: int = 0            #: solves with a factorization of K (a block of k counts k)
    factorizations: int = 0    #: numeric factorizations made for this operator
    face_solves: int = 0       #: D_AA^-1 rhs computed
    cg_iterations: int = 0     #: CG iterations of the matrix-free face solves
    al_steps: int = 0          #: augmented-Lagrangian steps of the factorized face solves
    amg_iterations: int = 0    #: CG iterations of the AMG K-solves (ksolve="amg")

    def as_dict(self) -> dict:
        return asdict(self)


class DualOperator(ABC):
    """The dual operator D = B K^-1 B' of a QP and what dual methods need with it (module docstring)."""

    kind: str = "?"
    #: True when the K-solves are exact to rounding (a factorization); False on an iterative K-solve backend
    exact: bool = True

    def __init__(self, qp: QP):
        self.qp = qp
        self.m = int(qp.m)
        self.counters = OperatorCounters()
        self.time_s: dict[str, float] = {}
        self._norm: float | None = None

    # -------------------------------------------------------------- interface
    @property
    @abstractmethod
    def b0(self) -> np.ndarray:
        """The gaps B x at zero contact force: B K^-1 F (m,)."""

    @abstractmethod
    def apply(self, v: np.ndarray) -> np.ndarray:
        """D v for v of shape (m,) or (m, k)."""

    @abstractmethod
    def x_of(self, mu: np.ndarray) -> np.ndarray:
        """The displacements of the contact forces mu: K^-1 (F + B'mu)."""

    @abstractmethod
    def k_solve(self, r: np.ndarray) -> np.ndarray:
        """K^-1 r."""

    @abstractmethod
    def k_quad(self, r: np.ndarray) -> tuple[float, np.ndarray]:
        """(r'K^-1 r, B K^-1 r)."""

    @abstractmethod
    def diagonal(self) -> np.ndarray:
        """diag(D) (m,): exact (dense) or an estimate (matrix-free)."""

    @abstractmethod
    def face_solve(self, A: np.ndarray, rhs: np.ndarray, x0: np.ndarray | None = None,
                   rtol: float = 1e-13) -> np.ndarray:
        """D_AA^-1 rhs for a boolean mask A of the m rows (rhs of size A.sum()); ``x0`` a start (CG only).
        Raises numpy.linalg.LinAlgError when D_AA is not positive definite (or CG fails)."""

    #: the exact LocalReduction (dense operator) for refinement and the certificate, else None
    reduction = None
    #: relative accuracy of the K-solves behind apply / b0 / x_of (0: a factorization, exact to rounding;
    #: the AMG K-solve's relative residual otherwise; reported, so a caller can see what it may ask for)
    accuracy: float = 0.0
    #: why this operator was chosen (set by :func:`make_operator`)
    chosen_because: str = ""

    # -------------------------------------------------------------- shared
    def norm_estimate(self, iters: int = 20) -> float:
        """|D|_2 from power iterations (:func:`power_norm`; a lower estimate; cached)."""
        if self._norm is None:
            self._norm = power_norm(self.apply, self.m, iters)
        return self._norm

    def face_minimiser(self, mu: np.ndarray, tol: float, rtol: float = 1e-13) -> np.ndarray | None:
        """The exact minimiser of q on the face of mu (D_AA mu_A = -b0_A on A = {mu > 0}, 0 elsewhere; the
        face solve from mu_A), or None when it is not consistent: a negative force, or a gap off A below
        -tol max|b0|. Raises what :meth:`face_solve` raises."""
        b0 = self.b0
        A = mu > 0
        mu_p = np.zeros(b0.size)
        if A.any():
            mu_p[A] = self.face_solve(A, -b0[A], x0=mu[A], rtol=rtol)
        gap = self.apply(mu_p) + b0
        if np.all(mu_p >= 0) and np.all(gap[~A] >= -tol * max(np.abs(b0).max(initial=0.0), 1e-300)):
            return mu_p
        return None

    def dual_energy(self, mu: np.ndarray, Dmu: np.ndarray | None = None) -> float:
        """q(mu) = 1/2 mu'D mu + b0'mu (the negative dual function up to a constant)."""
        Dmu = self.apply(mu) if Dmu is None else Dmu
        return float(0.5 * mu @ Dmu + self.b0 @ mu)

    def info(self) -> dict:
        """The operator's kind, counters and setup times (for ``Solution.info``)."""
        return {"operator": self.kind, "operator_chosen_because": self.chosen_because, **self.counters.as_dict(),
                "operator_time_s": dict(self.time_s)}


# --------------------------------------------------------------------------- dense
class DenseDualOperator(DualOperator):
    """D as a dense matrix from the exact reduction onto the local unknowns (see the module docstring)."""

    kind = "dense"

    def __init__(self, qp: QP, factor=None, store=None, reduction=None):
        super().__init__(qp)
        from dualfem.numerics.linalg import LocalReduction

        t0 = time.perf_counter()
        before = _factorizations(qp, store)
        self.red = self.reduction = reduction if reduction is not None else LocalReduction(qp, factor, store)
        self.D, self._b0 = self.red.dual()
        self.counters.factorizations = _factorizations(qp, store) - before
        self.time_s["setup"] = time.perf_counter() - t0

    @property
    def b0(self) -> np.ndarray:
        return self._b0

    def apply(self, v):
        self.counters.applications += 1 if np.ndim(v) == 1 else np.shape(v)[1]
        return self.D @ v

    def x_of(self, mu):
        red = self.red
        return red.full(sla.cho_solve(red.S_cho, red.g + red.BI.T @ mu))

    def k_solve(self, r):
        self.counters.solves += 1
        return self.red.k_solve(r)

    def k_quad(self, r):
        self.counters.solves += 1
        q, zI = self.red.k_quad(r)
        return q, self.red.BI @ zI

    def diagonal(self):
        return np.diag(self.D).copy()

    def face_solve(self, A, rhs, x0=None, rtol=1e-13):
        self.counters.face_solves += 1
        return sla.solve(self.D[np.ix_(A, A)], rhs, assume_a="pos")


# --------------------------------------------------------------------------- matrix-free
class MatrixFreeDualOperator(DualOperator):
    """D v = B K^-1 B'v through one sparse factorization of K; no m x m matrix (module docstring)."""

    kind = "matrix_free"

    def __init__(self, qp: QP, factor=None, store=None, face: str = "cg", ksolve: str = "factor",
                 k_rtol: float | None = None):
        super().__init__(qp)
        if face not in FACE_METHODS:
            raise InputError(f"face solve method must be one of {', '.join(FACE_METHODS)}, got {face!r}")
        if ksolve not in KSOLVES:
            raise InputError(f"ksolve must be one of {', '.join(KSOLVES)}, got {ksolve!r}")
        #: "factor" (one sparse factorization of K) or a non-direct K-solve backend (``amg``: AMG-preconditioned
        #: CG to k_rtol; :func:`dualfem.numerics.factor.registered` with ``direct=False``)
        self.ksolve = ksolve
        #: True when K-solves are exact to rounding (a factorization), False for an iterative K-solve backend
        self.exact = ksolve == "factor"
        #: how D_AA^-1 is applied: "cg" (preconditioned CG, one K-solve per iteration) or "factor" (one
        #: factorization of K + B_A' C B_A per set, augmented-Lagrangian refinement: a few solves)
        self.face = face
        self._factor_name = factor
        self._newton = None
        t0 = time.perf_counter()
        before = _factorizations(qp, store)
        if not self.exact:
            kb = backend_class(ksolve)
            #: relative residual of every iterative K-solve (|r - K z| <= k_rtol |r|)
            self.k_rtol = float(kb.default_rtol() if k_rtol is None else k_rtol)
            self.accuracy = self.k_rtol
            self.fact = kb.for_qp(qp, store)
            self._its0 = self.fact.counters.iterations
        else:
            self.k_rtol = 0.0
            self.fact = factor_whole(qp, factor, store)
        self._x_last: np.ndarray | None = None       # warm start of x_of (AMG)
        self.counters.factorizations = _factorizations(qp, store) - before
        self.B = qp.B.tocsr()
        self.BT = self.B.T.tocsr()
        self._b0: np.ndarray | None = None
        self._diag: np.ndarray | None = None
        #: the last face solve: CG iterations, the Lanczos condition estimate, the tolerance
        self.last_face: dict = {}
        #: an approximate inverse of D (sparse m x m, SPD; e.g. dual_precond.dirichlet_inverse) whose A x A
        #: block preconditions the face CG; None: Jacobi with :meth:`diagonal`
        self.face_preconditioner = None
        self.time_s["setup"] = time.perf_counter() - t0

    def _solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        self.counters.solves += 1 if b.ndim == 1 else b.shape[1]
        if not self.exact:
            z = self.fact.solve(b, x0=x0, rtol=self.k_rtol)
            self.counters.amg_iterations = self.fact.counters.iterations - self._its0
            return z
        return self.fact.solve(b)

    @property
    def b0(self) -> np.ndarray:
        if self._b0 is None:
            self._b0 = self.B @ self._solve(np.asarray(self.qp.F, float))
        return self._b0

    def apply(self, v):
        v = np.asarray(v, float)
        self.counters.applications += 1 if v.ndim == 1 else v.shape[1]
        if self.m == 0:
            return np.zeros_like(v)
        return self.B @ self._solve(self.BT @ v)

    def x_of(self, mu):
        x = self._solve(self.qp.F + self.BT @ np.asarray(mu, float), x0=self._x_last)
        if not self.exact:
            self._x_last = x.copy()          # the next x(mu) starts from this one (mu changes little)
        return x

    def k_solve(self, r):
        return self._solve(np.asarray(r, float))

    def k_quad(self, r):
        z = self._solve(np.asarray(r, float))
        return float(r @ z), self.B @ z

    @property
    def diagonal_estimate(self) -> np.ndarray | None:
        """The diag(D) estimate :meth:`diagonal` returns, None until computed or given; set it to reuse one
        (the certificate takes the solver's, :class:`dualfem.numerics.ksolver.OperatorHints`)."""
        return self._diag

    @diagonal_estimate.setter
    def diagonal_estimate(self, d: np.ndarray | None) -> None:
        self._diag = d

    def diagonal(self) -> np.ndarray:
        """An estimate of diag(D): the lumped values |b_j|^4 / (b_j'K b_j) (lower bounds of D_jj, by
        Cauchy-Schwarz), calibrated by the exact D_jj of up to :data:`DIAG_SAMPLES` rows spread over the
        constraints (one block solve): their median ratio multiplies the lumped values."""
        if self._diag is None:
            B, K = self.B, self.qp.K
            bb = np.asarray(B.multiply(B).sum(axis=1)).ravel()
            bKb = np.asarray((B @ K).multiply(B).sum(axis=1)).ravel()
            lumped = np.where(bKb > 0, bb ** 2 / np.where(bKb > 0, bKb, 1.0), 0.0)
            if self.m:
                rows = np.unique(np.linspace(0, self.m - 1, min(DIAG_SAMPLES, self.m)).astype(int))
                E = np.zeros((self.m, rows.size))
                E[rows, np.arange(rows.size)] = 1.0
                exact = self.apply(E)[rows, np.arange(rows.size)]
                ok = lumped[rows] > 0
                ratio = float(np.median(exact[ok] / lumped[rows][ok])) if ok.any() else 1.0
                lumped = lumped * max(ratio, 1.0)
                lumped[rows] = exact
            pos = lumped[lumped > 0]
            self._diag = np.where(lumped > 0, lumped, pos.mean() if pos.size else 1.0)
        return self._diag

    def face_solve(self, A, rhs, x0=None, rtol=1e-13):
        """D_AA^-1 rhs: by Jacobi-preconditioned CG (one K-solve per iteration) from ``x0`` (``face="cg"``),
        or by one factorization of K + B_A' C B_A and augmented-Lagrangian steps (``face="factor"``)."""
        self.counters.face_solves += 1
        A = np.asarray(A, bool)
        idx = np.flatnonzero(A)
        if idx.size == 0:
            return np.zeros(0)
        if self.face == "factor":
            return self._face_by_factor(A, np.asarray(rhs, float), rtol)
        sol, its, kappa = self._face_cg(idx, np.asarray(rhs, float), x0, rtol)
        self.last_face = {"iterations": its, "kappa": kappa, "rtol": rtol}
        return sol

    def _face_cg(self, idx: np.ndarray, rhs: np.ndarray, x0, rtol: float) -> tuple[np.ndarray, int, float]:
        """(D_AA^-1 rhs by Jacobi-PCG from x0, its iterations, the Lanczos condition estimate)."""
        v = np.zeros(self.m)

        def mv(w):
            v[:] = 0.0
            v[idx] = w
            return self.apply(v)[idx]

        stats: dict = {}
        prec = 1.0 / self.diagonal()[idx]
        if self.face_preconditioner is not None:             # its A x A block (sparse, SPD)
            Msub = self.face_preconditioner[idx][:, idx].tocsr()
            prec = Msub.__matmul__
        sol, its = pcg(mv, rhs, prec, x0=x0, rtol=rtol, max_iter=max(50, 4 * idx.size), stats=stats)
        self.counters.cg_iterations += its
        return sol, its, stats["kappa"]

    def newton_matrix(self, keep: int = 2):
        """The :class:`dualfem.numerics.newton_matrix.NewtonMatrix` of K and B (made on first use; with AMG
        K-solves its systems are AMG-preconditioned CG too, to this operator's ``k_rtol``)."""
        if self._newton is None:
            from dualfem.numerics.newton_matrix import NewtonMatrix

            if not self.exact:
                from dualfem.numerics.amg import rigid_body_modes

                self._newton = NewtonMatrix(self.qp.K, self.B, self.ksolve, keep=keep,
                                            modes=rigid_body_modes(self.qp.geometry, self.qp.n), rtol=self.k_rtol)
            else:
                self._newton = NewtonMatrix(self.qp.K, self.B, self._factor_name, keep=keep)
        return self._newton

    def _face_by_factor(self, A: np.ndarray, g: np.ndarray, rtol: float) -> np.ndarray:
        """D_AA^-1 g from the KKT system K x = B_A'y, B_A x = g by the augmented Lagrangian on H = K +
        B_A' C B_A, C = AL_SCALE / diag(D) on A (so every mode of D_AA contracts by 1 / (1 + AL_SCALE
        lambda) per step, lambda >= the Jacobi-scaled D_AA's smallest eigenvalue): x = H^-1 B_A'(y + C g),
        y <- y - C (B_A x - g). Each step is one solve and is computed from the residual (iterative
        refinement), so the factor's rounding does not accumulate. Stops at |B_A x - g| <= rtol |g|."""
        nm = self.newton_matrix()
        idx = np.flatnonzero(A)
        c = np.zeros(self.m)
        c[idx] = AL_SCALE / self.diagonal()[idx]
        gn = float(np.linalg.norm(g))
        y = np.zeros(idx.size)
        if gn == 0.0:
            return y
        full = np.zeros(self.m)
        before = nm.counters.factorizations
        res, steps = gn, 0
        while steps < AL_MAX_STEPS:
            steps += 1
            full[:] = 0.0
            full[idx] = y + c[idx] * g
            x = nm.solve(c, self.BT @ full)
            self.counters.solves += 1
            r = (self.B @ x)[idx] - g
            y = y - c[idx] * r
            res = float(np.linalg.norm(r))
            if res <= rtol * gn:
                break
        if res > rtol * gn:
            raise np.linalg.LinAlgError(f"augmented Lagrangian on the face did not reach {rtol:g} in "
                                        f"{AL_MAX_STEPS} steps (relative residual {res / gn:.1e})")
        self.counters.factorizations += nm.counters.factorizations - before
        self.counters.al_steps += steps
        # the same system in the operator's own representation (products through the factorization of K,
        # whose rounding differs by ~1e-12): a few CG steps from y, so that D y + b0 is consistent to rtol
        y, its, kappa = self._face_cg(idx, g, y, rtol)
        self.last_face = {"iterations": steps, "cg_iterations": its, "kappa": kappa, "rtol": rtol}
        return y

    def info(self) -> dict:
        out = super().info()
        out["face_method"] = self.face
        out["ksolve"] = self.ksolve
        if not self.exact:
            out["k_rtol"] = self.k_rtol
            out[self.ksolve] = {**self.fact.info, **self.fact.counters.as_dict()}
        if self._newton is not None:
            out.update(self._newton.info())
        return out


# --------------------------------------------------------------------------- factorization of K
def _factorizations(qp: QP, store) -> int:
    from dualfem.numerics.linalg import store_of

    return (store_of(qp) if store is None else store).factorizations


def make_operator(qp: QP, operator: str = "auto", factor=None, store=None, tol: float | None = None,
                  chosen: tuple[str, str] | None = None) -> DualOperator:
    """The dual operator of ``qp`` (``operator`` in :data:`OPERATORS`; see :func:`choose_operator`). ``amg``
    is the matrix-free operator (``kind`` "matrix_free") with AMG K-solves to the relative residual
    :func:`dualfem.numerics.amg.inner_rtol` (``tol``), ``tol`` the dual solver's declared relative tolerance.
    ``chosen``: the (kind, why) the linear-algebra context chose already (:meth:`dualfem.numerics.la.
    LinearAlgebra.choose_operator`); None: chosen now in the current context."""
    if chosen is None:
        from dualfem.numerics.la import current

        chosen = current().choose_operator(qp, operator, factor=getattr(factor, "name", factor))
    kind, why = chosen
    if kind == "dense":
        op: DualOperator = DenseDualOperator(qp, factor, store)
    elif kind == "matrix_free":
        op = MatrixFreeDualOperator(qp, factor, store)
    else:                           # the matrix-free operator on the non-direct K-solve backend of that name
        op = MatrixFreeDualOperator(qp, factor, store, ksolve=kind,
                                    k_rtol=None if tol is None else backend_class(kind).inner_rtol(tol))
    op.chosen_because = why
    return op
