"""K = K_el + interface term for one delta after another, without a sparse addition per delta.

The interface term ``sum_j coef_j |u_j^+ - u_j^-|^2`` (``coef = w / delta``, see
:func:`.assemble.interface`) has a pattern that does not depend on delta: 8 entries per defect
node (two components, the 2 x 2 block [[1, -1], [-1, 1]] on its "+" and "-" unknowns). So once a
sum has been formed by scipy (the first delta on a mesh), :class:`InterfaceSum` remembers its
pattern, its values with the interface part taken out (K_el's values there), and the place of
each interface entry; every further delta costs one copy of the values and a few thousand
additions. The result equals scipy's ``K_el + interface(...)[0]`` entry for entry and pattern for
pattern (tests/test_problem.py): the same single floating-point addition per entry; for an exact
cancellation (an entry scipy would drop) :meth:`InterfaceSum.matrix` returns None and the caller
forms scipy's sum.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class InterfaceSum:
    """Delta-free plan of ``K_el + sum_j coef_j |u_j^+ - u_j^-|^2`` (CSC), made from one such sum.

    Use :meth:`from_sum` (None when the sum does not have the expected pattern); ``matrix(coef)``
    returns the sum for coefficients ``coef`` (m,) > 0 (None on an exact cancellation); its index
    arrays are shared, read-only, by every matrix it returns.
    """

    def __init__(self, K_el: sp.csc_matrix, K: sp.csc_matrix, slot: np.ndarray, sign: np.ndarray, node: np.ndarray):
        base = np.array(K.data)
        base[slot] = _values_at(K_el, K.indices[slot], _columns(K, slot))   # K_el's values (0 if none)
        self._base, self._slot, self._sign, self._node = base, slot, sign, node
        self.indices, self.indptr, self.shape = np.array(K.indices), np.array(K.indptr), K.shape
        for a in (self._base, self.indices, self.indptr):
            a.flags.writeable = False

    @classmethod
    def from_sum(cls, K: sp.csc_matrix, K_el: sp.csc_matrix, node_dofs: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray) -> InterfaceSum | None:
        """The plan from a sum ``K`` formed by scipy (canonical CSC), or None if an interface entry is
        missing from its pattern (an exact cancellation) or appears twice."""
        if K.format != "csc" or K_el.format != "csc" or not (K.has_canonical_format and K_el.has_canonical_format):
            return None
        rows, cols, sign, node = _interface_entries(node_dofs, lower, upper)
        slot = _positions(K, rows, cols)
        if np.any(slot < 0) or np.unique(slot).size != slot.size:
            return None
        return cls(K_el, K, slot, sign, node)

    def matrix(self, coef: np.ndarray) -> sp.csc_matrix | None:
        """K_el + sum_j coef_j |u_j^+ - u_j^-|^2 as a new CSC matrix (values of its own), or None on an
        exact cancellation (an entry scipy's sum would drop: the caller forms that sum)."""
        data = self._base.copy()
        data[self._slot] += self._sign * np.asarray(coef, float)[self._node]
        if np.any(data[self._slot] == 0.0):
            return None
        K = sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)
        K.has_canonical_format = True
        return K


def _interface_entries(node_dofs: np.ndarray, lower: np.ndarray,
                       upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, sign, node j) of the 8 m entries of sum_j coef_j |u_j^+ - u_j^-|^2."""
    rows, cols, sign, node = [], [], [], []
    j = np.arange(lower.size)
    for c in range(2):
        up, lo = node_dofs[c, upper], node_dofs[c, lower]
        for r, s, sg in ((up, up, 1.0), (up, lo, -1.0), (lo, up, -1.0), (lo, lo, 1.0)):
            rows.append(r)
            cols.append(s)
            sign.append(np.full(j.size, sg))
            node.append(j)
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(sign), np.concatenate(node)


def _positions(A: sp.csc_matrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Index into ``A.data`` of each entry (rows[k], cols[k]) of a canonical CSC matrix, -1 if not stored."""
    if rows.size == 0:
        return np.zeros(0, np.int64)
    start, end = A.indptr[cols].astype(np.int64), A.indptr[cols + 1].astype(np.int64)
    width = int((end - start).max(initial=0))
    if width == 0:
        return np.full(rows.size, -1, np.int64)
    k = np.arange(width)
    idx = np.minimum(start[:, None] + k, np.maximum(end - 1, start)[:, None])
    hit = (A.indices[np.minimum(idx, A.indices.size - 1)] == rows[:, None]) & (k < (end - start)[:, None])
    return np.where(hit.any(axis=1), start + hit.argmax(axis=1), -1)


def _columns(A: sp.csc_matrix, pos: np.ndarray) -> np.ndarray:
    """Column of each stored entry ``A.data[pos]``."""
    return np.searchsorted(A.indptr, pos, side="right") - 1


def _values_at(A: sp.csc_matrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """A[rows[k], cols[k]] (0 where nothing is stored) of a canonical CSC matrix."""
    pos = _positions(A, rows, cols)
    return np.where(pos >= 0, A.data[np.maximum(pos, 0)], 0.0)
