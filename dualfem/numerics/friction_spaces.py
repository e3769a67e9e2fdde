"""The frictional modified Lagrangian of Uzawa: the stacked dual state, its projections, the generalized
Hessian's coefficients and the two linear-algebra spaces its Newton steps run in.

Stacked rows: the constraint blocks of the QP in block order (:attr:`dualfem.core.qp.QP.constraints`:
the Signorini block first, then friction blocks, node-major), operator ``Gs = qp.G``, weights ``w`` (lengths).
The dual state ``y`` holds stresses: ``l_j`` on a normal row (pressure, >= 0), the tangential traction ``t_j``
(``components`` values) on a friction node, in the disc ``||t_j|| <= g_j`` (g_j the node's threshold, stress:
Tresca's bound, or Coulomb's ``mu_f lambda_j / w_j``); the multipliers (forces) are ``w * y`` (the sign of
:class:`dualfem.core.qp.QP`, ``K x - F = Gs' (w y)``). With ``a = y - r Gs x`` and ``P`` the projection of each
row / node onto its set (``max(., 0)`` for normal rows, the disc for friction nodes) the modified Lagrangian is

    M(x, y) = 1/2 x'Kx - F'x + sum_normal w/(2r) ((a^+)^2 - l^2) + sum_nodes w/(2r) (psi(a_j) - ||t_j||^2),
    psi(a) = ||a||^2 - dist(a, disc_g)^2  (= ||a||^2 inside, 2 g ||a|| - g^2 outside: the Moreau envelope of
    g ||s||, Tresca's term, so that M is the augmented Lagrangian of the frictional problem),

with gradient ``K x - F - Gs' (w P(a))`` and generalized Hessian ``K + r Gs' W dP(a) Gs``: on a normal row 1 where
a > 0, else 0; on a sticking node (||a_j|| < g_j) the identity; on a slipping one ``(g/||a||)(I - a a'/||a||^2)``
(0 in 2D), written as a rotation ``R_j`` of the node's rows onto ``(a/||a||, its normal)`` with diagonal
coefficients ``(0, g/||a||)``, so that every Newton matrix is ``K + Gr' diag(coef) Gr``, ``Gr = R Gs``.

Spaces (the Newton solve, the start K^-1 F, the energy norm):

* :class:`DenseFrictionSpace`: on the local unknowns I of the exact reduction
  (:class:`dualfem.numerics.linalg.LocalReduction`), Newton solves by Woodbury with ``V = L^-1 Gs_I'`` (one
  |A| x |A| Cholesky per step; per active set cached when no node is rotated, i.e. in 2D);
* :class:`SparseFrictionSpace`: on all unknowns, ``K + Gr' diag(coef) Gr`` by
  :class:`dualfem.numerics.newton_matrix.NewtonMatrix` (one analysis; a numeric factorization per new coefficient
  vector, kept ones reused: in 3D the slip directions change every step, so about one per Newton step).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from dualfem.core.constraints import offsets, split
from dualfem.core.laws import Coulomb, Friction, Signorini
from dualfem.core.qp import QP
from dualfem.numerics.linalg import LocalReduction, sparse_factor
from dualfem.numerics.newton_matrix import NewtonMatrix

EPS = float(np.finfo(float).eps)
#: the sparse space's polish forms the dense Delassus matrix (block K-solves) up to this many stacked rows
POLISH_MAX = 4000


class Layout:
    """The stacked rows of a QP's blocks: which rows are normal (Signorini), which friction nodes (per block:
    row offset, components, law), and the weights ``w``. Only Signorini and friction laws are handled."""

    def __init__(self, qp: QP):
        self.blocks = qp.constraints
        self.off = offsets(self.blocks)
        self.w = np.concatenate([b.weights for b in self.blocks])
        self.normal = np.zeros(self.off[-1], bool)
        self.fric: list[tuple[int, int, int, Friction]] = []          # (block index, start row, components, law)
        for k, b in enumerate(self.blocks):
            if isinstance(b.law, Signorini):
                self.normal[self.off[k]:self.off[k + 1]] = True
            elif isinstance(b.law, Friction):
                self.fric.append((k, int(self.off[k]), b.law.components, b.law))
            else:
                raise ValueError(f"law {b.law.name!r} is neither Signorini nor friction")
        self.rotated = any(c > 1 for _, _, c, _ in self.fric)

    @property
    def m(self) -> int:
        return int(self.off[-1])

    def bounds(self, y: np.ndarray) -> list[np.ndarray]:
        """Per friction block, the nodes' thresholds g (stress) given the dual state ``y`` (Coulomb reads its
        normal multipliers ``w y`` there; Tresca's is fixed)."""
        mus = tuple(split(self.blocks, self.w * y))
        out = []
        for k, _, c, law in self.fric:
            wb = self.blocks[k].weights
            out.append(law.radius(wb, mus) / wb[::c])
        return out

    def coulomb(self) -> bool:
        return any(isinstance(law, Coulomb) for *_, law in self.fric)

    def nodes(self, v: np.ndarray, j: int) -> np.ndarray:
        """The rows of friction block j of a stacked vector as (nodes, components) (a view)."""
        k, start, c, _ = self.fric[j]
        return v[start:int(self.off[k + 1])].reshape(-1, c)


def project(lay: Layout, a: np.ndarray, g: list[np.ndarray]) -> np.ndarray:
    """P(a): normal rows ``max(a, 0)``, friction nodes onto their discs of radius g."""
    p = np.where(lay.normal, np.maximum(a, 0.0), a)
    for j in range(len(lay.fric)):
        aj, pj = lay.nodes(a, j), lay.nodes(p, j)
        n = np.linalg.norm(aj, axis=1)
        out = n > g[j]
        pj[out] = aj[out] * (g[j][out] / n[out])[:, None]
    return p


def newton_terms(lay: Layout, a: np.ndarray, g: list[np.ndarray], r: float):
    """(coef, rot) of the generalized Hessian at ``a`` (module docstring): ``coef`` per stacked row, ``rot`` None
    or per 3D friction block the (nodes, 2, 2) rotations (identity on sticking nodes)."""
    coef = np.where(lay.normal & (a > 0), r * lay.w, 0.0)
    rot: list | None = [] if lay.rotated else None
    for j, (_, _, c, _) in enumerate(lay.fric):
        aj, cj, wj = lay.nodes(a, j), lay.nodes(coef, j), lay.nodes(lay.w, j)
        n = np.linalg.norm(aj, axis=1)
        stick = n < g[j]
        cj[stick] = r * wj[stick]
        if c == 1:
            if rot is not None:
                rot.append(None)
            continue
        R = np.tile(np.eye(2), (aj.shape[0], 1, 1))
        slip = ~stick & (n > 0)
        e = aj[slip] / n[slip, None]
        R[slip, 0, :], R[slip, 1, :] = e, np.c_[-e[:, 1], e[:, 0]]
        cj[slip, 0], cj[slip, 1] = 0.0, r * wj[slip, 1] * g[j][slip] / n[slip]
        assert rot is not None
        rot.append(R)
    return coef, rot


def remainder(lay: Layout, a: np.ndarray, e: np.ndarray, g: list[np.ndarray]) -> np.ndarray:
    """Per stacked row (friction: on the node's first row), ``phi(a + e) - phi(a) - phi'(a) e`` of the penalty
    (normal rows ``(a^+)^2``, friction nodes psi), in a cancellation-free form where both points lie on one
    smooth piece, so that a Newton step at rounding level is judged the same by every space."""
    ap, lps = np.maximum(a, 0.0), a + e
    rem = np.where((a > 0) & (lps > 0), e * e, np.maximum(lps, 0.0) ** 2 - ap * ap - 2.0 * e * ap)
    rem = np.where(lay.normal, rem, 0.0)
    for j in range(len(lay.fric)):
        aj, ej, rj = lay.nodes(a, j), lay.nodes(e, j), lay.nodes(rem, j)
        gj, b = g[j], aj + ej
        na, nb = np.linalg.norm(aj, axis=1), np.linalg.norm(b, axis=1)
        ee = np.einsum("ij,ij->i", ej, ej)
        inside = (na <= gj) & (nb <= gj)
        safe = np.where(na > 0, na, 1.0)
        ae = np.einsum("ij,ij->i", aj, ej) / safe
        den = nb + na + ae
        outside = (na > gj) & (nb > gj) & (den > 0)
        psi_b = np.where(nb <= gj, nb * nb, 2 * gj * nb - gj * gj)
        psi_a = np.where(na <= gj, na * na, 2 * gj * na - gj * gj)
        lin = 2.0 * np.einsum("ij,ij->i", _disc(aj, na, gj), ej)
        val = np.where(inside, ee, np.where(outside, 2 * gj * (ee - ae * ae) / np.where(den > 0, den, 1.0),
                                            psi_b - psi_a - lin))
        rj[:, 0] = val
    return rem


def _disc(aj: np.ndarray, n: np.ndarray, g: np.ndarray) -> np.ndarray:
    out = n > g
    p = aj.copy()
    p[out] = aj[out] * (g[out] / n[out])[:, None]
    return p


def _rotate(lay: Layout, M: np.ndarray, rot) -> np.ndarray:
    """M (rows = stacked rows, any trailing shape) with each 3D friction node's rows rotated by R_j (a copy)."""
    if rot is None:
        return M
    M = M.copy()
    for j, R in enumerate(rot):
        if R is None:
            continue
        k, start, c, _ = lay.fric[j]
        block = M[start:int(lay.off[k + 1])]
        nodes = block.reshape(-1, c, *block.shape[1:])
        block[...] = np.einsum("nij,nj...->ni...", R, nodes).reshape(block.shape)
    return M


class DenseFrictionSpace:
    """Dense, on the local unknowns I (the exact reduction; every friction row must live on I)."""

    kind = "dense"

    def __init__(self, qp: QP, lay: Layout, reduction: LocalReduction | None = None, factor=None):
        self.red = red = reduction if reduction is not None else LocalReduction(qp, factor=factor)
        self.lay, self.Q, self.c0 = lay, red.S, red.c0
        G = qp.G.tocsc()
        outside = np.ones(qp.n, bool)
        outside[red.I] = False
        if G[:, outside].nnz:
            raise ValueError("a constraint row touches unknowns outside the reduction's local set")
        self.G = G[:, red.I].toarray()
        self.L = red.S_cho[0]
        self.V = la.solve_triangular(self.L, self.G.T, lower=True, check_finite=False)
        self._cache: dict[bytes, tuple] = {}
        self.factorizations = 0

    def start(self) -> np.ndarray:
        return la.cho_solve(self.red.S_cho, self.red.g, check_finite=False)

    def qgrad(self, z):
        return self.Q @ z - self.red.g

    def qform(self, d):
        return float(d @ (self.Q @ d))

    def norm2(self, z):
        return float(z @ (self.Q @ z) - 2.0 * self.c0)

    def full(self, z):
        return self.red.full(z)

    def newton(self, coef: np.ndarray, rot, rhs: np.ndarray) -> np.ndarray:
        """Solve (Q + Gr' diag(coef) Gr) d = rhs by Woodbury (Gr = R Gs)."""
        h = la.solve_triangular(self.L, rhs, lower=True, check_finite=False)
        A = np.flatnonzero(coef)
        if A.size:
            key = coef.tobytes() if rot is None else None
            fac = self._cache.get(key) if key is not None else None
            VA = _rotate(self.lay, self.V.T, rot)[A].T
            if fac is None:
                cap = VA.T @ VA
                cap[np.diag_indices_from(cap)] += 1.0 / coef[A]
                fac = la.cho_factor(cap, lower=True, check_finite=False)
                self.factorizations += 1
                if key is not None:
                    if len(self._cache) >= 64:
                        self._cache.pop(next(iter(self._cache)))
                    self._cache[key] = fac
            h = h - VA @ la.cho_solve(fac, VA.T @ h, check_finite=False)
        return la.solve_triangular(self.L, h, lower=True, trans="T", check_finite=False)

    def polish(self, A: np.ndarray, C: np.ndarray, mu_fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z, mu) of the minimiser on one piece: rows ``A`` carry ``mu_A = -C_A (Gs z)_A`` (penalty springs), the
        others the fixed forces ``mu_fixed``: ``(D_AA + C_A^-1) mu_A = -(Gs S^-1 (g + Gs' mu_fixed))_A``, then
        ``z = S^-1 (g + Gs' mu)`` (well conditioned however large C: no difference of rounded gaps)."""
        h = la.solve_triangular(self.L, self.red.g + self.G.T @ mu_fixed, lower=True, check_finite=False)
        mu = mu_fixed.copy()
        if A.any():
            VA = self.V[:, A]
            M = VA.T @ VA
            M[np.diag_indices_from(M)] += 1.0 / C
            mu[A] = la.solve(M, -(VA.T @ h), assume_a="pos")
            self.factorizations += 1
        return la.cho_solve(self.red.S_cho, self.red.g + self.G.T @ mu, check_finite=False), mu

    def mu_min(self, w: np.ndarray) -> float:
        """Smallest eigenvalue of W^1/2 (Gs K^-1 Gs') W^1/2 on its range (dense eigvalsh)."""
        sw = np.sqrt(w)
        Vw = self.V * sw[None, :]
        return _range_min(np.linalg.eigvalsh(Vw.T @ Vw))


class SparseFrictionSpace:
    """Sparse, on all unknowns: one factorization of K + Gr' diag(coef) Gr per Newton step."""

    kind = "sparse"

    def __init__(self, qp: QP, lay: Layout, factor=None, keep: int = 4):
        self.qp, self.lay, self.factor = qp, lay, factor
        self.Q, self.q, self.G = qp.K.tocsr(), np.asarray(qp.F, float), qp.G.tocsr()
        self._K: Any = None
        self._D: np.ndarray | None = None
        # one extra row g1 + g2 per 3D friction node: with it every Newton matrix K + Gs' R' diag(c) R Gs is
        # K + Bx' diag(c_ext) Bx on one pattern (NewtonMatrix: analyzed once, numeric factors kept by c_ext)
        self._sum = _node_sums(lay)
        Bx = self.G if self._sum is None else sp.vstack([self.G, self._sum @ self.G], format="csr")
        self.nm = NewtonMatrix(self.Q, Bx, factor, keep=keep)

    @property
    def factorizations(self) -> int:
        return self.nm.counters.factorizations + int(self._K is not None)

    def _k(self):
        if self._K is None:
            self._K = sparse_factor(self.Q, self.factor)
        return self._K

    def start(self):
        return self._k().solve(self.q)

    def qgrad(self, z):
        return self.Q @ z - self.q

    def qform(self, d):
        return float(d @ (self.Q @ d))

    def norm2(self, z):
        return float(z @ (self.Q @ z))

    def full(self, z):
        return z

    def newton(self, coef, rot, rhs):
        """Solve (K + Gr' diag(coef) Gr) d = rhs: each rotated node's 2 x 2 block R' diag(c) R = [[p, q], [q, s]]
        becomes the coefficients (p - q, s - q) on its rows and q on its extra row g1 + g2."""
        c = np.array(coef, float)
        if self._sum is None:
            return self.nm.solve(c, rhs)
        extra = []
        for j, R in enumerate(rot or []):
            if R is None:
                continue
            cj = self.lay.nodes(c, j)
            c0, c1 = cj[:, 0].copy(), cj[:, 1].copy()
            p = c0 * R[:, 0, 0] ** 2 + c1 * R[:, 1, 0] ** 2
            s_ = c0 * R[:, 0, 1] ** 2 + c1 * R[:, 1, 1] ** 2
            q = c0 * R[:, 0, 0] * R[:, 0, 1] + c1 * R[:, 1, 0] * R[:, 1, 1]
            cj[:, 0], cj[:, 1] = p - q, s_ - q
            extra.append(q)
        return self.nm.solve(np.concatenate([c, *extra]), rhs)

    def delassus(self) -> np.ndarray:
        """D = Gs K^-1 Gs' (dense, m_total x m_total), by block solves of 256 columns; computed once."""
        if self._D is None:
            K, G = self._k(), self.G
            Gt = G.T.tocsc()
            cols = [G @ K.solve(Gt[:, i:i + 256].toarray()) for i in range(0, G.shape[0], 256)]
            D = np.hstack(cols) if cols else np.zeros((0, 0))
            self._D = 0.5 * (D + D.T)
        return self._D

    def polish(self, A: np.ndarray, C: np.ndarray, mu_fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """As :meth:`DenseFrictionSpace.polish`, with the Delassus matrix of :meth:`delassus` (formed once, by block
        K-solves); None above ``POLISH_MAX`` stacked rows (its memory, 8 m^2 bytes)."""
        if self.lay.m > POLISH_MAX:
            return None
        K, G = self._k(), self.G
        mu = mu_fixed.copy()
        if A.any():
            M = self.delassus()[np.ix_(A, A)]
            M[np.diag_indices_from(M)] += 1.0 / C
            mu[A] = la.solve(M, -(G @ K.solve(self.q + G.T @ mu_fixed))[A], assume_a="pos")
        return K.solve(self.q + G.T @ mu), mu

    def mu_min(self, w: np.ndarray, tol: float = 1e-2) -> float:
        """Lanczos estimate (ARPACK eigsh, smallest) of W^1/2 Gs K^-1 Gs' W^1/2 (one K-solve per product)."""
        from scipy.sparse.linalg import LinearOperator, eigsh

        sw, K, G = np.sqrt(w), self._k(), self.G
        m = G.shape[0]
        if m <= 32:
            cols = np.column_stack([K.solve(G.T @ (sw * e)) for e in np.eye(m)])
            return _range_min(np.linalg.eigvalsh(sw[:, None] * (G @ cols)))
        op = LinearOperator((m, m), matvec=lambda v: sw * (G @ K.solve(G.T @ (sw * np.ravel(v)))), dtype=float)
        return float(eigsh(op, k=1, which="SA", tol=tol, v0=np.ones(m) / np.sqrt(m),
                           return_eigenvectors=False, maxiter=max(1000, 10 * m))[0])


def _node_sums(lay: Layout) -> sp.csr_matrix | None:
    """The operator summing the two rows of every 3D friction node (rows: those nodes, in block order), or None."""
    rows, cols = [], []
    count = 0
    for k, start, c, _ in lay.fric:
        if c != 2:
            continue
        nodes = (int(lay.off[k + 1]) - start) // 2
        rows.append(np.repeat(np.arange(count, count + nodes), 2))
        cols.append(start + np.arange(2 * nodes))
        count += nodes
    if not count:
        return None
    r, cc = np.concatenate(rows), np.concatenate(cols)
    return sp.csr_matrix((np.ones(r.size), (r, cc)), shape=(count, lay.m))


def _rotation(lay: Layout, rot) -> sp.csr_matrix:
    """The block-diagonal rotation of the stacked rows (identity but on 3D friction nodes)."""
    rows, cols, vals = [np.arange(lay.m)], [np.arange(lay.m)], [np.ones(lay.m)]
    keep = np.ones(lay.m, bool)
    for j, R in enumerate(rot):
        if R is None:
            continue
        k, start, c, _ = lay.fric[j]
        keep[start:int(lay.off[k + 1])] = False
        base = start + c * np.arange(R.shape[0])
        rr = base[:, None, None] + np.arange(c)[None, :, None]
        cc = base[:, None, None] + np.arange(c)[None, None, :]
        rows.append(np.broadcast_to(rr, R.shape).ravel())
        cols.append(np.broadcast_to(cc, R.shape).ravel())
        vals.append(R.ravel())
    rows[0], cols[0], vals[0] = rows[0][keep], cols[0][keep], vals[0][keep]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(lay.m, lay.m))


def _range_min(ev: np.ndarray) -> float:
    top = float(ev.max(initial=0.0))
    kept = ev[ev > ev.size * EPS * top]
    return float(kept.min()) if kept.size else float(ev.min(initial=0.0))
