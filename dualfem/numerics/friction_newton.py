"""Semismooth Newton (primal-dual active sets) for contact with Tresca or Coulomb friction, on the stacked dual.

The unknowns are the stacked multipliers ``mu = [lambda; t]`` of :mod:`dualfem.numerics.friction_dual` (forces),
the gaps and slips ``g = D mu + b0`` (lengths). With ``c > 0`` (force / length) the conditions are the
complementarity functions of Hüeber, Stadler & Wohlmuth (SISC 30, 2008; no regularization, no penalty):

    normal row i:       lambda_i - max(0, lambda_i - c g_i) = 0,
    friction node j:    max(r_j, |z_j|) t_j - r_j z_j = 0,      z_j = t_j - c s_j   (s_j = g of its rows),

r_j the radius (Tresca ``g_j w_j``; Coulomb ``mu_f,j max(lambda_j, 0)``, which makes the Coulomb variant
monolithic: the radius is differentiated inside the Newton system). Each step splits the nodes into primal-dual
active sets: normal **contact** (lambda - c g > 0: the gap held at 0) or **open** (lambda = 0); friction
**stick** (|z| < r: the slip held at 0), **slip** (|z| >= r: the linearization of ``|z| t - r z``, with HSW's
modification: t replaced by its projection onto the disc in the term ``t z'/|z|``, which keeps the step a descent
direction away from the solution) or **free** (r = 0: t = 0). In 2D (boxes) a slip row is divided by |z| and
linearized as ``t - r sign(z)`` (HSW's 2D form: the term ``(t sign z - r) dz / |z|`` that vanishes at a solution
is dropped), so for Tresca each step lands on the exact point of its sets: the primal-dual active set method for
boxes; in 3D (discs) it is a semismooth Newton method, superlinear near the solution.

The Newton matrix is ``J = P + Q D`` (P, Q sparse, block diagonal per node; P couples a Coulomb node to its
normal row): dense LU when the operator is dense (D an M x M matrix), else GMRES with products ``D v``
(one K-solve each), preconditioned by J with D replaced by its diagonal (a sparse LU, block diagonal per node).
Steps are semismooth Newton steps, backtracked (halved, at most ``max_backtracks`` times) on
the merit ``|Phi|_inf`` (Phi the projection residual ``mu - P(mu - c g)``) until ``|Phi(mu + t d)| <= (1 - sigma
t) |Phi(mu)|``; when no step passes, the full step is taken (a non-monotone safeguard: full steps alone cycle
between slip directions on a stuck 2D crack at mu_f = 1, where the damped step converges in 3). The
iteration stops at ``|Phi| <= tol`` (relative to the forces' scale) or after ``max_iter`` steps (then the status
is MAX_ITER, never SOLVED).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dualfem.numerics.friction_dual import FrictionLayout


@dataclass
class NewtonResult:
    """The answer of :func:`semismooth_newton`: multipliers ``mu`` (stacked), whether it ``converged``, the final
    relative residual, and the counters (Newton steps, active-set changes, set sizes, GMRES iterations)."""

    mu: np.ndarray
    converged: bool
    residual: float
    steps: int
    changes: int
    sets: dict
    gmres_iterations: int = 0
    history: list = field(default_factory=list)
    message: str = ""


def phi(layout: FrictionLayout, mu: np.ndarray, gap: np.ndarray, c: float) -> np.ndarray:
    """The projection residual ``mu - P(mu - c gap)`` (forces; 0 exactly at a solution): normal rows
    ``min(lambda, c g)``, friction rows ``t_j - P_{r_j}(t_j - c s_j)`` with r_j at mu."""
    z = mu - c * gap
    out = mu - layout.project(z, layout.radius(mu))
    out[:layout.m] = np.minimum(mu[:layout.m], c * gap[:layout.m])
    return out


def _sets(layout: FrictionLayout, mu: np.ndarray, gap: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
    """(contact mask of the normal rows, friction state per node: 0 free (r = 0), 1 stick, 2 slip)."""
    m = layout.m
    contact = (mu[:m] - c * gap[:m]) > 0
    r = layout.radius(mu)
    z = mu[layout.t_rows] - c * gap[layout.t_rows]
    nz = np.linalg.norm(z, axis=1)
    state = np.where(r <= 0, 0, np.where(nz < r, 1, 2))
    return contact, state


def newton_system(layout: FrictionLayout, mu: np.ndarray, gap: np.ndarray, c: float):
    """(P, Q, F, contact, state): the Newton matrix ``J = P + Q D`` and the HSW function F at mu (J d = -F)."""
    M, m, cc = mu.size, layout.m, layout.c
    contact, state = _sets(layout, mu, gap, c)
    rows_p, cols_p, vals_p = [np.flatnonzero(~contact)], [np.flatnonzero(~contact)], [np.ones(int((~contact).sum()))]
    q = np.zeros(M)
    q[:m][contact] = c
    F = np.zeros(M)
    F[:m] = np.where(contact, c * gap[:m], mu[:m])
    tr = layout.t_rows
    free, stick, slip = tr[state == 0].ravel(), tr[state == 1].ravel(), state == 2
    rows_p.append(free)
    cols_p.append(free)
    vals_p.append(np.ones(free.size))
    F[free] = mu[free]
    q[stick] = c
    F[stick] = c * gap[stick]
    Qs = sp.diags(q, format="csr")
    if slip.any():
        R = tr[slip]                                           # (k, c)
        t, s = mu[R], gap[R]
        r = layout.radius(mu)[slip]
        z = t - c * s
        nz = np.linalg.norm(z, axis=1)
        n = z / nz[:, None]
        nt = np.linalg.norm(t, axis=1)
        if cc == 1:         # 2D, a box: the row divided by |z| is t - r sign(z), linear (PDAS for boxes)
            A = np.zeros((t.shape[0], 1, 1))
            Pb = np.ones((t.shape[0], 1, 1))
            F[R.ravel()] = (t - r[:, None] * n).ravel()
            z = n
        else:               # 3D, a disc: HSW, t projected onto the disc in the term t z'/|z|
            tt = t * (r / np.maximum(r, nt))[:, None]
            A = tt[:, :, None] * n[:, None, :] - r[:, None, None] * np.eye(cc)[None]
            Pb = A + nz[:, None, None] * np.eye(cc)[None]
            F[R.ravel()] = (nz[:, None] * t - r[:, None] * z).ravel()
        rr = np.repeat(R, cc, axis=1).ravel()
        cl = np.tile(R, (1, cc)).ravel()
        rows_p.append(rr)
        cols_p.append(cl)
        vals_p.append(Pb.ravel())
        cou = layout.coulomb[slip] & (mu[np.maximum(layout.normal[slip], 0)] > 0)
        if cou.any():                                          # d r = mu_f d lambda: the term -z dr
            nr = layout.normal[slip][cou]
            coef = layout.bound[slip][cou]
            rows_p.append(R[cou].ravel())
            cols_p.append(np.repeat(nr, cc))
            vals_p.append((-z[cou] * coef[:, None]).ravel())
        Qblock = sp.csr_matrix((np.r_[(-c * A).ravel()], (rr, cl)), shape=(M, M))
        Qs = Qs + Qblock
    P = sp.csr_matrix((np.concatenate(vals_p), (np.concatenate(rows_p), np.concatenate(cols_p))), shape=(M, M))
    return P, Qs, F, contact, state


def _solve(op, P, Q, F, counters: dict) -> np.ndarray:
    """d with (P + Q D) d = -F: dense LU (dense operator) or GMRES with operator products."""
    D = getattr(op, "D", None)
    if D is not None:
        J = P.toarray() + Q @ D
        return sla.solve(J, -F)
    M = F.size

    def mv(v):
        return P @ v + Q @ op.apply(v)

    its = [0]

    def cb(_):
        its[0] += 1

    # preconditioner: J with D replaced by its diagonal (block diagonal per node: a sparse LU)
    lu = spla.splu(sp.csc_matrix(P + Q @ sp.diags(op.diagonal())))
    prec = spla.LinearOperator((M, M), matvec=lu.solve)
    d, info = spla.gmres(spla.LinearOperator((M, M), matvec=mv), -F, rtol=1e-13, atol=0.0, restart=min(M, 200),
                         maxiter=20, M=prec, callback=cb, callback_type="pr_norm")
    counters["gmres"] += its[0]
    return d


def semismooth_newton(op, layout: FrictionLayout, c: float, tol: float, max_iter: int, sigma: float = 1e-4,
                      max_backtracks: int = 20,
                      deadline: float = np.inf, mu0: np.ndarray | None = None) -> NewtonResult:
    """HSW's semismooth Newton on the stacked dual of ``op`` (a DualOperator of the stacked QP)."""
    b0 = op.b0
    M = b0.size
    mu = np.zeros(M) if mu0 is None else mu0.copy()
    scale0 = max(c * np.abs(b0).max(initial=0.0), 1e-300)
    counters = {"gmres": 0}
    history: list[dict] = []

    def residual(mu_, gap_):
        return float(np.abs(phi(layout, mu_, gap_, c)).max(initial=0.0) / max(scale0, np.abs(mu_).max(initial=0.0)))

    gap = op.apply(mu) + b0
    res = residual(mu, gap)
    k, changes, last = 0, 0, None
    while res > tol and k < max_iter and time.perf_counter() < deadline:
        k += 1
        P, Q, F, contact, state = newton_system(layout, mu, gap, c)
        key = np.concatenate([contact.astype(np.int8), state.astype(np.int8)])
        if last is not None:
            changes += int((key != last).sum())
        last = key
        d = _solve(op, P, Q, F, counters)
        t = 1.0
        for _ in range(max_backtracks + 1):
            mt = mu + t * d
            gt = op.apply(mt) + b0
            rt = residual(mt, gt)
            if rt <= (1.0 - sigma * t) * res:
                break
            t *= 0.5
        else:                                                  # no decrease: the full step (non-monotone)
            t = 1.0
            mt = mu + d
            gt = op.apply(mt) + b0
            rt = residual(mt, gt)
        mu, gap, res = mt, gt, rt
        history.append({"iter": k, "contact": int(contact.sum()), "stick": int((state == 1).sum()),
                        "slip": int((state == 2).sum()), "step": t, "residual": res})
    contact, state = _sets(layout, mu, gap, c)
    sets = {"contact": int(contact.sum()), "open": int((~contact).sum()), "stick": int((state == 1).sum()),
            "slip": int((state == 2).sum()), "free": int((state == 0).sum())}
    ok = res <= tol
    msg = (f"converged: |Phi| = {res:.1e} (relative) in {k} Newton steps" if ok else
           f"no convergence in {k} Newton steps (|Phi| = {res:.1e})")
    return NewtonResult(mu, ok, res, k, changes, sets, counters["gmres"], history, msg)
