"""Active-set polishing of an approximate solution (as OSQP's ``polishing``, for any backend).

Interior-point and ADMM backends stop at a tolerance on their own residuals; at small delta the
QP is nearly degenerate (open defect nodes with gaps of 1e-9 and tiny forces), and a "Solved" answer
can be far off in the energy norm (docs/measurements.md). Polishing guesses
the active set from the approximate (x, mu) with the primal-dual active-set rule
``A = {mu_j - c gap_j > 0}`` (c = 1 / mean diag of the Delassus matrix D = B K^-1 B'), solves
the equality-constrained problem on A exactly (reduced space of
:class:`dualfem.numerics.linalg.LocalReduction`: ``D_AA mu_A = -b0_A``, x from mu), refines once with
full-space residuals, and accepts the result only if it is consistent: mu_A >= 0 and the
gaps off A are >= 0 (to rounding). Otherwise it returns None and the caller keeps (and says it
keeps) the unpolished answer.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from dualfem.core import evaluator
from dualfem.core.qp import QP
from dualfem.numerics.certify import guess_active_set
from dualfem.numerics.linalg import LocalReduction


def active_set_polish(qp: QP, x: np.ndarray, mu: np.ndarray, red=None):
    """(x, mu, info) polished on the guessed active set, or None if the guess is inconsistent."""

    if x is None or mu is None or not (np.all(np.isfinite(x)) and np.all(np.isfinite(mu))):
        return None
    red = red or LocalReduction(qp)
    D, b0 = red.dual()
    A = guess_active_set(D, mu, qp.B @ x)
    mu1 = np.zeros(qp.m)
    try:
        if A.any():
            mu1[A] = sla.solve(D[np.ix_(A, A)], -b0[A], assume_a="pos")
    except (np.linalg.LinAlgError, ValueError):
        return None
    gap = D @ mu1 + b0
    scale_gap = max(np.abs(b0).max(initial=0.0), 1e-300)
    if np.any(mu1[A] < 0) or np.any(gap[~A] < -1e-12 * scale_gap):
        return None
    x1 = red.full(sla.cho_solve(red.S_cho, red.g + red.BI.T @ mu1))
    # one step of iterative refinement on A with full-space residuals
    try:
        x2, mu2 = red.refine(x1, mu1, A)
        if np.all(mu2[A] >= 0):
            x1, mu1 = x2, mu2
    except (np.linalg.LinAlgError, ValueError):
        pass
    nrm = float(np.sqrt(max(x1 @ (qp.K @ x1), 1e-300)))
    dxx = x1 - x
    change = float(np.sqrt(max(dxx @ (qp.K @ dxx), 0.0)) / nrm)
    return x1, mu1, {"n_active": int(A.sum()), "x_change_energy": change}


def refine_on_active_set(qp: QP, red, x: np.ndarray, mu: np.ndarray, steps: int,
                         skip_below: float = 0.0) -> tuple[np.ndarray, np.ndarray, int]:
    """Iterative refinement of (x, mu) on the active set {mu > 0} with full-space residuals.

    The reduced solve loses accuracy as 1/delta and N grow (docs/measurements.md). Each step
    (:meth:`dualfem.numerics.linalg.LocalReduction.refine`, two solves) is kept only if it lowers
    the residual ``max(|Kx - F - B'mu|_inf, |B_A x|_inf |K|)`` and keeps mu_A >= 0; none is taken
    when that residual is already <= 1e-13 of the load, and a step whose exact size |dx|_K is
    <= ``skip_below`` |x|_K is not taken (one solve instead of two: x is already that accurate) unless
    the evaluator's stationarity residual (beyond its rounding floor) exceeds ``skip_below``: near
    incompressibility a forward-accurate x (error 4.6e-11 at nu = 0.4999 with SuperLU, which does no
    iterative refinement of its own) can leave a residual 5.7e-9 of the force scale, above the declared
    tolerance that bounds the residuals too; one step brings it to the floor.
    Returns (x, mu, steps kept).
    """
    A = mu > 0
    kd = np.abs(qp.K.diagonal()).max(initial=0.0)

    def resid(x_, Kx_, mu_):
        return max(np.abs(Kx_ - qp.F - qp.B.T @ mu_).max(initial=0.0), np.abs(qp.B[A] @ x_).max(initial=0.0) * kd)

    Kx = qp.K @ x
    r0 = resid(x, Kx, mu)
    fs = max(np.abs(qp.F).max(initial=0.0), np.abs(Kx).max(initial=0.0), 1e-300)
    if r0 <= 1e-13 * fs:
        return x, mu, 0
    if skip_below > 0 and evaluator.residuals(qp, x, mu)["stationarity"] > skip_below:
        skip_below = 0.0       # accurate x, residual beyond its floor (ill-conditioned K): refine anyway
    kept = 0
    for _ in range(steps):
        try:
            step = red.refine(x, mu, A, skip_below=skip_below, Kx=Kx)
        except (np.linalg.LinAlgError, ValueError):
            break
        if step is None:
            break
        x1, mu1 = step
        Kx1 = qp.K @ x1
        r1 = resid(x1, Kx1, mu1)
        if not (r1 < r0) or np.any(mu1[A] < 0):
            break
        x, Kx, mu, r0 = x1, Kx1, mu1, r1
        kept += 1
    return x, mu, kept


def polish_if_better(qp: QP, x: np.ndarray, z: np.ndarray):
    """(x, z, info): :func:`active_set_polish` of (x, z), kept only if it is consistent and lowers the
    evaluator's KKT error (``info["polished"]`` says which; ``info["kkt_before_polish"]`` the error before).
    Used by the clarabel and ``qp_<backend>`` plugins."""
    before = evaluator.kkt_error(evaluator.residuals(qp, x, z))
    out = active_set_polish(qp, x, z)
    if out is not None:
        xs, zs = out[0], out[1]
        if evaluator.kkt_error(evaluator.residuals(qp, xs, zs)) < before:
            return xs, zs, {"polished": True, "kkt_before_polish": before}
    return x, z, {"polished": False, "kkt_before_polish": before}
