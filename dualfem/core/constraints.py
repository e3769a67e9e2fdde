"""Constraint blocks ``(G, weights, law)`` of a QP, and the few operations over all blocks of a QP.

A QP carries one or more blocks (:attr:`dualfem.core.qp.QP.constraints`): the first is always the
Signorini block ``(qp.B, qp.weights)`` (possibly with no rows), further ones come from ``QP(blocks=...)``.
The multipliers of a solution are the blocks' multipliers concatenated in block order (length
``qp.m_total``), and ``K x - F = G' mu`` with ``G = qp.G``, the blocks' operators stacked (``qp.B`` itself
when there is one block). See :mod:`dualfem.core.laws` for the laws and their sign conventions.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.laws import CONES, Law


@dataclass(frozen=True, eq=False)
class Constraint:
    """One constraint block: operator ``G`` (m, n) acting on the QP's unknowns (``G x`` in lengths),
    nodal weights ``weights`` (m,) (lengths, > 0) and its :class:`dualfem.core.laws.Law`."""

    G: sp.csr_matrix
    weights: np.ndarray
    law: Law

    @classmethod
    def make(cls, G, weights, law: Law) -> Constraint:
        """A validated block (G as float CSR, weights as a float vector, default 1 per row)."""
        G = sp.csr_matrix(G, dtype=float)
        w = np.ones(G.shape[0]) if weights is None else np.asarray(weights, dtype=float).ravel()
        block = cls(G, w, law)
        block.validate(G.shape[1])
        return block

    @property
    def m(self) -> int:
        """Rows of the block."""
        return self.G.shape[0]

    def validate(self, n: int) -> None:
        """Raise InputError unless G has n columns, finite entries, weights one per row and > 0, and a law."""
        if not isinstance(self.law, Law):
            raise InputError(f"a constraint block's law must be a dualfem.core.laws.Law, got {type(self.law).__name__}")
        if self.G.shape[1] != n:
            raise InputError(f"the {self.law.name} block's G must have {n} columns (the size of K), "
                             f"got {self.G.shape[1]}")
        if self.weights.shape != (self.m,):
            raise InputError(f"the {self.law.name} block's weights must have length {self.m} (rows of G), "
                             f"got {self.weights.shape[0]}")
        if not (np.all(np.isfinite(self.G.data)) and np.all(np.isfinite(self.weights))):
            raise InputError(f"the {self.law.name} block contains NaN or infinite entries")
        if np.any(self.weights <= 0):
            raise InputError(f"the {self.law.name} block's weights must be > 0")


def offsets(blocks: tuple[Constraint, ...]) -> np.ndarray:
    """Start row of each block in the stacked operator, and the total (length len(blocks) + 1)."""
    return np.concatenate([[0], np.cumsum([b.m for b in blocks])]).astype(np.int64)


def split(blocks: tuple[Constraint, ...], v: np.ndarray) -> list[np.ndarray]:
    """``v`` (stacked rows: gaps or multipliers) cut into one view per block (``v`` itself for one block)."""
    if len(blocks) == 1:
        return [v]
    o = offsets(blocks)
    return [v[o[k]:o[k + 1]] for k in range(len(blocks))]


def stack(blocks: tuple[Constraint, ...]) -> sp.csr_matrix:
    """The blocks' operators stacked (the first block's G itself when there is one)."""
    if len(blocks) == 1:
        return blocks[0].G
    return sp.vstack([b.G for b in blocks], format="csr")


def project(blocks: tuple[Constraint, ...], mu: np.ndarray) -> np.ndarray:
    """The stacked multipliers projected block by block onto each law's dual set."""
    mus = tuple(split(blocks, mu))
    parts = [b.law.project(mk, b.weights, mus) for b, mk in zip(blocks, mus)]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def support(blocks: tuple[Constraint, ...], mu: np.ndarray, gap: np.ndarray) -> float:
    """The sum of the blocks' duality-gap terms (:meth:`dualfem.core.laws.Law.support`)."""
    mus, gaps = tuple(split(blocks, mu)), split(blocks, gap)
    return sum((b.law.support(mk, gk, b.weights, mus) for b, mk, gk in zip(blocks, mus, gaps)), 0.0)


def call_law(method, *args, weights=None, mus=()):
    """``method(*args)`` of a law, with ``weights=`` and ``mus=`` when the method takes them (a law written
    before they were passed to :meth:`~dualfem.core.laws.Law.face` / ``face_holds`` keeps working)."""
    params = inspect.signature(method).parameters
    if "weights" in params and "mus" in params:
        return method(*args, weights=weights, mus=mus)
    return method(*args)


def face(blocks: tuple[Constraint, ...], mu: np.ndarray, gap: np.ndarray, c: float) -> np.ndarray:
    """The stacked mask of every block's active face (:meth:`dualfem.core.laws.Law.face`)."""
    mus = tuple(split(blocks, mu))
    parts = [call_law(b.law.face, mk, gk, c, weights=b.weights, mus=mus)
             for b, mk, gk in zip(blocks, mus, split(blocks, gap))]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def conic_rows(blocks: tuple[Constraint, ...]) -> list[tuple[str, int]]:
    """(cone kind, rows) of every block, in block order, from each law's :meth:`dualfem.core.laws.Law.conic`:
    what a conic backend builds (``G x`` in the cone). InputError for a law without a conic description."""
    out = []
    for k, b in enumerate(blocks):
        kind = b.law.conic()
        if kind not in CONES:
            raise InputError(f"the {b.law.name!r} law of constraint block {k} has no conic description "
                             f"(one of {', '.join(CONES)}), got {kind!r}")
        out.append((kind, b.m))
    return out


def upper_bounds(blocks: tuple[Constraint, ...]) -> np.ndarray:
    """Per stacked row, the upper bound of ``G x`` in a box form ``0 <= G x <= u`` (an operator-splitting
    backend's ``l <= A x <= u``): +inf for a ``nonneg`` row, 0 for a ``zero`` row."""
    return np.concatenate([np.full(m, np.inf if kind == "nonneg" else 0.0) for kind, m in conic_rows(blocks)])
