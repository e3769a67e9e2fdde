"""Independent checks of a solution: recomputed from (x, multipliers) and the QP alone.

Nothing here reads a solver's own residuals. All residuals are scale-free so that one tolerance
works in MPa/mm and in Pa/m alike:

* force scale  f_s = max(|F|_inf, |Kx|_inf, |B'mu|_inf)   (nodal forces)
* length scale l_s = |x|_inf                               (displacements; for a shifted QP,
  whose user unknowns are ``x + qp.shift.x``, the larger of |x|_inf and |x + x_shift|_inf)

==================  =====================================================
``stationarity``    |Kx - F - B'mu|_inf / f_s
``primal``          max(0, -min_j (Bx)_j) / l_s          (max penetration)
``dual``            max(0, -min_j mu_j) / f_s            (negative contact force)
``complementarity`` max_j |mu_j (Bx)_j| / (f_s l_s)
==================  =====================================================
"""
from __future__ import annotations

import numpy as np

from dualfem.core.qp import QP

TINY = 1e-300

#: the names of the four KKT residuals, in report order (defined here only)
RESIDUALS = ("stationarity", "primal", "dual", "complementarity")

#: A defect node is "in contact" when its normal jump is at most this fraction of |x|_inf.
CONTACT_RTOL = 1e-6


def _scales(qp: QP, x: np.ndarray, mu: np.ndarray, Kx: np.ndarray) -> tuple[float, float]:
    fs = max(np.abs(qp.F).max(initial=0.0), np.abs(Kx).max(initial=0.0),
             np.abs(qp.B.T @ mu).max(initial=0.0), TINY)
    # a shifted QP (a QP file with h != 0, signorini): the user's unknowns are x + x_shift, and
    # their size is the length scale (x itself may be exactly 0 at the solution)
    ls = max(size_max(qp, x), TINY)
    return fs, ls


def residuals(qp: QP, x: np.ndarray, multipliers: np.ndarray) -> dict:
    """KKT residuals of ``(x, multipliers)`` for ``qp`` (see module docstring), plus the energy."""
    x = np.asarray(x, dtype=float)
    mu = np.asarray(multipliers, dtype=float)
    if x.shape != (qp.n,) or mu.shape != (qp.m,):
        raise ValueError(f"x must have length {qp.n} and multipliers length {qp.m}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(mu))):
        nan = float("nan")
        return {"stationarity": nan, "primal": nan, "dual": nan, "complementarity": nan,
                "energy": nan, "finite": False}
    Kx = qp.K @ x                        # the one product with K
    fs, ls = _scales(qp, x, mu, Kx)
    gap = qp.B @ x
    r = Kx - qp.F - qp.B.T @ mu
    return {
        "stationarity": float(np.abs(r).max(initial=0.0) / fs),
        "primal": float(max(0.0, -gap.min(initial=0.0)) / ls),
        "dual": float(max(0.0, -mu.min(initial=0.0)) / fs),
        "complementarity": float(np.abs((mu / fs) * (gap / ls)).max(initial=0.0)),
        "energy": qp.energy(x, Kx),
        "finite": True,
    }


def kkt_error(res: dict) -> float:
    """The largest of the four KKT residuals (nan if any is nan)."""
    vals = [res[k] for k in RESIDUALS]
    return float("nan") if any(np.isnan(vals)) else float(max(vals))


def kkt_residuals(res: dict) -> dict:
    """The four KKT residuals of a :func:`residuals` record (without energy and flags)."""
    return {k: res[k] for k in RESIDUALS}


def contact_set(qp: QP, x: np.ndarray, rtol: float = CONTACT_RTOL) -> np.ndarray:
    """Boolean mask of defect nodes in contact: normal jump <= rtol * |x|_inf."""
    gap = qp.B @ x
    return gap <= rtol * max(np.abs(x).max(initial=0.0), TINY)


def energy_norm(qp: QP, v: np.ndarray, Kv: np.ndarray | None = None) -> float:
    """sqrt(v' K v) (``Kv``: the product K v, if known)."""
    return float(np.sqrt(max(v @ (qp.K @ v if Kv is None else Kv), 0.0)))


def _shift(qp: QP, x: np.ndarray) -> np.ndarray | None:
    return None if qp.shift is None or qp.shift.x.shape != np.shape(x) else qp.shift.x


def size_energy(qp: QP, x: np.ndarray, Kx: np.ndarray | None = None) -> float:
    """The energy-norm size of a solution, the denominator of relative errors: |x|_K, or for a shifted
    QP (user unknowns ``x + qp.shift.x``) the larger of |x|_K and |x + x_shift|_K, so that a
    solution x = 0 of the shifted problem still has a size. ``Kx``: the product K x, if known."""
    shift = _shift(qp, x)
    e = energy_norm(qp, x, Kx)
    return e if shift is None else max(e, energy_norm(qp, x + shift))


def size_max(qp: QP, x: np.ndarray) -> float:
    """|x|_inf, or for a shifted QP the larger of |x|_inf and |x + x_shift|_inf (see :func:`size_energy`)."""
    shift = _shift(qp, x)
    e = float(np.abs(x).max(initial=0.0))
    return e if shift is None else max(e, float(np.abs(x + shift).max(initial=0.0)))


def compare(qp: QP, x: np.ndarray, mu: np.ndarray, x_ref: np.ndarray, mu_ref: np.ndarray,
            rtol: float = CONTACT_RTOL) -> dict:
    """Relative differences of (x, mu) against a reference (x_ref, mu_ref).

    ``x_energy``: |x - x_ref|_K / |x_ref|_K; ``x_max``: |x - x_ref|_inf / |x_ref|_inf (for a shifted
    QP the sizes of :func:`size_energy` and :func:`size_max`);
    ``multipliers``: |mu - mu_ref|_inf / max(|mu_ref|_inf, |F|_inf) (the load scale guards the
    all-open case where mu_ref = 0); ``energy``: |Pi(x) - Pi(x_ref)| / |Pi(x_ref)|;
    ``contact_mismatch``: number of defect nodes in one contact set and not the other.
    """
    dx = x - x_ref
    ref_e = max(size_energy(qp, x_ref), TINY)
    e_ref = qp.energy(x_ref)
    mu_scale = max(np.abs(mu_ref).max(initial=0.0), np.abs(qp.F).max(initial=0.0), TINY)
    c1, c2 = contact_set(qp, x, rtol), contact_set(qp, x_ref, rtol)
    return {
        "x_energy": energy_norm(qp, dx) / ref_e,
        "x_max": float(np.abs(dx).max(initial=0.0) / max(size_max(qp, x_ref), TINY)),
        "multipliers": float(np.abs(mu - mu_ref).max(initial=0.0) / mu_scale),
        "energy": float(abs(qp.energy(x) - e_ref) / max(abs(e_ref), TINY)),
        "contact_mismatch": int(np.count_nonzero(c1 != c2)),
    }


def active_set_solution(qp: QP, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact minimizer with ``B_A x = 0`` on the active set A (one sparse KKT solve).

    Returns (x, mu) with mu = 0 off A. If A is the true contact set, this is the exact QP
    solution (check with :func:`certify`): a way to certify a reference without trusting
    any iterative solver.

    Deliberately independent of the solvers' linear algebra: one sparse LU of the full KKT
    matrix, no :class:`dualfem.numerics.linalg.LocalReduction` (which uzawa, pdas, penalty, the active-set
    polish and :mod:`dualfem.numerics.certify` share), so a fault in that shared path cannot certify itself.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla

    A = np.flatnonzero(active)
    BA = qp.B[A]
    kkt = sp.bmat([[qp.K, BA.T], [BA, None]], format="csc")
    sol = sla.splu(kkt).solve(np.r_[qp.F, np.zeros(A.size)])
    mu = np.zeros(qp.m)
    mu[A] = -sol[qp.n:]
    return sol[:qp.n], mu


def certify(qp: QP, x: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, bool]:
    """Exact active-set solution for the contact set of ``x``, and whether it satisfies KKT.

    Returns (x*, mu*, ok): ok is True when the exact solution for that contact set has
    every KKT residual below ``tol``, i.e. the contact set is right and (x*, mu*) is the QP's
    solution up to round-off.
    """
    xs, mus = active_set_solution(qp, contact_set(qp, x))
    return xs, mus, kkt_error(residuals(qp, xs, mus)) <= tol
