"""Preconditioned conjugate gradients for the dual operator's face systems, with a condition estimate.

:func:`pcg` solves an SPD system given as a product, preconditioned by a diagonal or a linear map, from
a start vector, and reports the condition number CG saw (from the Lanczos tridiagonal matrix of its
coefficients): the matrix-free dual operator (:mod:`dualfem.numerics.dual_operator`) uses it for
D_AA^-1, and the certificate widens its rounding margin by that condition.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["pcg"]


def pcg(matvec, rhs: np.ndarray, inv_diag, x0: np.ndarray | None = None, rtol: float = 1e-13,
        max_iter: int = 1000, stats: dict | None = None) -> tuple[np.ndarray, int]:
    """Preconditioned CG for an SPD operator: (x, iterations) with |r| <= rtol |rhs|.

    ``inv_diag``: the preconditioner, an array (Jacobi: z = inv_diag * r) or an SPD linear map r -> z.

    ``stats``, if given, receives ``kappa``: the condition number of the preconditioned operator
    estimated from the Lanczos tridiagonal matrix of the CG coefficients (a lower estimate).
    Raises numpy.linalg.LinAlgError when a curvature p'Ap <= 0 shows the operator is not positive
    definite or the iteration cap is reached.
    """
    nb = float(np.linalg.norm(rhs))
    alphas: list[float] = []
    betas: list[float] = []
    if nb == 0.0:
        _lanczos_kappa(alphas, betas, stats)
        return np.zeros_like(rhs), 0
    prec = inv_diag if callable(inv_diag) else (lambda v: inv_diag * v)
    x = np.zeros_like(rhs) if x0 is None else np.array(x0, float)
    r = rhs - matvec(x) if x0 is not None and np.any(x) else rhs.copy()
    z = prec(r)
    p = z.copy()
    rz = float(r @ z)
    for k in range(max_iter + 1):
        if np.linalg.norm(r) <= rtol * nb:
            _lanczos_kappa(alphas, betas, stats)
            return x, k
        if k == max_iter:
            break
        Ap = matvec(p)
        pAp = float(p @ Ap)
        if not pAp > 0:
            raise np.linalg.LinAlgError("CG: the operator is not positive definite on the face")
        a = rz / pAp
        x += a * p
        r -= a * Ap
        z = prec(r)
        rz, rz_old = float(r @ z), rz
        alphas.append(a)
        betas.append(rz / rz_old)
        p = z + (rz / rz_old) * p
    raise np.linalg.LinAlgError(f"CG on the face did not reach {rtol:g} in {max_iter} iterations "
                                f"(relative residual {np.linalg.norm(r) / nb:.1e})")


def _lanczos_kappa(alphas: list[float], betas: list[float], stats: dict | None) -> None:
    """stats["kappa"]: extreme eigenvalues of the CG Lanczos matrix T (T_kk = 1/a_k + b_(k-1)/a_(k-1),
    T_k,k+1 = sqrt(b_k)/a_k): the condition of the preconditioned operator seen by CG (1 if none)."""
    if stats is None:
        return
    k = len(alphas)
    if k == 0:
        stats["kappa"] = 1.0
        return
    a, b = np.array(alphas), np.array(betas)
    diag = 1.0 / a
    diag[1:] += b[:-1] / a[:-1]
    off = np.sqrt(b[:-1]) / a[:-1]
    ev = sla.eigvalsh_tridiagonal(diag, off) if k > 1 else diag
    stats["kappa"] = float(ev.max() / max(ev.min(), 1e-300))
