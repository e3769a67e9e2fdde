"""The error bound of a penetrating answer without the Delassus matrix: a feasible correction, measured in K.

:func:`dualfem.numerics.certify.infeasible_bound` (and its multi-block case
:func:`dualfem.numerics.faces.blocks_infeasible_bound`) bounds the error of an answer x that penetrates beyond
rounding through ``p'D^+ p``, with the dense ``D = G K^-1 G'``: above :data:`dualfem.numerics.faces.MAX_ROWS` rows,
matrix-free, or where p is not in D's range it gives no bound. This one needs no D, only products with K and G and
the residual solve ``r'K^-1 r`` the certificate already has. The certificate
(:func:`dualfem.numerics.certify.certified_error`) computes it for every answer that penetrates beyond rounding,
frictional or not, and keeps the smaller of it and the dense bound (both rigorous); where the dense bound
exists only the candidates that need no further K-solve are tried.

**The bound.** Move x by a correction dx onto the feasible set, ``x_f = x + dx`` with every Signorini row
``(G x_f)_j >= 0`` (friction rows carry no primal constraint). With mu projected onto every law's set,
``z = K^-1 (F + G'mu)`` (the minimiser of the Lagrangian at mu, ``r = K x - F - G'mu = K (x - z)``) and the dual
value ``D(mu) = L(z, mu) <= Pi(x*)`` (weak duality), the objective ``Pi`` (energy plus the Tresca term
``sum_j r_j ||s_j||``; Coulomb: the Tresca problem of the answer's own threshold, as the rest of the
certificate) is K-strongly convex, so ``1/2 |x_f - x*|_K^2 <= Pi(x_f) - Pi(x*) <= Pi(x_f) - D(mu)``, and since
``L(., mu)`` is quadratic with minimiser z,

    Pi(x_f) - D(mu) = 1/2 |x_f - z|_K^2 + support(mu, G x_f),

the laws' duality-gap terms (:meth:`dualfem.core.laws.Law.support`: ``mu' G x_f`` on Signorini rows,
``sum_j r_j ||s_j|| + mu_j . s_j`` on friction rows; >= 0 for a feasible x_f and a projected mu). Hence

    |x - x*|_K  <=  |dx|_K + sqrt( |x_f - z|_K^2 + 2 support(mu, G x_f) ),
    |x_f - z|_K^2 = r'K^-1 r + 2 dx'r + dx'K dx        (no further K-solve).

Every step is exact arithmetic on (x, mu) and the QP, with the same two conventions as
:func:`dualfem.numerics.certify.error_bound`: x_f counts as feasible when its penetration is at most
``FEAS_RTOL |x|_inf`` (rounding), and the support term loses its rounding floor (``_support_floor``). With AMG
K-solves ``r'K^-1 r`` is the certificate's widened estimate (rigorous given its lambda_min(K); module docstring
of certify.py), as for the duality-gap bound.

**The correction** (:func:`feasible_correction`): the Euclidean projection of each penetrating Signorini row,
``dx = sum_j p_j g_j' / |g_j|^2`` (p_j the penetration, g_j the row). Rows that share no unknown (the defects'
normal rows: each acts on its own node's two sides) are corrected exactly in one step; rows that share
unknowns are corrected by repeated simultaneous projections (each divided by the largest number of penetrating
rows on one unknown), at most :data:`SWEEPS` times, and the result is checked: a correction that does not reach
the feasible set gives no bound (nan), never a guessed one. The correction is not the energy-optimal one (that
needs D); for the thin-defect QP, whose normal jump carries the interface stiffness ``w / delta``, it costs about
what any correction of the same jumps costs.

**Sharper candidates** (:func:`correction_bound` keeps the smallest bound; each is rigorous). The support term is
first order in an answer's small defects and enters under a square root: a loaded contact row opened a little, a
sticking node (its force inside the disc) slipping a little, a slipping node's force a little inside its radius.
So the feasible point is also taken with those rows held closed (:func:`face_correction`: one sparse solve with
``G_S G_S'``, block diagonal per node), from x and from z, and the slipping nodes' forces are also set onto their
radius against their slip (:func:`slip_multipliers`; the normal forces, hence Coulomb's radii, unchanged: the same
Tresca problem is certified) with their own residual solve. Measured on uzawa's Coulomb answer on 50 random cracks
(its x penetrating by 8e-10 of |x|, true error 1.4e-8 against pdas): the dense infeasible bound 1.8e-5, this one
3.1e-8.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.core import constraints
from dualfem.core.evaluator import abs_product, size_energy, size_max
from dualfem.core.laws import Friction, Signorini
from dualfem.core.qp import QP

#: the most simultaneous-projection sweeps of :func:`feasible_correction` (rows sharing unknowns); one suffices
#: for rows on disjoint unknowns
SWEEPS = 50


def _signorini_rows(qp: QP) -> np.ndarray | None:
    """Mask of the stacked rows under a Signorini law; None when a block's law is neither Signorini nor friction
    (its feasible set is not known here: no bound is claimed)."""
    parts = []
    for b in qp.constraints:
        if isinstance(b.law, Signorini):
            parts.append(np.ones(b.m, bool))
        elif isinstance(b.law, Friction):
            parts.append(np.zeros(b.m, bool))
        else:
            return None
    return np.concatenate(parts) if parts else np.zeros(0, bool)


def feasible_correction(qp: QP, x: np.ndarray, feas_tol: float) -> np.ndarray | None:
    """A correction dx with ``G_S (x + dx) >= -feas_tol`` on the Signorini rows S (module docstring); None when
    the projections do not reach it in :data:`SWEEPS` sweeps or a penetrating row is zero."""
    rows = _signorini_rows(qp)
    if rows is None:
        return None
    GS = sp.csr_matrix(qp.G)[np.flatnonzero(rows)]
    norm2 = np.asarray(GS.multiply(GS).sum(axis=1)).ravel()
    dx = np.zeros_like(x, dtype=float)
    for _ in range(SWEEPS):
        p = np.maximum(-(GS @ (x + dx)), 0.0)
        bad = p > feas_tol
        if not bad.any():
            return dx
        if np.any(norm2[bad] <= 0):
            return None
        Gb = GS[np.flatnonzero(bad)]
        share = float(np.diff(sp.csc_matrix(Gb != 0).indptr).max(initial=1))
        dx += Gb.T @ (p[bad] / (norm2[bad] * max(share, 1.0)))
    return dx if np.max(-(GS @ (x + dx)), initial=0.0) <= feas_tol else None


def _candidate(qp: QP, x: np.ndarray, e: np.ndarray, r: np.ndarray, rKr: float, mu: np.ndarray, floor) -> float:
    """``|e|_K + sqrt(|x_f - z|_K^2 + 2 support(mu, G x_f))`` for the feasible point ``x_f = x + e`` (absolute;
    ``|x_f - z|_K^2 = r'K^-1 r + 2 e'r + e'K e`` since ``K (x - z) = r``)."""
    eKe = max(float(e @ (qp.K @ e)), 0.0)
    xf = x + e
    fz = max(float(rKr) + 2.0 * float(e @ r) + eKe, 0.0)
    support = constraints.support(qp.constraints, mu, qp.G @ xf) - floor(mu, abs_product(qp.G, np.abs(xf)))
    return float(np.sqrt(eKe) + np.sqrt(fz + 2.0 * max(support, 0.0)))


def face_rows(qp: QP, mu: np.ndarray) -> np.ndarray:
    """Mask of the stacked rows the face correction holds at zero gap: Signorini rows that carry a force
    (``lambda_j > 0``) and the rows of friction nodes strictly inside their disc (``||mu_j|| < (1 - 1e-6) r_j``:
    sticking). Holding them closed removes their first-order terms from the support (a tiny opening under a
    force, a tiny slip of a sticking node), which otherwise enter the bound under a square root."""
    blocks = qp.constraints
    mus = tuple(constraints.split(blocks, mu))
    parts = []
    for b, mk in zip(blocks, mus):
        if isinstance(b.law, Friction):
            inside = np.linalg.norm(b.law.nodes(mk), axis=1) < (1.0 - 1e-6) * b.law.radius(b.weights, mus)
            parts.append(np.repeat(inside, b.law.components))
        else:
            parts.append(np.asarray(mk) > 0)
    return np.concatenate(parts) if parts else np.zeros(0, bool)


def face_correction(qp: QP, x: np.ndarray, rows: np.ndarray, feas_tol: float) -> np.ndarray | None:
    """The Euclidean projection of x onto ``{G_S y = 0}`` for the rows S = ``rows`` and the penetrating Signorini
    rows, ``dx = G_S' (G_S G_S')^-1 (-G_S x)`` (a sparse solve: the rows of one node are orthogonal, nodes share
    no unknown); None when that system is singular or the result leaves a Signorini row penetrating."""
    import scipy.sparse.linalg as sla

    signorini = _signorini_rows(qp)
    if signorini is None:
        return None
    G = sp.csr_matrix(qp.G)
    gap = G @ x
    S = np.flatnonzero(rows | (signorini & (gap < -feas_tol)))
    if S.size == 0:
        return np.zeros_like(x, dtype=float)
    GS = G[S]
    A = sp.csc_matrix(GS @ GS.T)
    try:
        c = sla.spsolve(A, -gap[S]) if S.size > 1 else np.array([-gap[S][0] / A[0, 0]])
    except (RuntimeError, ValueError, ZeroDivisionError):
        return None
    c = np.atleast_1d(np.asarray(c, float))
    if not np.all(np.isfinite(c)):
        return None
    dx = GS.T @ c
    GSi = G[np.flatnonzero(signorini)]
    return dx if np.min(GSi @ (x + dx), initial=0.0) >= -feas_tol else None


def slip_multipliers(qp: QP, mu: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """``mu`` with the friction forces of the slipping nodes (on the rim of their disc: not :func:`face_rows`'
    sticking ones) set to oppose their slip at ``gap`` with the full radius
    (:meth:`dualfem.core.laws.Law.complementary`; the normal forces, hence Coulomb's radii, unchanged): dual
    feasible, and their support term is 0 at that gap."""
    blocks = qp.constraints
    mus = tuple(constraints.split(blocks, mu))
    held = constraints.split(blocks, face_rows(qp, mu))
    parts = [np.where(h, mk, b.law.complementary(mk, gk, b.weights, mus)) if isinstance(b.law, Friction) else mk
             for b, mk, gk, h in zip(blocks, mus, constraints.split(blocks, gap), held)]
    return np.concatenate(parts) if parts else np.asarray(mu, float)


def _best(qp: QP, x: np.ndarray, mu: np.ndarray, r: np.ndarray, rKr: float, w: np.ndarray | None, floor,
          tol: float) -> float:
    """The smallest :func:`_candidate` over the feasible points from x and (``w = K^-1 r`` given) from z = x - w,
    each by :func:`feasible_correction` and :func:`face_correction` (absolute; inf when none is found)."""
    rows = face_rows(qp, mu)
    starts = [(x, np.zeros_like(x, dtype=float))] + ([] if w is None else [(x - w, -w)])
    best = float("inf")
    for base, shift in starts:
        for dx in (feasible_correction(qp, base, tol), face_correction(qp, base, rows, tol)):
            if dx is not None and np.all(np.isfinite(dx)):
                best = min(best, _candidate(qp, x, shift + dx, r, rKr, mu, floor))
    return best


def correction_bound(qp: QP, x: np.ndarray, mu: np.ndarray, rKr: float, floor, feas_rtol: float,
                     Kx: np.ndarray | None = None, ksolve=None) -> float:
    """The bound of the module docstring, relative to :func:`dualfem.core.evaluator.size_energy`; nan when no
    feasible correction is found, a law is not Signorini or friction, or x = 0 with no load.

    ``mu``: the multipliers projected onto every law's set; ``rKr``: ``r'K^-1 r`` for ``r = K x - F - G'mu``
    (the certificate's shared solve); ``floor(mu, gap_scale)``: the support term's rounding floor;
    ``feas_rtol``: the relative penetration counted as rounding. Several feasible points and dual points are tried
    and the smallest bound kept (each is rigorous):

    * feasible points from x, and, when ``ksolve`` is an exact K-solve, from the Lagrangian's minimiser
      ``z = x - K^-1 r`` (``x_f = z + dz``, ``e = dz - K^-1 r``, so that ``|e|_K^2 = r'K^-1 r - 2 dz'r + dz'K dz``:
      the sharper one when mu is accurate and x is not); each corrected by :func:`feasible_correction` (the
      penetrating rows only) and by :func:`face_correction` (also the loaded contact rows and the sticking
      friction nodes held closed: the sharper one when x opens or slips a little where mu says it should not);
    * with an exact K-solve, also the multipliers :func:`slip_multipliers` (the slipping nodes' forces opposing
      their slip with the full radius; Coulomb's radii unchanged) with their own residual solve: the sharper
      one when the answer's friction forces are a little off.

    Cost: products with K and G, a sparse solve with ``G_S G_S'`` (block diagonal per node), and with an exact
    K-solve two more K-solves."""
    tol = feas_rtol * size_max(qp, x)
    Kx = qp.K @ x if Kx is None else Kx
    r = Kx - qp.F - qp.G.T @ mu
    exact = ksolve is not None and not getattr(ksolve, "amg", False)
    best = _best(qp, x, mu, r, rKr, ksolve(r) if exact else None, floor, tol)
    if exact and qp.blocks:
        mu2 = slip_multipliers(qp, mu, qp.G @ x)
        r2 = Kx - qp.F - qp.G.T @ mu2
        w2 = ksolve(r2)
        best = min(best, _best(qp, x, mu2, r2, max(float(r2 @ w2), 0.0), w2, floor, tol))
    nx = size_energy(qp, x, Kx)
    if nx == 0.0 or not np.isfinite(best):
        return float("nan")
    return best / nx
