"""The certificate's exact face step for a QP with several constraint blocks (:attr:`dualfem.core.qp.QP.blocks`).

The same measurement as :func:`dualfem.numerics.certify.active_set_check` (read its docstring: one exact
Newton step onto the face the laws guess, verified when the exact point of that face keeps every law's
conditions with margins larger than the step), on the stacked operator ``G`` of all blocks, with each
block's law deciding its face (:meth:`dualfem.core.laws.Law.face`), the multipliers it holds off the face
(:meth:`dualfem.core.laws.Law.complementary`) and whether the exact point holds
(:meth:`dualfem.core.laws.Law.face_holds`). The Delassus matrix ``D = G K^-1 G'`` is formed densely from
``m_total`` K-solves (exact factorizations only: with AMG K-solves no value is claimed), up to
:data:`MAX_ROWS` rows.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from dualfem.core import constraints
from dualfem.core.evaluator import force_scale, size_energy
from dualfem.core.qp import QP
from dualfem.numerics.linalg import step_size

#: the face step of a multi-block QP forms D densely: above this many rows no value is claimed
MAX_ROWS = 2000


def delassus(G, ksolve, n: int) -> np.ndarray:
    """The dense ``D = G K^-1 G'`` (symmetrized). With a local reduction whose interface unknowns I hold every
    column G touches (the defects' node pairs: every block of a cut mesh), ``G_I S^-1 G_I'`` from the reduction's
    Cholesky factor of the Schur complement S (``(K^-1)_II = S^-1``): no K-solve; otherwise one K-solve per row."""
    red = getattr(ksolve, "red", None)
    cols = np.unique(G.indices)
    I = getattr(red, "I", None)
    S_cho = getattr(red, "S_cho", None)
    if I is not None and S_cho is not None and np.isin(cols, I).all():
        pos = np.full(n, -1, np.int64)
        pos[I] = np.arange(len(I))
        GI = np.zeros((G.shape[0], len(I)))
        coo = G.tocoo()
        np.add.at(GI, (coo.row, pos[coo.col]), coo.data)
        D = GI @ sla.cho_solve(S_cho, GI.T)
    else:
        Z = np.column_stack([ksolve(G[j].toarray().ravel()) for j in range(G.shape[0])]) if G.shape[0] else \
            np.zeros((n, 0))
        D = np.asarray(G @ Z)
    return 0.5 * (D + D.T)


def blocks_active_set_check(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, margin: float = 10.0,
                            Kx: np.ndarray | None = None) -> tuple[float, float]:
    """(error of x relative to :func:`size_energy`, error of mu relative to :func:`force_scale`) through the
    verified face of every block's law; (nan, nan) when the face is not verified or the step cannot be taken
    (AMG K-solves, more than :data:`MAX_ROWS` rows, a singular D on the face)."""
    nan = (float("nan"), float("nan"))
    if getattr(ksolve, "amg", False) or qp.m_total > MAX_ROWS:
        return nan
    blocks, G = qp.constraints, qp.G
    mu = np.asarray(mu, float)
    gap = G @ x
    D = delassus(G, ksolve, qp.n)
    dD = np.diag(D)
    c = 1.0 / dD.mean() if dD.size and dD.mean() > 0 else 1.0
    A = constraints.face(blocks, mu, gap, c)
    mus, gaps = tuple(constraints.split(blocks, mu)), constraints.split(blocks, gap)
    held = [b.law.complementary(mk, gk, b.weights, mus) for b, mk, gk in zip(blocks, mus, gaps)]
    mu_A = np.where(A, mu, np.concatenate(held) if held else mu)
    r = (qp.K @ x if Kx is None else Kx) - qp.F - G.T @ mu_A
    z = ksolve(r)
    rKr, Gz = float(r @ z), G @ z
    dmu = np.zeros_like(mu)
    if A.any():
        try:
            dmu[A] = sla.cho_solve(sla.cho_factor(D[np.ix_(A, A)]), -(gap[A] - Gz[A]))
        except (np.linalg.LinAlgError, ValueError):
            return nan
    Ddmu = D @ dmu
    gap1, mu1 = gap - Gz + Ddmu, mu_A + dmu
    step_mu = max(np.abs(dmu).max(initial=0.0), np.abs(mu - mu_A).max(initial=0.0))
    step_gap = np.abs(Ddmu - Gz).max(initial=0.0)
    mus1 = tuple(constraints.split(blocks, mu1))
    parts = zip(blocks, mus1, constraints.split(blocks, gap1), constraints.split(blocks, A))
    if not all(constraints.call_law(b.law.face_holds, m1, g1, a, margin * step_mu, margin * step_gap,
                                    weights=b.weights, mus=mus1) for b, m1, g1, a in parts):
        return nan
    nx = size_energy(qp, x, Kx)
    err_mu = float(np.abs(mu - mu1).max(initial=0.0)) / force_scale(qp, mu1)
    if nx == 0.0:
        return float("nan"), err_mu
    return step_size(rKr, Gz, dmu, Ddmu) / nx, err_mu
