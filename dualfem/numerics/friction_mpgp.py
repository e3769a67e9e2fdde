"""MPGP: Dostál's modified proportioning with gradient projections for separable convex constraints (the dual of
contact with Tresca friction: half-lines lambda_i >= 0 and discs ||t_j|| <= r_j, 2D boxes / 3D discs).

The problem is ``min q(mu) = 1/2 mu'D mu + b0'mu`` over the product set Omega of
:class:`dualfem.numerics.friction_dual.FrictionLayout` (radii fixed: Tresca), gradient ``g = D mu + b0`` (the gaps
and slips). Following Dostál & Kozubek (Math. Program. 135, 2012) and Bouchala, Dostál, Kozubek & Vodstrčil
(2014), with one "block" per normal row or friction node:

* a block is **free** when it lies strictly inside its set (lambda > 0; ||t|| < r), **active** on the boundary,
  with outer unit normal n (-1 for lambda = 0; t/r for the disc);
* the **free gradient** phi is g on free blocks (0 on active ones); the **chopped gradient** beta is, on an
  active block, the part of g that points into the set or along its boundary: ``g - min(g.n, 0) n`` (for
  lambda = 0 it is min(g, 0), MPRGP's); the projected gradient is ``g^P = phi + beta``;
* the **reduced free gradient** ``phi~ = (mu - P(mu - alpha phi)) / alpha`` on free blocks;
* each iteration is a **CG step** in the face along the conjugate direction p when it stays in Omega; else an
  **expansion step** (the largest feasible CG step, then the projected step ``P(mu - alpha phi)``, restart);
  or, when ``|beta|^2 > Gamma^2 phi~'phi`` (not proportional), a **proportioning step**: the exact line search
  along -beta, projected onto Omega, kept if it decreases q, else the projected gradient step ``P(mu - alpha g)``
  (monotone for alpha < 2/|D|);
* stop at ``|g^P| <= tol |b0|``.

The projections are the laws' own (normal: max(., 0); friction: radial onto the disc). Every product D v is
counted by the operator (one K-solve each, matrix-free).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from dualfem.numerics.friction_dual import FrictionLayout


@dataclass
class MPGPResult:
    """MPGP's multipliers ``mu``, whether it ``converged`` (|g^P| <= tol |b0|), the final relative |g^P|, and the
    step counts (cg, expansion, proportioning)."""

    mu: np.ndarray
    converged: bool
    residual: float
    counts: dict
    message: str


class _Blocks:
    """The blocks of a layout with fixed radii r: free masks, gradients split, projection, feasible steps."""

    def __init__(self, layout: FrictionLayout, r: np.ndarray, rel: float = 1e-12):
        self.L, self.r, self.m, self.T = layout, r, layout.m, layout.t_rows
        self.rel = rel

    def project(self, mu: np.ndarray) -> np.ndarray:
        return self.L.project(mu, self.r)

    def split(self, mu: np.ndarray, g: np.ndarray):
        """(free mask per row, phi, beta) at mu (feasible) with gradient g."""
        m, T, r = self.m, self.T, self.r
        free = np.empty(mu.size, bool)
        free[:m] = mu[:m] > 0
        t = mu[T]
        nt = np.linalg.norm(t, axis=1)
        fnode = nt < r * (1 - self.rel)
        free[T] = fnode[:, None]
        phi = np.where(free, g, 0.0)
        beta = np.zeros_like(g)
        beta[:m] = np.where(free[:m], 0.0, np.minimum(g[:m], 0.0))
        act = ~fnode & (r > 0)
        if act.any():
            n = t[act] / nt[act][:, None]
            ga = g[T[act]]
            gn = np.minimum(np.einsum("ij,ij->i", ga, n), 0.0)
            beta[T[act]] = ga - gn[:, None] * n
        return free, phi, beta

    def max_step(self, mu: np.ndarray, p: np.ndarray) -> float:
        """The largest a with mu - a p in Omega (mu in Omega)."""
        m, T, r = self.m, self.T, self.r
        pos = p[:m] > 0
        a = float(np.min(mu[:m][pos] / p[:m][pos])) if pos.any() else np.inf
        t, d = mu[T], -p[T]
        dd = np.einsum("ij,ij->i", d, d)
        mv = dd > 0
        if mv.any():                                    # |t + a d|^2 = r^2: the positive root
            td = np.einsum("ij,ij->i", t[mv], d[mv])
            c0 = np.maximum(r[mv] ** 2 - np.einsum("ij,ij->i", t[mv], t[mv]), 0.0)
            root = (-td + np.sqrt(td ** 2 + dd[mv] * c0)) / dd[mv]
            a = min(a, float(root.min()))
        return a


def mpgp(matvec, b0: np.ndarray, layout: FrictionLayout, r: np.ndarray, alpha: float, gamma: float, tol: float,
         max_iter: int, deadline: float = np.inf, mu0: np.ndarray | None = None) -> MPGPResult:
    """MPGP (module docstring) for min 1/2 mu'D mu + b0'mu over Omega(r), from ``mu0`` projected (default 0)."""
    S = _Blocks(layout, r)
    mu = np.zeros(b0.size) if mu0 is None else S.project(np.asarray(mu0, float))
    g = matvec(mu) + b0 if mu.any() else b0.copy()
    counts = {"cg": 0, "expansion": 0, "proportioning": 0}
    nb0 = max(float(np.linalg.norm(b0)), 1e-300)
    free, phi, beta = S.split(mu, g)
    p = phi.copy()
    k = 0
    while True:
        gp = float(np.linalg.norm(phi + beta))
        if gp <= tol * nb0:
            return MPGPResult(mu, True, gp / nb0, counts, f"converged: |g^P| = {gp / nb0:.1e} |b0| in {k} steps")
        if k >= max_iter or time.perf_counter() > deadline:
            why = f"no convergence in {k} steps" if k >= max_iter else f"time limit after {k} steps"
            return MPGPResult(mu, False, gp / nb0, counts, f"{why} (|g^P|/|b0| = {gp / nb0:.1e})")
        k += 1
        phit = np.where(free, (mu - S.project(mu - alpha * phi)) / alpha, 0.0)
        if beta @ beta <= gamma ** 2 * (phit @ phi):
            if not p.any():
                p = phi.copy()
            Ap = matvec(p)
            pAp = p @ Ap
            a_cg = (g @ p) / pAp
            a_f = S.max_step(mu, p)
            if a_cg <= a_f:
                mu, g = mu - a_cg * p, g - a_cg * Ap
                free, phi, beta = S.split(mu, g)
                p = phi - ((phi @ Ap) / pAp) * p
                counts["cg"] += 1
                continue
            mu = S.project(mu - a_f * p)
            g = g - a_f * Ap
            _, phi_f, _ = S.split(mu, g)
            mu = S.project(mu - alpha * phi_f)
            counts["expansion"] += 1
        else:
            Ab = matvec(beta)
            a = (g @ beta) / (beta @ Ab)
            q0 = 0.5 * mu @ (g - b0) + b0 @ mu
            cand = S.project(mu - a * beta)
            gc = matvec(cand) + b0
            if 0.5 * cand @ (gc - b0) + b0 @ cand < q0:
                mu, g = cand, gc
            else:
                mu = S.project(mu - alpha * g)
            counts["proportioning"] += 1
            if mu is cand:
                free, phi, beta = S.split(mu, g)
                p = phi.copy()
                continue
        g = matvec(mu) + b0
        free, phi, beta = S.split(mu, g)
        p = phi.copy()
