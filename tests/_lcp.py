"""Test helper: an exact, plugin-independent solution of small contact QPs.

For ``min 1/2 x'Kx - F'x s.t. Bx >= 0`` with few constraints (m <= 12), the dual linear
complementarity problem ``gap = D mu + b0 >= 0, mu >= 0, mu.gap = 0`` (D = B K^-1 B',
b0 = B K^-1 F) is solved by enumerating all 2^m active sets with a sparse LU of K; D is positive
definite, so the complementary solution is unique.
"""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse.linalg as spla


def enumerate_lcp(K, F, B):
    """(x, mu, number of complementary active sets found) for the QP (K, F, B)."""
    lu = spla.splu(K.tocsc())
    Bd = B.toarray()
    KiBt = lu.solve(np.ascontiguousarray(Bd.T))
    D = Bd @ KiBt
    D = 0.5 * (D + D.T)
    u0 = lu.solve(np.asarray(F, float))
    b0 = Bd @ u0
    m = B.shape[0]
    assert m <= 12, "enumeration is for tiny defects only"
    sols = []
    for k in range(m + 1):
        for A in itertools.combinations(range(m), k):
            A = list(A)
            mu = np.zeros(m)
            if A:
                mu[A] = np.linalg.solve(D[np.ix_(A, A)], -b0[A])
            gap = D @ mu + b0
            tol = 1e-10 * max(np.abs(b0).max(initial=0.0), np.abs(D).max() * np.abs(mu).max(initial=0.0), 1e-300)
            if np.all(mu >= -tol) and np.all(gap >= -tol):
                sols.append(mu)
    assert sols, "no complementary solution found"
    mu = np.maximum(sols[0], 0.0)
    x = u0 + KiBt @ mu
    x = x + lu.solve(F + B.T @ mu - K @ x)   # one step of iterative refinement
    return x, mu, len(sols)
