"""Normalise a QP once at the boundary, for the third-party backends.

With ``x = c D y`` (D = diag(K)^(-1/2), c = max|D F|) and constraint rows scaled by R (unit
infinity norm of R B D), the scaled QP (objective divided by c^2)

    min 1/2 y' (D K D) y - (D F / c)' y   s.t.  (R B D) y >= 0

has a unit diagonal, a unit load and unit constraint rows, whatever the units, the load
magnitude or delta. Its multiplier nu maps back to ours by ``mu = c R nu`` (from
``D (K x - F) / c = D B' R nu``). (Scaling the objective instead of the unknowns made the
Hessian grow like 1 / load, and OSQP/Clarabel failed at load scales 1e-6 and 1e6.)
With several constraint blocks, ``B`` is the stacked ``qp.G`` (:attr:`dualfem.core.qp.QP.G`) and nu the
blocks' multipliers concatenated.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dualfem.core.qp import QP


@dataclass
class ScaledQP:
    """Scaled data (P, q, A) and the factors to map (y, nu) back to (x, mu)."""

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csr_matrix
    d: np.ndarray
    r: np.ndarray
    c: float

    def unscale(self, y: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, mu) in the units of the original QP."""
        return self.c * self.d * y, self.c * self.r * nu


def scale(qp: QP, enable: bool = True) -> ScaledQP:
    """Jacobi/objective/row scaling of ``qp`` (identity factors if ``enable`` is False)."""
    n, m = qp.n, qp.m_total
    if not enable:
        return ScaledQP(qp.K.tocsc(), -qp.F, qp.G.tocsr(), np.ones(n), np.ones(m), 1.0)
    d = 1.0 / np.sqrt(qp.K.diagonal())
    Dm = sp.diags(d)
    qd = d * qp.F
    c = float(np.abs(qd).max(initial=0.0))
    if not np.isfinite(c) or c == 0.0:
        c = 1.0
    A = (qp.G @ Dm).tocsr()
    rn = np.abs(A).max(axis=1).toarray().ravel()
    r = 1.0 / np.where(rn > 0, rn, 1.0)
    A = (sp.diags(r) @ A).tocsr()
    P = (Dm @ qp.K @ Dm).tocsc()
    return ScaledQP(P, -qd / c, A, d, r, c)
