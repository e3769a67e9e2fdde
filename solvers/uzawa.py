"""The paper's method: Uzawa on the modified Lagrangian with a generalized Newton-Armijo inner loop.

Zhiltsov & Maksimova (2023), sections 3-4. With l the contact pressure (units of stress, the
paper's alpha_j at defect node j) and w_j the trapezoid weights, the discrete modified Lagrangian is

    M(x, l) = 1/2 x'Kx - F'x + sum_j w_j / (2 r) ( ((l_j - r [x_nu]_j)^+)^2 - l_j^2 ),

(K already holds the 1/delta interface term). Uzawa (outer, counter k):

    x^{k+1} = argmin_x M(x, l^k),      l^{k+1} = (l^k - r [x^{k+1}_nu])^+,

stopping when max_j |l^{k+1}_j - l^k_j| <= tol. The inner minimization is the generalized
Newton method (counter m, summed over all outer iterations): with lambda = l - r B x and the
active set A = {lambda_j > 0},

    gradient  G(x) = K x - F - B' (w * lambda^+),
    Hessian   H(x) = K + r B' diag(w * [j in A]) B,
    x <- x - s d,  d = H^-1 G,

with s = 1 divided by ``step_factor`` until the Armijo test
``M(x - s d) <= M(x) - armijo_c * s * G'd`` holds, and the inner stop
``||x^{m+1} - x^m|| / max(||x^{m+1}||, s_F) < tol_inner`` (s_F the size the load sets:
:func:`dualfem.core.evaluator.load_energy` in the energy norm, ``load_length`` in the Euclidean one; the
test stays relative to the data when x* = 0).

Choices where the paper is silent or misprinted (documented here once):

* The printed gradient beta(t) uses t_{i+} alone where the energy gives the jump t_{i+} - t_{i-};
  we use the jump. The printed Armijo test has no constant and the wrong sign for the descent
  direction -d; we use the standard sufficient decrease with ``armijo_c`` (default 1e-4).
* lambda_j = 0 counts as inactive (the paper lists > 0 and < 0 only).
* The norm of the inner stop test is the paper's V^h norm; we take the energy norm
  ||x||^2 = x'Kx (``inner_norm="energy"``, the natural norm of V^h for this problem and the one
  that is exact and cheap in the reduced space). ``inner_norm="euclidean"`` (the plain
  vector norm) is available with ``linalg="full"``.
* The first Newton iterate is the unconstrained minimizer K^-1 F (the paper does not say; it
  apparently starts from 0, which costs one extra Newton step: its m = 2 for f3). Every later
  inner loop is warm-started from the previous outer iterate.
* Honest stop: the paper's outer test bounds only the last change of l. Two estimates of the
  remaining error of l: change * rho / (1 - rho) with the observed linear rate rho, and the
  proximal-point bound change / (r mu_min) (mu_min = smallest dual compliance, see below), which
  also holds after one outer iteration. With the relative test (``tol_mode="relative"``, the default)
  the iteration goes on until the larger is also <= tol (the answer's multipliers are certified to the
  declared tolerance: on fractured scenes the last change alone left errors of 1.5-1.7e-6 against a
  tolerance of 1e-6). With the paper's absolute test, when the larger exceeds ``error_factor * tol`` the
  status is ``inaccurate`` (with both numbers in the message) instead of ``solved``; the iterates
  and the counts k, m are then the paper's.
* Shortcut (``shortcut=True``, with l^0 = 0): if the unconstrained minimizer has no negative
  jump, it already is the answer of the first Uzawa iteration and l^1 = 0; we return it with
  k = 1, m = 1 (one solve).

Choosing r (``r_rule``): Uzawa on the modified Lagrangian is a proximal-point method on the
dual; a dual mode with compliance mu (an eigenvalue of G W, G = B K^-1 B', W = diag(w)) contracts
by 1 / (1 + r mu) per outer iteration. The interface term makes mu ~ delta for small delta, so the
paper's fixed r = 1e7 gives r mu ~ 1e-2 at delta = 1e-9: the ~900 iterations of its Table 2.
``r_rule="auto"`` takes r = r_factor / mu_min, computed from the QP itself (scale-invariant: the
same r mu in MPa/mm and Pa/m), so every mode contracts by 1 / (1 + r_factor); mu_min is the smallest
eigenvalue on G W's range (dependent or duplicated rows of B add zero eigenvalues whose modes change no
x: r = r_factor / 0 gave a singular Newton system). The solver
``uzawa_auto`` is this method with ``r_rule="auto"``; ``uzawa`` keeps the paper's r = 1e7.

The paper's r is a dimensional number (stress / length): 1e7 MPa per unit length for its body of
E = 69000 MPa and width 1. ``r_rule="scaled"`` (the default of ``uzawa``) reads ``r`` in those
units and converts it to the scene's: r_used = r * (E / 69000) / width, with E and width from the
QP's units (``QP.units``). In the paper's units r_used = r exactly (the same iterates as the paper's
method); with E or the length unit scaled by any factor, the iterates scale with them and the
status stays the same. A QP without scene units (a QP file) uses r as given, and says so in
``info["r_units"]``. ``r_rule="fixed"`` uses r as given always (``report paper`` asks for it).

Linear algebra (``linalg``, ``operator``): ``linalg="reduced"`` (default) runs on the contact dual
operator that ``operator`` names (:mod:`dualfem.numerics.dual_operator`; ``auto`` picks by size and
memory, so the method runs at every size and is never skipped for its number of defect unknowns):

* ``operator="dense"``: the exact Schur reduction onto the local unknowns I
  (:class:`dualfem.numerics.linalg.LocalReduction`, K_fixed factorized once, reused across delta,
  loads and solvers); each generalized Hessian is applied by Woodbury on the dense Delassus matrix
  with one |A| x |A| Cholesky factor per active set (cached). Cost: the factorization of K_fixed and
  its Schur complement, then O(|I|^2 m) to form D once (memory 8 (2 |I|^2 + |I| m + m^2) bytes);
  every Newton step is dense work on |I|-sized blocks. mu_min (``r_rule="auto"``) by a dense
  eigensolver on the m x m matrix, O(m^3).
* ``operator="matrix_free"``: all unknowns, sparse. The Newton matrices
  H = K + r B' diag(w * active) B have one sparsity pattern, that of K + B'B (inactive rows stored as
  zeros): :class:`dualfem.numerics.newton_matrix.NewtonMatrix` analyzes it once and factorizes it
  numerically once per new active set (the last ``keep_factors`` kept by active set; counted in
  ``info["factorizations"]``); the start K^-1 F is one solve with the operator's factorization of K
  (shared with the certificate). Cost: one factorization of K, one analysis, one numeric
  factorization of K + B'B per active set met (each about as costly as K's), one sparse solve per
  Newton step; memory: two sparse factors. Measured on a 269 k-unknown many-crack scene (400 cracks,
  m = 3,200, 12,800 local unknowns, beyond the dense path; delta = 1e-5, load f1, 2 shared cores),
  setup + solve against the floor (one factorization + solve of K in the same process, 1.6-2.8 s
  with the machine's load): ``uzawa_auto`` 5 outer / 11 Newton steps, 1 analysis + 5 numeric
  factorizations, 71 Lanczos products (2.9-5.5 s of it), 8-21 s = 4.8-7.6x the floor (four runs);
  ``uzawa`` (r = 1e7) 23 / 53, 13 factorizations (17 with ``keep_factors=1``), 10-25 s = 5.8-9.2x.
  On a 25 k-unknown scene (64 cracks, 1,536 local unknowns) the dense path is faster (uzawa_auto
  0.66 s against 1.2 s): ``auto`` keeps it there.
  ``info`` reports the counters (``newton_*``, ``applications``, ``mu_min_applications``).
  mu_min (``r_rule="auto"``, and the honest-stop bound of every run that stops) is estimated by
  Lanczos (ARPACK ``eigsh``, which="SA", relative tolerance ``eig_tol`` = 1e-2) on products
  W^1/2 D W^1/2 v, one K-solve each (about 70-80 products on the many-crack scenes). An estimate is
  enough: a Ritz value is an upper bound of mu_min, so r = r_factor / mu_min comes out slightly
  smaller than the exact rule's and the slowest dual mode contracts by 1 / (1 + r mu_min), slightly
  slower than 1 / (1 + r_factor) (a 1 % error costs nothing measurable); r only sets the speed of
  the proximal-point iteration, never its fixed point, and the outer stop test (the relative dual
  change, with the error estimates above) guards the accuracy whatever r is. The honest-stop bound
  change / (r mu_min) is then at most that 1 % optimistic.

The two operators compute the same iterates: every iterate after the first is exactly optimal in the
non-local unknowns, so the Newton steps, Armijo tests and stop tests (gradient'step, d'Qd, the
energy norm x'Kx) are the same numbers, computed in the smaller space or the whole one (tested: the
same steps, answers within 1e-10 in the energy norm). ``linalg="full"`` is the textbook path (it
ignores ``operator``): it refactorizes the sparse Hessian at every Newton step, no analysis reused,
and allows ``inner_norm="euclidean"``.
"""
from __future__ import annotations

import sys
import time

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.evaluator import load_energy, load_length
from dualfem.core.parts import UnitsPart
from dualfem.core.registry import register_solver
from dualfem.core.solution import Solution, Status
from dualfem.numerics.dual_solver import OPERATORS, DualOperatorSolver
from dualfem.numerics.factor import from_param
from dualfem.numerics.linalg import LocalReduction, sparse_factor
from dualfem.numerics.newton_matrix import NewtonMatrix

EPS = float(np.finfo(float).eps)

#: the matrix-free path computes mu_min densely (one block of m products) up to this many rows
DENSE_EIG_MAX = 32
#: the paper's unit system (Zhiltsov & Maksimova 2023, section 5): E in MPa, the unit square
PAPER_E = 69000.0
PAPER_WIDTH = 1.0


def paper_r_in_scene_units(r: float, units: UnitsPart | None) -> tuple[float, str]:
    """(r converted from the paper's units to the scene's, how): r * (E / 69000) / (width / 1).

    r is a stress per length; a scene in other units (``QP.units``: its E and length scale, the
    body's width) gets the same r relative to its own stiffness and size. A QP without units (a
    QP file) uses r as given."""
    if units is None:
        return r, "as given (the QP has no units: E and width)"
    return r * (units.E / PAPER_E) * (PAPER_WIDTH / units.length), f"scaled: r * (E / {PAPER_E:g}) / width"


def _contraction(history: list[dict], last: int = 5) -> float:
    """Observed linear rate of the dual iteration: geometric mean of the last change ratios."""
    ch = [h["dual_change"] for h in history[-(last + 1):]]
    if len(ch) < 3 or min(ch) <= 0:
        return 0.0
    return float(np.exp(np.mean(np.diff(np.log(ch)))))


class _ReducedSpace:
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


class _FullSpace:
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
        return _ReducedSpace(self.qp, "energy", self.factor).mu_min(w)


class _SparseSpace:
    """Sparse linear algebra on all unknowns with one analysis (the matrix-free operator's path).

    The Newton matrices K + B' diag(coef) B share the pattern of K + B'B
    (:class:`dualfem.numerics.newton_matrix.NewtonMatrix`): analyzed once, one numeric factorization
    per new active set (``keep`` factors kept). The start K^-1 F and the products D v of the
    Lanczos estimate of mu_min use the operator's factorization of K (shared with the certificate
    through the QP's store). Every quantity of the inner and outer tests is the full-space one,
    equal to the reduced space's (module docstring), so the iterates are the dense path's to rounding.
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
        upper bound of mu_min, accurate to about ``tol`` relative (module docstring: why that is enough)."""
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


@register_solver
class Uzawa(DualOperatorSolver):
    """Uzawa on the modified Lagrangian + generalized Newton-Armijo (the paper's method)."""

    name = "uzawa"
    family = "dual"
    description = "Uzawa / modified Lagrangian + generalized Newton-Armijo (Zhiltsov & Maksimova 2023)"
    tolerance = 1e-6
    defaults = {
        "r": 1e7,                 # augmentation parameter (stress / length, the paper's units with r_rule="scaled")
        "r_rule": "scaled",       # "scaled": r * (E / 69000 MPa) / width (scene units); "fixed": r as given;
                                  # "auto": r = r_factor / mu_min(B K^-1 B' W)
        "r_factor": 100.0,        # with r_rule="auto": slowest dual mode contracts by 1/(1 + r_factor) per outer it
        "tol": 1e-6,              # on max_j |l^{k+1}_j - l^k_j| / max_j l^{k+1}_j (unit-free; see tol_mode)
        "tol_mode": "relative",   # "absolute": tol in stress units, the paper's test (1e-5 MPa; report paper)
        "tol_inner": 1e-7,        # on ||x^{m+1} - x^m|| / ||x^{m+1}||
        "step_factor": 2.0,       # Armijo backtracking divides s by this (paper: 2 or 1.1)
        "armijo_c": 1e-4,         # sufficient-decrease constant
        "max_iter": 20000,
        "max_inner": 200,         # Newton steps per outer iteration
        "max_backtracks": 80,
        "l0": 0.0,                # starting pressure l^0 (same at every defect node)
        "linalg": "reduced",      # "reduced" (fast, exact: on the dual operator) or "full" (textbook)
        "operator": "auto",       # with linalg="reduced": dense (reduction onto the defect unknowns),
                                  # matrix_free (sparse Newton matrices, one analysis), auto (by size, memory)
        "factor": "auto",         # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
        "keep_factors": 4,        # matrix_free: numeric factorizations of Newton matrices kept (by active set)
        "eig_tol": 1e-2,          # matrix_free, r_rule="auto": relative tolerance of the Lanczos estimate of mu_min
        "inner_norm": "energy",   # norm of the inner stop test
        "shortcut": True,         # return the unconstrained minimizer when it is admissible
        "stall_window": 1000,     # stop with 'stagnation' if the dual change has not improved for this many outer its
        "time_limit": 600.0,      # seconds
        "error_factor": 10.0,     # 'inaccurate' if the estimated dual error exceeds this x tol
        "verbose": False,         # print one line per outer iteration to stderr
    }
    renamed = {"tol_outer": "tol", "max_outer": "max_iter"}
    ranges = {"r": "(0, inf)", "r_rule": ("scaled", "fixed", "auto"), "r_factor": "(0, inf)",
              "tol_mode": ("relative", "absolute"),
              "tol_inner": "(0, inf)", "step_factor": "(1, inf)", "armijo_c": "(0, 1)", "max_inner": "[1, inf)",
              "max_backtracks": "[1, inf)", "l0": "[0, inf)", "linalg": ("reduced", "full"),
              "operator": OPERATORS, "keep_factors": "[1, inf)", "eig_tol": "(0, 1)",
              "factor": None, "inner_norm": ("energy", "euclidean"), "shortcut": bool, "stall_window": "[1, inf)",
              "error_factor": "(0, inf)"}

    def validate(self) -> None:
        super().validate()
        p = self.params
        if p["inner_norm"] == "euclidean" and p["linalg"] != "full":
            raise InputError(f"parameter 'inner_norm' of solver '{self.name}' must be 'energy' with "
                             "linalg='reduced' ('euclidean' needs linalg='full')")

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": tol * 10.0, "tol_inner": tol * 1e-2}

    def skip(self, qp) -> str | None:
        # linalg="reduced": refused only when no operator fits the memory (operator=auto switches
        # to matrix_free above the dense sizes: the paper's method runs at every size)
        return super().skip(qp) if self.params["linalg"] == "reduced" else None

    def setup(self, qp) -> None:
        p = self.params
        self.qp, self.op, self.reduction = qp, None, None
        self._mu, self._mu_info = None, {}
        # the inner test's size has the evaluator's floor (the energy / length the load sets), so that a
        # solution x* = 0 (a crack pushed shut, nothing else loaded) still has a scale: relative to the data
        self._floor2 = (load_energy(qp) if p["inner_norm"] == "energy" else load_length(qp)) ** 2
        if p["linalg"] == "reduced":
            super().setup(qp)            # self.op (dense or matrix_free), self.reduction (dense only)
            if self.op.kind == "dense":
                self.space = _ReducedSpace(qp, p["inner_norm"], reduction=self.op.reduction)
            else:
                self.space = _SparseSpace(qp, self.op, from_param(self), keep=int(p["keep_factors"]))
        else:
            self.space = _FullSpace(qp, p["inner_norm"], from_param(self))
        self.r, self.r_units = paper_r_in_scene_units(float(self.params["r"]), qp.units) \
            if self.params["r_rule"] == "scaled" else (float(self.params["r"]), "as given")
        if self.params["r_rule"] == "auto" and qp.m:
            self.r = float(self.params["r_factor"] / self._mu_min())
            self.r_units = "r_factor / min dual compliance"

    def _mu_min(self) -> float:
        """Smallest eigenvalue of the dual compliance G W (computed once, when first needed): exact
        (dense eigvalsh) on the dense and full paths, a Lanczos estimate on the matrix-free one."""
        if self._mu is None:
            if self.qp.m == 0:
                self._mu = np.inf
            else:
                kw = {"tol": float(self.params["eig_tol"])} if self.space.kind == "matrix_free" else {}
                mu, self._mu_info = self.space.mu_min(self.qp.weights, **kw)
                self._mu = float(max(mu, 1e-300))
        return self._mu

    def solve(self) -> Solution:
        p, qp, sp_ = self.params, self.qp, self.space
        r, w = self.r, qp.weights
        t_start = time.perf_counter()
        deadline = t_start + p["time_limit"]
        z = sp_.start()
        l = np.full(qp.m, float(p["l0"]))
        k = m_total = 0
        history: list[dict] = []

        def result(status, msg=""):
            x = sp_.full(z)
            info = {**self.op.info()} if self.op is not None else {"operator": "none (linalg='full')"}
            if sp_.kind == "matrix_free":
                info.update(sp_.nm.info())
            info.update({"factorizations": sp_.factorizations, "operator_factorizations": info.get("factorizations", 0),
                         "r": r, "r_units": self.r_units, "linalg": p["linalg"], **self._mu_info})
            return Solution(solver=self.name, status=status, x=x, multipliers=w * l,
                            iterations={"outer": k, "inner": m_total}, history=history, message=msg, info=info)

        self.report_iterate(0, lambda: sp_.full(z), lambda: w * l)     # the start: K^-1 F, l^0
        if p["shortcut"] and p["l0"] == 0.0 and np.all(sp_.B @ z >= 0):
            k, m_total = 1, 1
            self.report_iterate(1, lambda: sp_.full(z), lambda: w * l)
            history.append({"k": 1, "dual_change": 0.0, "inner_steps": 1, "steps": [1.0], "active": 0,
                            "shortcut": True})
            return result(Status.SOLVED, "unconstrained minimizer is admissible (shortcut)")

        best, best_k = np.inf, 0
        while k < p["max_iter"]:
            z, steps, inner_ok, msg = self._inner(z, l, r, w, deadline)
            m_total += len(steps)
            if not np.all(np.isfinite(z)):
                return result(Status.NUMERICAL_ERROR, "NaN/inf in the Newton iterate")
            l_new = np.maximum(0.0, l - r * (sp_.B @ z))
            change = float(np.abs(l_new - l).max(initial=0.0))
            k += 1
            history.append({"k": k, "dual_change": change, "inner_steps": len(steps), "steps": steps,
                            "active": int(np.count_nonzero(l_new > 0)), "inner_converged": inner_ok,
                            "inner_ratios": list(self._ratios)})
            l = l_new
            self.report_iterate(k, lambda z=z: sp_.full(z), lambda l=l: w * l)
            if p["verbose"]:
                print(f"{self.name}: outer {k} dual change {change:.3e} inner {len(steps)} "
                      f"active {history[-1]['active']}", file=sys.stderr)
            if not np.isfinite(change):
                return result(Status.NUMERICAL_ERROR, "NaN/inf in the multiplier update")
            tol = p["tol"] * (1.0 if p["tol_mode"] == "absolute" else max(np.abs(l).max(initial=0.0), 1e-300))
            if change <= tol:
                if not inner_ok:
                    return result(Status.INACCURATE, f"outer test met but last inner loop failed: {msg}")
                rho = _contraction(history)
                est_rate = change * rho / (1.0 - rho) if rho < 1 else np.inf
                # proximal-point bound: the dual is mu_min-strongly concave and its gradient at
                # l^{k+1} is (l^{k+1} - l^k) / r, so |l^{k+1} - l*| <~ change / (r mu_min). It also
                # covers a stop after one or two outer iterations, where no rate can be observed.
                est = max(est_rate, change / (r * self._mu_min()))
                history[-1]["dual_error_estimate"] = est
                if p["tol_mode"] == "relative" and est > tol and k < p["max_iter"]:
                    # the relative test (the default) bounds the estimated error of l, not only its last
                    # change: iterate on (the paper's absolute test stops here, as the paper does)
                    pass
                elif est > p["error_factor"] * tol:
                    return result(Status.INACCURATE,
                                  f"outer test met, but the estimated multiplier error {est:.2g} > "
                                  f"{p['error_factor']:g} x tol (observed rate {rho:.4f}, r x min dual "
                                  f"compliance = {r * self._mu_min():.2g}, which should be >> 1); "
                                  f"use r_rule='auto' (solver uzawa_auto) or a smaller tol")
                else:
                    return result(Status.SOLVED)
            if change < best:
                best, best_k = change, k
            elif k - best_k >= p["stall_window"]:
                return result(Status.STAGNATION, f"dual change has not improved on {best:.3g} for "
                                                 f"{p['stall_window']} outer iterations")
            if time.perf_counter() > deadline:
                return result(Status.TIME_LIMIT, f"time limit {p['time_limit']} s reached")
        return result(Status.MAX_ITER, f"max_iter={p['max_iter']} reached; last dual change {change:.3g}")

    def _inner(self, z, l, r, w, deadline):
        """Generalized Newton-Armijo for min_x M(x, l); returns (z, step sizes, converged, msg)."""
        p, sp_ = self.params, self.space
        B = sp_.B
        steps: list[float] = []
        self._ratios = ratios = []
        for _ in range(int(p["max_inner"])):
            lam = l - r * (B @ z)
            lp = np.maximum(lam, 0.0)
            qg = sp_.qgrad(z)
            G = qg - B.T @ (w * lp)
            coef = np.where(lam > 0, r * w, 0.0)
            d = sp_.newton(coef, G)
            Gd = float(G @ d)
            dQd = sp_.qform(d)
            rBd = r * (B @ d)
            s = 1.0
            if Gd > 0:
                # M(x - s d) - M(x) = -s G'd + s^2/2 d'Qd + sum_j w_j/(2r) D_j, with the remainder of
                # the penalty's linearization D_j = ((lam_j + s r Bd_j)^+)^2 - (lam_j^+)^2 - 2 s r Bd_j lam_j^+
                # evaluated in a cancellation-free form, so a Newton step at round-off level is
                # accepted or refused the same way whatever the linear algebra.
                for _ in range(int(p["max_backtracks"])):
                    eps = s * rBd
                    lps = lam + eps
                    rem = np.where((lam > 0) & (lps > 0), eps * eps,
                                   np.maximum(lps, 0.0) ** 2 - lp * lp - 2.0 * eps * lp)
                    dM = -s * Gd + 0.5 * s * s * dQd + float(w @ rem) / (2.0 * r)
                    if dM <= -p["armijo_c"] * s * Gd:
                        break
                    s /= p["step_factor"]
                else:
                    return z, steps, False, "Armijo backtracking failed"
            # Gd <= 0 only happens when G is at round-off level: the full step is taken and the
            # stop test below ends the inner loop.
            z = z - s * d
            steps.append(s)
            nz2 = sp_.norm2(z)
            ratio = s * np.sqrt(max(dQd, 0.0) if p["inner_norm"] == "energy" else float(d @ d)) \
                / np.sqrt(max(nz2, self._floor2, 1e-300))
            ratios.append(float(ratio))
            if ratio < p["tol_inner"]:
                return z, steps, True, ""
            if not np.isfinite(nz2):
                return z, steps, False, "NaN/inf"
            if time.perf_counter() > deadline:
                return z, steps, False, "time limit"
        return z, steps, False, f"max_inner={p['max_inner']} Newton steps without meeting tol_inner"


@register_solver
class UzawaAuto(Uzawa):
    """The same method with r chosen from the problem's dual compliance (see module docstring)."""

    name = "uzawa_auto"
    description = "Uzawa / modified Lagrangian + Newton-Armijo, r = 100 / (min dual compliance), relative tolerance"
    tolerance = 1e-8
    defaults = {**Uzawa.defaults, "r_rule": "auto", "tol_mode": "relative", "tol": 1e-9}

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # the relative dual change cannot go much below ~1e-10: with r ~ 100/delta, r times the
        # round-off of the jump is ~1e-10 of the pressure at delta = 1e-9 (measured: 1e-11 stalls,
        # 1e-10 takes 27 ... 1000 outer iterations on f1 at delta = 1e-9 depending on the rounding of
        # the factorization, 1e-9 takes 6 with certified errors <= 1e-12, N = 16 ... 64)
        return {"tol": max(tol * 1e-2, 1e-9), "tol_inner": max(tol * 1e-2, 1e-12)}
