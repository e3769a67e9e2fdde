"""The certificate's exact face step for a QP with several constraint blocks (:attr:`dualfem.core.qp.QP.blocks`).

The same measurement as :func:`dualfem.numerics.certify.active_set_check` (read its docstring: one exact
Newton step onto the face the laws guess, verified when the exact point of that face keeps every law's
conditions with margins larger than the step), on the stacked operator ``G`` of all blocks, with each
block's law deciding its face (:meth:`dualfem.core.laws.Law.face`), the multipliers it holds off the face
(:meth:`dualfem.core.laws.Law.complementary`) and whether the exact point holds
(:meth:`dualfem.core.laws.Law.face_holds`). The Delassus matrix ``D = G K^-1 G'`` is formed densely from
``m_total`` K-solves (exact factorizations only: with AMG K-solves no value is claimed), up to
:data:`MAX_ROWS` rows. :func:`blocks_infeasible_bound`: the bound of an answer that penetrates, with friction
blocks (:func:`dualfem.numerics.certify.infeasible_bound`'s multi-block case).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from dualfem.core import constraints
from dualfem.core.evaluator import EPS, force_scale, size_energy
from dualfem.core.laws import Friction, Signorini
from dualfem.core.qp import QP
from dualfem.numerics.linalg import step_size

#: the face step of a multi-block QP forms D densely: above this many rows no value is claimed
MAX_ROWS = 2000


@dataclass
class FaceStep:
    """One exact step onto the face ``A`` the laws guess from (x, mu): the face point's multipliers ``mu1`` and
    gaps ``gap1``, the step's pieces (``z = K^-1 r``, ``rKr``, ``Gz``, ``dmu``, ``Ddmu``) and its sizes
    ``step_mu`` (forces) and ``step_gap`` (lengths); :meth:`x1` the face point itself."""

    A: np.ndarray
    mu1: np.ndarray
    gap1: np.ndarray
    z: np.ndarray
    rKr: float
    Gz: np.ndarray
    dmu: np.ndarray
    Ddmu: np.ndarray
    step_mu: float
    step_gap: float
    kappa: float = 1.0      #: a cheap estimate of cond(D_AA), from its Cholesky factor's diagonal

    def x1(self, qp: QP, x: np.ndarray, ksolve) -> np.ndarray:
        """The face point ``x - K^-1 r + K^-1 G' dmu`` (one more K-solve)."""
        return x - self.z + (ksolve(qp.G.T @ self.dmu) if self.dmu.any() else 0.0)

    def holds(self, qp: QP, margin: float) -> bool:
        """Whether every block's law holds at the face point with ``margin`` times the step
        (:meth:`dualfem.core.laws.Law.face_holds`): then the face point is the solution."""
        blocks = qp.constraints
        mus1 = tuple(constraints.split(blocks, self.mu1))
        parts = zip(blocks, mus1, constraints.split(blocks, self.gap1), constraints.split(blocks, self.A))
        return all(constraints.call_law(b.law.face_holds, m1, g1, a, margin * self.step_mu, margin * self.step_gap,
                                        weights=b.weights, mus=mus1) for b, m1, g1, a in parts)


def delassus(qp: QP, ksolve) -> tuple[np.ndarray, float]:
    """(the dense Delassus matrix ``D = G K^-1 G'``, ``c = 1 / mean diag D``): from the exact local reduction of
    ``ksolve`` when every row of G acts on its local unknowns I (``D = G_I S^-1 G_I'``, S the Schur complement of
    K onto I: one dense solve), else from ``m_total`` K-solves."""
    G = qp.G
    D = _local_delassus(qp, ksolve)
    if D is None:
        Z = np.column_stack([ksolve(G[j].toarray().ravel()) for j in range(qp.m_total)]) if qp.m_total else \
            np.zeros((qp.n, 0))
        D = np.asarray(G @ Z)
    D = 0.5 * (D + D.T)
    dD = np.diag(D)
    return D, (1.0 / dD.mean() if dD.size and dD.mean() > 0 else 1.0)


def _local_delassus(qp: QP, ksolve) -> np.ndarray | None:
    """``G_I S^-1 G_I'`` from the K-solver's exact local reduction (None without one, or when G reaches beyond I)."""
    red = getattr(ksolve, "red", None)
    if red is None or getattr(red, "qp", None) is not qp:
        return None
    G = qp.G.tocsc()
    outside = np.ones(qp.n, bool)
    outside[red.I] = False
    if G[:, outside].nnz:
        return None
    GI = G[:, red.I].toarray()
    return GI @ sla.cho_solve(red.S_cho, GI.T)


def face_step(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, D: np.ndarray, c: float,
              Kx: np.ndarray | None = None) -> FaceStep | None:
    """The exact step onto the face the laws guess from (x, mu) (module docstring); None when D is singular on it."""
    blocks, G = qp.constraints, qp.G
    mu = np.asarray(mu, float)
    gap = G @ x
    A = constraints.face(blocks, mu, gap, c)
    mus, gaps = tuple(constraints.split(blocks, mu)), constraints.split(blocks, gap)
    held = [b.law.complementary(mk, gk, b.weights, mus) for b, mk, gk in zip(blocks, mus, gaps)]
    mu_A = np.where(A, mu, np.concatenate(held) if held else mu)
    r = (qp.K @ x if Kx is None else Kx) - qp.F - G.T @ mu_A
    z = ksolve(r)
    rKr, Gz = float(r @ z), G @ z
    dmu = np.zeros_like(mu)
    kappa = 1.0
    if A.any():
        try:
            L = sla.cho_factor(D[np.ix_(A, A)])
            dmu[A] = sla.cho_solve(L, -(gap[A] - Gz[A]))
        except (np.linalg.LinAlgError, ValueError):
            return None
        dL = np.abs(np.diag(L[0]))
        kappa = float((dL.max() / max(dL.min(), 1e-300)) ** 2)
    Ddmu = D @ dmu
    return FaceStep(A, mu_A + dmu, gap - Gz + Ddmu, z, rKr, Gz, dmu, Ddmu,
                    max(np.abs(dmu).max(initial=0.0), np.abs(mu - mu_A).max(initial=0.0)),
                    float(np.abs(Ddmu - Gz).max(initial=0.0)), kappa)


def blocks_active_set_check(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, margin: float = 10.0,
                            Kx: np.ndarray | None = None) -> tuple[float, float]:
    """(error of x relative to :func:`size_energy`, error of mu relative to :func:`force_scale`) through the
    verified face of every block's law; (nan, nan) when the face is not verified or the step cannot be taken
    (AMG K-solves, more than :data:`MAX_ROWS` rows, a singular D on the face)."""
    return blocks_face_check(qp, x, mu, ksolve, margin, Kx)[:2]


def blocks_face_check(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, margin: float = 10.0,
                      Kx: np.ndarray | None = None) -> tuple[float, float, float]:
    """:func:`blocks_active_set_check`'s pair, and where the face is not verified the rigorous bound through
    its exact point (:func:`dualfem.numerics.degenerate.degenerate_bound`: degenerate rows, e.g. closed without
    force or stick on the disc's edge; the Coulomb thresholds the answer's own); nan where the face is verified."""
    from dualfem.numerics.certify import MU_ROUNDING
    from dualfem.numerics.degenerate import degenerate_bound

    nan = (float("nan"), float("nan"), float("nan"))
    if getattr(ksolve, "amg", False) or qp.m_total > MAX_ROWS:
        return nan
    D, c = delassus(qp, ksolve)
    st = face_step(qp, x, mu, ksolve, D, c, Kx)
    if st is None:
        return nan
    nx = size_energy(qp, x, Kx)
    dx_K = step_size(st.rKr, st.Gz, st.dmu, st.Ddmu)
    if not st.holds(qp, margin):
        if nx == 0.0:
            return nan
        mus = tuple(constraints.split(qp.constraints, np.asarray(mu, float)))
        rnd = MU_ROUNDING * EPS * max(st.kappa, 1.0) * st.step_gap
        deg = degenerate_bound(qp, x, st.A, st.mu1, st.gap1, dx_K, D, rnd, nx, mus, ksolve)
        return float("nan"), float("nan"), deg
    err_mu = float(np.abs(np.asarray(mu, float) - st.mu1).max(initial=0.0)) / force_scale(qp, st.mu1)
    if nx == 0.0:
        return float("nan"), err_mu, float("nan")
    return dx_K / nx, err_mu, float("nan")


def blocks_infeasible_bound(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, Kx=None) -> float:
    """:func:`dualfem.numerics.certify.infeasible_bound` for a QP with friction blocks beside the Signorini one
    (Tresca; Coulomb as the Tresca problem of the answer's own threshold, as the rest of the certificate). With mu
    projected onto every law's set, z = K^-1 (F + G'mu), g = G z: for the tangential rows the linear term of the
    dual is bounded by the law's support term ``sum_j r_j |g_j| + mu_j . g_j`` (any nu_j in the disc), for the
    normal rows as in the Signorini case, and the quadratic maximum over the normal rows by ``1/2 p'D^+ p`` (p the
    penetration of z on the normal rows, 0 elsewhere; D = G K^-1 G' dense from the reduction, up to :data:`MAX_ROWS`
    rows):

        |x - x*|_K  <=  sqrt(r'K^-1 r) + sqrt(2 mu+'g+ + 2 sum_friction support + p'D^+ p).

    nan for AMG K-solves, more rows, another law, or p not in D's range."""
    blocks = qp.constraints
    if getattr(ksolve, "amg", False) or qp.m_total > MAX_ROWS or \
            not all(isinstance(b.law, (Signorini, Friction)) for b in blocks):
        return float("nan")
    mu = constraints.project(blocks, np.asarray(mu, float))
    r = (qp.K @ x if Kx is None else Kx) - qp.F - qp.G.T @ mu
    z = ksolve(r)
    rKr, g = float(r @ z), qp.G @ (x - z)
    mus, gaps = tuple(constraints.split(blocks, mu)), constraints.split(blocks, g)
    second, p = 0.0, np.zeros_like(g)
    for b, mk, gk, pk in zip(blocks, mus, gaps, constraints.split(blocks, p)):
        if isinstance(b.law, Signorini):
            second += 2.0 * float(mk @ np.maximum(gk, 0.0))
            pk[:] = np.maximum(-gk, 0.0)
        else:
            second += 2.0 * max(0.0, b.law.support(mk, gk, b.weights, mus))
    if p.any():
        D, _ = delassus(qp, ksolve)
        w, V = np.linalg.eigh(D)
        keep = w > EPS * qp.m_total * max(w.max(initial=0.0), 0.0)
        c = V.T @ p
        if np.linalg.norm(c[~keep]) > 1e-10 * np.linalg.norm(p):
            return float("nan")
        second += float(np.sum(c[keep] ** 2 / w[keep]))
    nx = size_energy(qp, x, Kx)
    if nx == 0.0:
        return float("nan")
    return float((np.sqrt(max(rKr, 0.0)) + np.sqrt(max(second, 0.0))) / nx)
