"""The dual of a frictional contact QP: the stacked multipliers, their sets and the per-node frames.

A QP with friction blocks (:mod:`dualfem.core.laws`: :class:`~dualfem.core.laws.Tresca`,
:class:`~dualfem.core.laws.Coulomb`) has the stacked operator ``G = [B; G_1; ...]`` (:attr:`dualfem.core.qp.QP.G`)
and the multipliers ``mu = [lambda; t_1; ...]`` (forces) with ``K x - F = G' mu``. Its dual is

    min  q(mu) = 1/2 mu'D mu + b0'mu   over  lambda >= 0,  ||t_j|| <= r_j  (per friction node j),

``D = G K^-1 G'`` (the Delassus matrix of all rows), ``b0 = G K^-1 F``; the gradient ``D mu + b0 = G x`` is the
normal gaps and the tangential slips. Tresca's radius ``r_j = g_j w_j`` is fixed (a convex QP over a product of
half-lines and discs); Coulomb's ``r_j = mu_f,j max(lambda_j, 0)`` depends on the normal multipliers (a
quasi-variational problem).

:func:`stacked_qp` returns the QP whose ``B`` is the whole ``G``: every existing dual operator
(:func:`dualfem.numerics.dual_operator.make_operator`, dense reduction or matrix-free) then gives D, b0 and
``x(mu)`` of the frictional problem, sharing the factorization of K with the original QP (its store).
:class:`FrictionLayout` says which rows are normal and which are friction nodes, and computes the radii and
the projection onto the dual set. Only friction blocks whose normal partner is the Signorini block 0 are
handled (:func:`layout_refusal` says why not otherwise).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from dualfem.core.laws import Coulomb, Friction
from dualfem.core.qp import QP


def layout_refusal(qp: QP) -> str | None:
    """Why the friction solvers cannot take ``qp`` (a block that is not friction on the Signorini block), or None."""
    for i, b in enumerate(qp.blocks, start=1):
        if not isinstance(b.law, Friction):
            return f"block {i} has law {b.law.name!r}: only friction blocks (tresca, coulomb) are handled"
        if isinstance(b.law, Coulomb) and b.law.normal_block != 0:
            return f"block {i}: Coulomb friction on normal block {b.law.normal_block} (only block 0 is handled)"
    return None


def friction_operator(qp: QP, operator: str, factor, tol: float):
    """The dual operator of the stacked ``qp`` (:func:`stacked_qp`) for a friction solver: ``operator`` as asked;
    ``auto`` (in an ``auto`` linear-algebra context) takes the dense reduction whenever it fits the memory budget,
    else the context's choice. The frictionless crossover (dense below ~1,200 interface unknowns) weighs a dense
    Cholesky against Jacobi-PCG on an SPD face; friction's Newton systems are nonsymmetric (3D slip rows), and
    matrix-free they cost GMRES iterations of one K-solve each, so the dense reduction wins far beyond it."""
    from dualfem.core.errors import InputError, MissingDependency
    from dualfem.numerics.dual_operator import make_operator
    from dualfem.numerics.la import current

    st = stacked_qp(qp)
    chosen = None
    if operator == "auto" and current().operator in (None, "auto"):
        try:
            kind, why = current().choose_operator(st, "dense", factor=getattr(factor, "name", factor))
            chosen = (kind, f"friction: dense fits ({why})")
        except (InputError, MissingDependency):
            chosen = None
    return make_operator(st, operator, factor=factor, tol=tol, chosen=chosen)


def stacked_qp(qp: QP) -> QP:
    """``qp`` with ``B`` = all blocks stacked (:attr:`QP.G`) and their weights, no blocks and no interface part
    (whose rows are the normal ones only); it shares ``qp``'s factorization store (one factorization of K)."""
    from dualfem.numerics.linalg import store_of

    weights = np.concatenate([np.asarray(b.weights, float) for b in qp.constraints])
    return dataclasses.replace(qp, B=qp.G, weights=weights, blocks=(), interface=None, store=store_of(qp))


@dataclasses.dataclass
class FrictionLayout:
    """The rows of the stacked multipliers: ``m`` normal rows first, then the friction nodes.

    ``nodes`` friction nodes in all, ``c`` components each (1 in 2D, 2 in 3D), their rows ``t_rows`` (nodes, c)
    into the stacked vector; ``normal`` (nodes,) the normal row of each node (its Coulomb partner, or -1 for a
    Tresca node), ``bound`` (nodes,) the Tresca radius g_j w_j (force) or the Coulomb coefficient mu_f,j,
    ``coulomb`` (nodes,) which nodes are Coulomb nodes."""

    m: int
    c: int
    t_rows: np.ndarray
    normal: np.ndarray
    bound: np.ndarray
    coulomb: np.ndarray

    @classmethod
    def of(cls, qp: QP) -> FrictionLayout:
        """The layout of ``qp``'s blocks (:func:`layout_refusal` must be None)."""
        start, rows, normal, bound, coulomb = qp.m, [], [], [], []
        cs = {getattr(b.law, "components", 0) for b in qp.blocks}
        c = cs.pop() if len(cs) == 1 else 0
        if c == 0:
            raise ValueError("friction blocks of different components (2D and 3D) in one QP")
        for b in qp.blocks:
            law, k = b.law, b.m // c
            assert isinstance(law, Friction)
            rows.append(start + np.arange(b.m).reshape(k, c))
            if isinstance(law, Coulomb):
                normal.append(np.arange(k) if law.normal_rows is None else np.asarray(law.normal_rows))
                bound.append(np.broadcast_to(np.asarray(law.coefficient, float), (k,)))
                coulomb.append(np.ones(k, bool))
            else:
                normal.append(-np.ones(k, np.int64))
                bound.append(law.radius(np.asarray(b.weights, float)) * np.ones(k))
                coulomb.append(np.zeros(k, bool))
            start += b.m
        return cls(qp.m, c, np.concatenate(rows) if rows else np.zeros((0, c), np.int64),
                   np.concatenate(normal).astype(np.int64), np.concatenate(bound).astype(float),
                   np.concatenate(coulomb))

    @property
    def nodes(self) -> int:
        return int(self.t_rows.shape[0])

    def radius(self, mu: np.ndarray) -> np.ndarray:
        """The disc radii r_j (forces) at the stacked multipliers ``mu`` (Coulomb: mu_f max(lambda, 0))."""
        r = self.bound.copy()
        cn = self.coulomb
        if cn.any():
            r[cn] = self.bound[cn] * np.maximum(mu[self.normal[cn]], 0.0)
        return r

    def project(self, mu: np.ndarray, r: np.ndarray | None = None) -> np.ndarray:
        """``mu`` projected onto the dual set: lambda >= 0, each t_j onto its disc (radii ``r``, default
        :meth:`radius` at the projected lambda)."""
        out = mu.copy()
        out[:self.m] = np.maximum(mu[:self.m], 0.0)
        r = self.radius(out) if r is None else r
        t = mu[self.t_rows]
        nt = np.linalg.norm(t, axis=1)
        scale = np.where(nt > r, r / np.where(nt > 0, nt, 1.0), 1.0)
        out[self.t_rows] = t * scale[:, None]
        return out
