"""A-posteriori error bound of an approximate QP solution, in the energy norm.

For the strictly convex QP ``min Pi(x) = 1/2 x'Kx - F'x  s.t.  Bx >= 0`` and any pair
(x, mu) with mu >= 0, let ``z = K^-1 (F + B'mu)`` (the minimiser of the Lagrangian at mu, so
``D(mu) = Pi(z) - mu'Bz`` is a lower bound of the optimal energy). Then

    Pi(x) - D(mu) = 1/2 |x - z|_K^2 + mu'Bx,

and for a feasible x, ``Pi(x) - Pi(x*) >= 1/2 |x - x*|_K^2`` and ``Pi(x*) >= D(mu)``, hence

    |x - x*|_K  <=  sqrt( r'K^-1 r + 2 mu'Bx ),        r = K x - F - B'mu.

(For an infeasible x the bound does not hold; :func:`error_bound` then returns nan.)

The term ``2 mu'Bx`` makes this bound only about sqrt(rounding) tight when there is contact
(docs/measurements.md). :func:`active_set_error` is the
sharp companion: with A = {mu > 0}, one exact refinement step of the equality-constrained KKT
system on A (``K dx - B_A' dmu_A = -r``, ``B_A dx = -B_A x``, via the reduced Delassus block)
measures the distance of (x, mu) to the solution of that linear system; if the refined point
keeps strict complementarity with margins larger than the step (mu_A > 10 |dmu|, inactive
gaps > 10 |B dx|), A is the true active set and |dx|_K / |x|_K estimates the error to first
order. :func:`certified_error` returns both and their minimum.

**Constraint laws** (:mod:`dualfem.core.laws`): the formulas above are the Signorini law's; in the code
``mu`` is projected by each block's law (``max(mu, 0)`` for Signorini), feasibility is the law's primal
residual and ``mu'Bx`` is the sum of the laws' support terms (``Law.support``), on the stacked ``qp.G``; the
active set is the law's face (``Law.face``). A QP with further blocks gets the face step of
:mod:`dualfem.numerics.faces`; the duplicated-row handling and :func:`infeasible_bound` are the Signorini
block's (nan with further blocks).

**Dependent rows** (non-unique multipliers are normal): duplicated rows (positive multiples of one
another, :func:`parallel_rows`) are one constraint, judged by the force of the group; a row off A whose
normal is a combination of A's (:func:`implied_rows`) has gap 0 at the exact point by construction and
no margin is asked of it; a singular D_AA is solved on its range (minimum norm), and where duplicates do
not explain the dependence the step's forces are accepted if nonnegative forces reproduce B_A'mu1
(:func:`nonnegative_forces`; no multiplier error is then claimed): :mod:`dualfem.numerics.dependent_rows`.

:func:`error_bound` returns that bound relative to |x|_K (with mu clipped at 0 and mu'Bx at
0: the tiny infeasibility of an exact-to-rounding x is not counted, and is reported separately
by the evaluator's ``primal`` residual). Unlike the KKT residuals it is a bound on the error in x
itself, so it certifies a reference solution. ``r'K^-1 r`` uses the cached factorization of
K_fixed through :meth:`dualfem.numerics.linalg.LocalReduction.k_solve`.

**Without a factorization** (3D, where none of K fits: :class:`KSolver` with AMG K-solves,
:mod:`dualfem.numerics.amg`), every K^-1 is a CG solve with a *true* residual s = b - Kz recorded
(computed by a product with K after CG). What is then guaranteed:

* the evaluator's KKT residuals (stationarity, primal, dual, complementarity) are computed from
  (x, mu) with products only: exact to rounding, as on every path (rigorous);
* the duality-gap bound uses r'K^-1 r <= (|z|_K + |s|_2 / sqrt(lambda_min(K)))^2 (z the computed
  K^-1 r, |z|_K from one product): rigorous *given* a lower bound of lambda_min(K);
* the active-set value |dx|_K gets the energy-norm errors of its two K-solves (z and K^-1 B'dmu) added,
  each <= |s|_2 / sqrt(lambda_min), and the gap margin of the verification their effect on the gaps,
  max_j |b_j|_2 |s|_2 / lambda_min each;
* lambda_min(K) is *estimated*: LOBPCG's smallest Ritz value preconditioned by the AMG hierarchy (an
  upper bound of lambda_min) divided by :data:`dualfem.numerics.amg.LAMBDA_SAFETY` = 2. So the widened certificate is
  an estimate, rigorous if LOBPCG found the smallest eigenvalue within that factor. The K-solves of
  the certificate run to :data:`CERT_K_RTOL`, so that the widening is far below the certified values
  (docs/measurements.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from dualfem.core import constraints
from dualfem.core.evaluator import ROUNDING_C, abs_product, force_scale, size_energy, size_max
from dualfem.core.laws import SIGNORINI
from dualfem.core.qp import QP
from dualfem.numerics.degenerate import DEGENERATE_NOTE, degenerate_bound
from dualfem.numerics.dependent_rows import (  # noqa: F401 (parallel_rows: public here, as before)
    group_forces,
    groups_explain,
    implied_rows,
    nonnegative_forces,
    parallel_rows,
)
from dualfem.numerics.feasible_bound import correction_bound
from dualfem.numerics.ksolver import CERT_K_RTOL, KSolver, OperatorHints, solver_for  # noqa: F401 (public here)
from dualfem.numerics.linalg import step_size


def refinement_step(qp: QP, ksolve, D: np.ndarray, x: np.ndarray, mu: np.ndarray,
                    A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One exact Newton step (dx, dmu) of the equality-constrained KKT system on the set A:

        K dx - B_A' dmu_A = -(K x - F - B' mu),     B_A dx = -B_A x,     dmu = 0 off A,

    with ``ksolve(r) = K^-1 r`` and the Delassus matrix ``D = B K^-1 B'`` (its A x A block is
    used). Used to refine a solution on its active set (pdas, the active-set polish) and to
    measure the distance of (x, mu) to the exact solution for A (:func:`active_set_error`).
    Raises ``numpy.linalg.LinAlgError`` if D_AA is not positive definite.
    """
    dx = ksolve(qp.F + qp.B.T @ mu - qp.K @ x)
    dmu = np.zeros_like(mu, dtype=float)
    if A.any():
        dmu[A] = sla.solve(D[np.ix_(A, A)], -(qp.B[A] @ (x + dx)), assume_a="pos")
        dx = dx + ksolve(qp.B.T @ dmu)
    return dx, dmu



EPS = float(np.finfo(float).eps)

#: the exact point of a guessed set certifies the multipliers when its signs hold beyond
#: MU_ROUNDING x eps x cond(D_AA) times the step (the rounding of the step itself)
MU_ROUNDING = 100.0

#: x counts as feasible for the bound when max penetration <= FEAS_RTOL * |x|_inf (rounding level)
FEAS_RTOL = 1e-12


def guess_active_set(D: np.ndarray, mu: np.ndarray, gap: np.ndarray, diagonal: np.ndarray | None = None,
                     blocks: tuple | None = None) -> np.ndarray:
    """The active face of every block's law (:meth:`dualfem.core.laws.Law.face`; ``blocks`` None: the
    Signorini law, the primal-dual guess ``{mu_j - c gap_j > 0}``), c = 1 / mean diag of the Delassus
    matrix D (so that c gap is a force); for an active-set answer this is {mu > 0}. ``diagonal``: diag(D)
    when D itself is not formed (matrix-free; D is then unused)."""
    dD = np.diag(D) if diagonal is None else np.asarray(diagonal)
    c = 1.0 / dD.mean() if dD.size and dD.mean() > 0 else 1.0
    if blocks is None:
        return SIGNORINI.face(mu, gap, c)
    return constraints.face(blocks, mu, gap, c)


class _Face:
    """D_AA^-1 for one set A: a dense Cholesky factor (``rtol`` 0: exact to rounding, ``kappa`` from its
    diagonal) or the matrix-free operator's CG (``rtol`` its tolerance, ``kappa`` its Lanczos estimate)."""

    def __init__(self, D: np.ndarray | None, op, A: np.ndarray, rtol: float):
        self.D, self.op, self.A, self.rtol = D, op, A, 0.0
        self.pinv = None
        if D is not None:
            DA = D[np.ix_(A, A)]
            try:
                self.L = sla.cho_factor(DA)
                dL = np.abs(np.diag(self.L[0]))
                self.kappa = float((dL.max() / max(dL.min(), 1e-300)) ** 2)   # a cheap estimate of cond(D_AA)
            except np.linalg.LinAlgError:
                # singular (dependent or duplicated rows): the minimum-norm solution, on D_AA's range
                w, V = np.linalg.eigh(0.5 * (DA + DA.T))
                keep = w > w.size * EPS * max(float(w.max(initial=0.0)), 0.0)
                if not keep.any():
                    raise
                self.pinv = (V[:, keep], w[keep])
                self.kappa = float(w[keep].max() / w[keep].min())
        else:
            self.kappa, self.cg_rtol = 1.0, rtol

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.pinv is not None:
            V, w = self.pinv
            return V @ ((V.T @ rhs) / (w if rhs.ndim == 1 else w[:, None]))
        if self.D is not None:
            return sla.cho_solve(self.L, rhs)
        out = self.op.face_solve(self.A, rhs, rtol=self.cg_rtol)
        self.kappa = max(self.kappa, self.op.last_face.get("kappa", 1.0))
        self.rtol = self.cg_rtol
        return out

    def apply(self, v: np.ndarray, ksolve=None) -> np.ndarray:
        """D v (all rows; through ``ksolve`` when given, so that its K-solve error is recorded)."""
        if self.D is not None:
            return self.D @ v
        return ksolve.apply(v) if isinstance(ksolve, KSolver) and ksolve.op is not None else self.op.apply(v)


#: relative tolerance of the matrix-free certificate's CG on D_AA. The step (dx, dmu) it computes is a
#: correction: a relative error e of dmu changes the measured distance |dx|_K by a relative O(e) (an
#: error estimate known to 1e-6 of itself) and moves mu1 = mu_A + dmu by e |dmu|, far below the margins
#: (10 |dmu|); the unverified branch widens its rounding margin to CG_RTOL x the condition CG saw
CG_RTOL = 1e-6


def _finite(x, mu) -> bool:
    return x is not None and mu is not None and bool(np.all(np.isfinite(x)) and np.all(np.isfinite(mu)))


def _residual_solve(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve,
                    Kx: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """(r'K^-1 r, B K^-1 r) for r = K x - F - B'mu; ``ksolve`` a :class:`KSolver` or a callable r -> K^-1 r;
    ``Kx`` the product K x, if known."""
    r = (qp.K @ x if Kx is None else Kx) - qp.F - qp.G.T @ mu
    if isinstance(ksolve, KSolver):
        return ksolve.quad(r)
    z = ksolve(r)
    return float(r @ z), qp.B @ z


def error_bound(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve=None, _quad=None, _Kx=None) -> float:
    """Relative energy-norm error bound |x - x*|_K / |x|_K (see module docstring).

    nan when it does not apply: non-finite data, x = 0, or x infeasible beyond rounding
    (penetration > FEAS_RTOL |x|_inf; e.g. a penalty solution), where the bound is not valid.
    """
    if not _finite(x, mu):
        return float("nan")
    blocks, gap = qp.constraints, qp.G @ x
    if max(b.law.primal(g) for b, g in zip(blocks, constraints.split(blocks, gap))) > FEAS_RTOL * size_max(qp, x):
        return float("nan")
    mu = constraints.project(blocks, np.asarray(mu, float))
    t1 = (_quad or _residual_solve(qp, x, mu, ksolve or solver_for(qp), _Kx))[0]
    floor = _support_floor(qp, mu, abs_product(qp.G, np.abs(x))) if qp.blocks else 0.0
    t2 = 2.0 * max(0.0, constraints.support(blocks, mu, gap) - floor)
    nx = size_energy(qp, x, _Kx)      # |x|_K (or the load's size); shifted QP: the smaller of both frames
    if nx == 0.0:
        return float("nan")
    return float(np.sqrt(max(t1, 0.0) + t2) / nx)


def _support_floor(qp: QP, mu: np.ndarray, gap_scale: np.ndarray) -> float:
    """The rounding floor of the duality-gap support term of a QP with friction blocks (0 for Signorini alone,
    whose exact answers the face step certifies at any size): ``ROUNDING_C eps`` times the support term of
    ``|mu|`` and ``gap_scale = |G| |x|``, the size of each computed gap (a stick node's slip ``G x`` is known only
    to ``eps (|G||x|)_j``: its term ``r_j |s_j| + mu_j . s_j`` is rounding up to ``(r_j + |mu_j|) eps (|G||x|)_j``).
    Above the face step's size limit (``faces.MAX_ROWS``) an exact frictional answer (residuals at rounding) would
    otherwise keep a bound sqrt(rounding) ~ 1e-8 and be demoted for rounding."""
    if not qp.blocks:
        return 0.0
    return ROUNDING_C * EPS * max(0.0, constraints.support(qp.constraints, np.abs(mu), gap_scale))


def active_set_error(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver | None = None,
                     margin: float = 10.0, _quad=None, _Kx=None) -> float:
    """Error |x - x*|_K / |x|_K through a verified active set; nan if the set is not verified
    (:func:`active_set_check` without the multipliers)."""
    return active_set_check(qp, x, mu, ksolve, margin, _quad, _Kx)[0]


def active_set_check(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver | None = None,
                     margin: float = 10.0, _quad=None, _Kx=None) -> tuple[float, float]:
    """(error of x, error of mu) through a verified active set; (nan, nan) if the set is not verified.

    The error of x is |x - x*|_K / size (:func:`dualfem.core.evaluator.size_energy`), the error of the
    multipliers |mu - mu*|_inf / :func:`dualfem.core.evaluator.force_scale` (mu* = mu_A + dmu, the exact
    multipliers of the verified set: the contact forces are certified, not only x, whose sensitivity
    to mu can be tiny, e.g. at delta = 1e-12 with a soft body).

    The active set is guessed by the primal-dual rule ``A = {mu_j - c gap_j > 0}`` (c = 1 / mean
    diag of the Delassus matrix D = B K^-1 B'; for an answer of an active-set method this is
    {mu > 0}, for an interior-point answer it separates the contact nodes from the open ones).
    With mu set to 0 off A, one exact step (:func:`refinement_step`, without forming dx) gives the
    solution (x + dx, mu + dmu) of the equality-constrained KKT system on A. If it keeps strict
    complementarity with margins larger than the step (mu_A > margin |step of mu|, gaps off A >
    margin |B dx|), it satisfies every KKT condition, so it IS the solution x*, and
    |dx|_K = |x - x*|_K (up to rounding). With z = K^-1 r (r = Kx - F - B'mu_A): B dx = -Bz + D dmu,
    |dx|_K^2 = r'K^-1 r - 2 (Bz)'dmu + dmu'D dmu: one solve (shared with :func:`error_bound`
    when mu is already 0 off A).
    """
    return _face_check(qp, x, mu, ksolve, margin, _quad, _Kx)[:2]


def _face_check(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver | None, margin: float, _quad,
                _Kx) -> tuple[float, float, float]:
    """:func:`active_set_check`'s (error of x, error of mu), and where the set is not verified the rigorous
    bound through its exact point of :mod:`dualfem.numerics.degenerate` (relative like the error; nan where
    the set is verified, or where that bound does not apply)."""
    nan = (float("nan"), float("nan"), float("nan"))
    if not _finite(x, mu):
        return nan
    ksolve = ksolve or solver_for(qp)
    if qp.blocks:                   # several laws: the face step on the stacked G (dualfem.numerics.faces)
        from dualfem.numerics.faces import blocks_face_check

        return blocks_face_check(qp, x, mu, ksolve, margin, _Kx)
    mu = np.asarray(mu, float)
    st = _exact_step(qp, x, mu, ksolve, _quad, _Kx)
    if st is None:
        return nan
    A, face = st.A, st.face
    Bdx = -st.Bz + st.Ddmu
    gap1 = st.gap + Bdx
    mu1 = st.mu_A + st.dmu
    step_mu = max(np.abs(st.dmu).max(initial=0.0), np.abs(mu - st.mu_A).max(initial=0.0))
    e_K, step_gap = _step_gap(qp, ksolve, Bdx)
    labels, in_A, mu1_g, err_mu = group_forces(qp, A, mu, mu1)
    open_ = _open_rows(st, ~in_A, gap1, margin * step_gap)
    extra = 0.0
    if face is not None and face.pinv is not None and not groups_explain(labels, A, face):
        # dependent rows beyond duplicates: the forces on A are not unique and the minimum-norm step may
        # split them with a sign; x1 is the solution iff some nonnegative forces nu give the same B_A'nu
        # (nonnegative least squares in D_AA's energy norm; the mismatch |B_A'(nu - mu1)|_{K^-1} is added
        # to the error, and no multiplier error is claimed: they are not unique)
        extra, ok = nonnegative_forces(face, mu1[A])
        if not ok:
            return nan
        mu1_g = np.where(A, np.inf, mu1_g)
        err_mu = float("nan")
    nx = size_energy(qp, x, _Kx)
    if _fails(A, mu1_g, open_, gap1, margin * step_mu, margin * step_gap):
        # not verified to first order (x's error is not |dx|); the multipliers of the set are still the
        # exact ones if the exact point keeps the KKT signs beyond the rounding of the step itself
        # (far-off multipliers with a right set: a large step, signs kept), then mu* = mu1; with CG the
        # step is known to its tolerance times the condition CG saw, not to rounding. x: the bound through
        # the exact point (degenerate rows: closed and without force), on the dense path only
        kappa, rtol = (face.kappa, face.rtol) if face is not None else (1.0, 0.0)
        rnd = MU_ROUNDING * max(EPS, rtol) * max(kappa, 1.0)
        deg = float("nan")
        if nx > 0.0 and e_K == 0.0 and not getattr(ksolve, "amg", False) and (face is None or face.D is not None):
            deg = degenerate_bound(qp, x, A, mu1, gap1, step_size(st.rKr, st.Bz, st.dmu, st.Ddmu),
                                   st.D if face is not None else None, rnd * step_gap, nx, ksolve=ksolve)
        if _fails(A, mu1_g, open_, gap1, rnd * step_mu, rnd * step_gap):
            return float("nan"), float("nan"), deg
        return float("nan"), err_mu, deg
    if nx == 0.0:
        return float("nan"), err_mu, float("nan")
    return (step_size(st.rKr, st.Bz, st.dmu, st.Ddmu) + 2.0 * e_K + extra) / nx, err_mu, float("nan")


@dataclass
class _Step:
    """The exact step of :func:`active_set_check` on the guessed set A (its notation): the gaps B x, mu_A (mu
    set to 0 off A), r'K^-1 r and B z (z = K^-1 r, r = K x - F - B'mu_A), dmu, D dmu and the face solver of
    D_AA (None when A is empty); D the Delassus matrix (None when matrix-free)."""

    A: np.ndarray
    gap: np.ndarray
    mu_A: np.ndarray
    rKr: float
    Bz: np.ndarray
    dmu: np.ndarray
    face: _Face | None
    Ddmu: np.ndarray
    D: np.ndarray | None


def _guess_set(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, _quad) -> tuple | None:
    """(D, op, gaps B x, the guessed active set A) of :func:`active_set_check`; None when the answer cannot
    be checked (no Delassus matrix and no operator, and mu not 0). Resets the K-solves' error record."""
    if isinstance(ksolve, KSolver) and _quad is None:
        ksolve.reset_k_error()
    op = getattr(ksolve, "op", None)
    D = ksolve.delassus() if qp.m else np.zeros((0, 0))
    gap = qp.B @ x
    if D is None and op is None:   # no Delassus matrix (large m, no reduction): only mu = 0 can be checked
        if np.any(mu != 0):
            return None
        D, A = np.zeros((0, 0)), np.zeros(mu.size, bool)
    else:
        A = guess_active_set(D, mu, gap, None if D is not None else op.diagonal(), qp.constraints)
    return D, op, gap, A


def _exact_step(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, _quad, _Kx) -> _Step | None:
    """The guessed set and one exact step on it (:func:`refinement_step` without forming dx; one K-solve,
    shared with ``_quad`` when mu is already 0 off A); None when it cannot be taken (D_AA not positive
    definite, or not checkable: :func:`_guess_set`)."""
    guess = _guess_set(qp, x, mu, ksolve, _quad)
    if guess is None:
        return None
    D, op, gap, A = guess
    mu_A = np.where(A, mu, 0.0)
    same = np.array_equal(mu_A, constraints.project(qp.constraints, mu))
    rKr, Bz = (_quad if (_quad is not None and same) else None) or _residual_solve(qp, x, mu_A, ksolve, _Kx)
    dmu = np.zeros_like(mu)
    face = None
    if A.any():
        try:
            face = _Face(D, op, A, CG_RTOL)
            dmu[A] = face.solve(-(gap[A] - Bz[A]))
        except (np.linalg.LinAlgError, ValueError):
            return None
    Ddmu = face.apply(dmu, ksolve) if face is not None else np.zeros_like(dmu)
    return _Step(A, gap, mu_A, rKr, Bz, dmu, face, Ddmu, D)


def _step_gap(qp: QP, ksolve, Bdx: np.ndarray) -> tuple[float, float]:
    """(e_K, the step's largest change of a gap): with AMG K-solves (no factorization) the two solves of the
    step (z, K^-1 B'dmu) are off by at most e_K each in the energy norm and move the gaps by at most
    max_j |b_j| e_2 each (module docstring: an estimate); both 0 with a factorization."""
    e_K, e_2 = ksolve.k_error() if isinstance(ksolve, KSolver) else (0.0, 0.0)
    bmax = float(np.sqrt(np.max(np.asarray(qp.B.multiply(qp.B).sum(axis=1)), initial=0.0))) if e_2 else 0.0
    return e_K, np.abs(Bdx).max(initial=0.0) + 2.0 * bmax * e_2


def _open_rows(st: _Step, open_: np.ndarray, gap1: np.ndarray, gap_margin: float) -> np.ndarray:
    """The rows off A whose gaps are tested: ``open_`` less the rows implied by A (:func:`implied_rows`; dense D
    only), looked for only among those that would fail ``gap_margin``."""
    if st.D is not None and st.face is not None and open_.any():
        near = open_ & (gap1 <= gap_margin)       # only rows that would fail the margin are looked at
        if near.any():
            open_ &= ~implied_rows(st.D, st.A, near, st.face)
    return open_


def _fails(A: np.ndarray, mu1_g: np.ndarray, open_: np.ndarray, gap1: np.ndarray, mu_margin: float,
           gap_margin: float) -> bool:
    """True when the exact point of A is not verified at these margins: a force on A at most ``mu_margin``,
    or a tested gap off A at most ``gap_margin``."""
    return bool((A.any() and mu1_g[A].min() <= mu_margin) or (open_.any() and gap1[open_].min() <= gap_margin))


def multiplier_floor(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver | None = None) -> float:
    """The rounding floor of the exact multipliers mu* of :func:`active_set_check`, relative like its error:
    the stationarity residual's rounding floor ``c eps (|K||x| + |F| + |B'||mu|)`` (and ``eps |B||x|`` of
    the gaps) carried through the exact step, ``D_AA^-1 (|B_A K^-1 floor| + eps |B_A||x|)``. mu* is
    known no better than this from the data in double precision (docs/measurements.md). One more solve
    with K; nan when there is no Delassus matrix."""
    from dualfem.core.evaluator import ROUNDING_C, abs_product

    ksolve = ksolve or solver_for(qp)
    op = getattr(ksolve, "op", None)
    D = ksolve.delassus() if qp.m else None
    if (D is None and op is None) or not qp.m or not _finite(x, mu) or qp.blocks:
        return float("nan")
    mu = np.asarray(mu, float)
    A = guess_active_set(D, mu, qp.B @ x, None if D is not None else op.diagonal(), qp.constraints)
    if not A.any():
        return 0.0
    s = abs_product(qp.K, np.abs(x)) + np.abs(qp.F) + abs_product(qp.B.T, np.abs(mu))
    z = ksolve(ROUNDING_C * EPS * s)
    rhs = (np.abs(qp.B @ z) + EPS * abs_product(qp.B, np.abs(x)))[A]
    try:
        dm = _Face(D, op, A, CG_RTOL).solve(rhs)
    except (np.linalg.LinAlgError, ValueError):
        return float("nan")
    return float(np.abs(dm).max()) / force_scale(qp, mu)


def infeasible_bound(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver, _quad=None, _Kx=None) -> float:
    """Relative energy-norm error bound of an answer that may be infeasible (a penalty answer, or any
    x penetrating beyond rounding, where :func:`error_bound` does not apply); nan where D = B K^-1 B' is
    not formed (matrix-free: no bound is claimed) or is singular on the data (p not in its range).

    With mu+ = max(mu, 0), z = K^-1 (F + B'mu+) = x - K^-1 r (r = K x - F - B'mu+), g = B z and
    p = max(-g, 0) (the penetration of z): the dual D(nu) = min_x L(x, nu) is the concave quadratic
    ``D(mu+) - g'(nu - mu+) - 1/2 (nu - mu+)'D(nu - mu+)``, and for nu >= 0 the linear term is at most
    ``mu+'g+ + p'(nu - mu+)``, so ``Pi(x*) = max_{nu >= 0} D(nu) <= D(mu+) + mu+'g+ + 1/2 p'D^+ p``;
    with ``1/2 |z - x*|_K^2 <= Pi(x*) - D(mu+)`` (x* feasible) and ``|x - z|_K^2 = r'K^-1 r``:

        |x - x*|_K  <=  sqrt(r'K^-1 r) + sqrt(2 mu+'g+ + p'D^+ p).

    Rigorous to rounding on the dense path (D^+ from a symmetric eigendecomposition of D, p checked to
    lie in D's range to 1e-10 of its size); relative to :func:`dualfem.core.evaluator.size_energy`."""
    if not _finite(x, mu):
        return float("nan")
    if qp.blocks:
        from dualfem.numerics.faces import blocks_infeasible_bound

        return blocks_infeasible_bound(qp, x, mu, ksolve, _Kx)
    D = ksolve.delassus() if qp.m else np.zeros((0, 0))
    if D is None:
        return float("nan")
    mu = constraints.project(qp.constraints, np.asarray(mu, float))
    rKr, BKr = _quad or _residual_solve(qp, x, mu, ksolve, _Kx)
    g = qp.B @ x - BKr
    p = np.maximum(-g, 0.0)
    pDp = 0.0
    if p.any():
        w, V = np.linalg.eigh(D)
        keep = w > EPS * qp.m * max(w.max(initial=0.0), 0.0)
        c = V.T @ p
        if np.linalg.norm(c[~keep]) > 1e-10 * np.linalg.norm(p):
            return float("nan")
        pDp = float(np.sum(c[keep] ** 2 / w[keep]))
    nx = size_energy(qp, x, _Kx)
    if nx == 0.0:
        return float("nan")
    second = 2.0 * float(mu @ np.maximum(g, 0.0)) + pDp
    return float((np.sqrt(max(rKr, 0.0)) + np.sqrt(max(second, 0.0))) / nx)


def certified_error(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve: KSolver | None = None) -> dict:
    """{"bound": duality-gap bound, "active_set": first-order estimate, "infeasible": the bound of
    :func:`infeasible_bound` (computed only where "bound" does not apply: x infeasible beyond rounding; for a QP
    with friction blocks where it gives none, the feasible correction's bound of
    :func:`dualfem.numerics.feasible_bound.correction_bound`, which needs no Delassus matrix),
    "degenerate": where the set is not verified, the bound through its exact point
    (:mod:`dualfem.numerics.degenerate`; a "notes" line says so when no multiplier error is claimed),
    "value": the smallest, "multipliers": the error of mu against the exact multipliers of the verified
    active set (nan when the set is not verified; :func:`active_set_check`)}.

    One solve with K in all: every part shares z = K^-1 r (through :meth:`KSolver.quad`), and one
    product K x.
    """
    ksolve = ksolve or solver_for(qp)
    quad = Kx = None
    ksolve.reset_k_error()
    if _finite(x, mu):
        mu = np.asarray(mu, float)
        Kx = qp.K @ x
        quad = _residual_solve(qp, x, constraints.project(qp.constraints, mu), ksolve, Kx)
    b = error_bound(qp, x, mu, ksolve, _quad=quad, _Kx=Kx)
    a, m, d = _face_check(qp, x, mu, ksolve, 10.0, quad, Kx)
    f = infeasible_bound(qp, x, mu, ksolve, _quad=quad, _Kx=Kx) if np.isnan(b) and not ksolve.amg else float("nan")
    if np.isnan(b) and quad is not None:
        # x infeasible beyond rounding: the feasible correction's bound needs no Delassus matrix (above
        # faces.MAX_ROWS, AMG, p not in D's range); both bounds are rigorous, so the smaller one is kept. Where
        # the dense bound exists the correction's candidates that need further K-solves are not tried
        c = correction_bound(qp, x, constraints.project(qp.constraints, mu), quad[0],
                             lambda m, s: _support_floor(qp, m, s), FEAS_RTOL, Kx,
                             ksolve if np.isnan(f) else None)
        f = float(np.nanmin([f, c])) if np.isfinite(c) or np.isfinite(f) else float("nan")
    vals = [v for v in (b, a, f, d) if np.isfinite(v)]
    out: dict = {"bound": b, "active_set": a, "infeasible": f, "degenerate": d,
                 "value": min(vals) if vals else float("nan"), "multipliers": m}
    if np.isfinite(d) and np.isnan(m):
        out["notes"] = DEGENERATE_NOTE
    return out
