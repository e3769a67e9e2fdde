"""Dependent constraint rows in the certificate (:func:`dualfem.numerics.certify.active_set_check`).

Non-unique multipliers are normal: duplicated rows (positive multiples of one another,
:func:`parallel_rows`) are one constraint, judged by the force of the group (:func:`group_forces`); a row
off the active set A whose normal is a combination of A's (:func:`implied_rows`) has gap 0 at the exact
point by construction and no margin is asked of it; where duplicates do not explain a singular D_AA
(:func:`groups_explain`), the step's forces are accepted if nonnegative forces reproduce B_A'mu1
(:func:`nonnegative_forces`). ``face``: the certificate's D_AA^-1 for one set (``solve``, and ``pinv``
= (V, w), the eigenpairs of D_AA's range, when D_AA is singular).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.evaluator import force_scale
from dualfem.core.qp import QP


def parallel_rows(B) -> np.ndarray | None:
    """Labels of the rows of B that are one constraint: ``labels[j] = labels[k]`` when row j is a positive
    multiple of row k (duplicated rows, to 1e-12 of the row's size); None when every row is its own. Two
    random projections of the normalised rows find the candidates (sorted), which are then compared."""
    import scipy.sparse as sp

    B = sp.csr_matrix(B)
    m = B.shape[0]
    if m < 2:
        return None
    norms = np.sqrt(np.asarray(B.multiply(B).sum(axis=1)).ravel())
    scale = np.where(norms > 0, norms, 1.0)
    h = (B @ np.random.default_rng(0).standard_normal((B.shape[1], 2))) / scale[:, None]
    order = np.lexsort((h[:, 1], h[:, 0]))
    close = np.all(np.abs(np.diff(h[order], axis=0)) <= 1e-10 * (1 + np.abs(h[order][1:])), axis=1)
    if not close.any():
        return None
    labels = np.arange(m)
    for i in np.flatnonzero(close):
        j, k = order[i], order[i + 1]
        d = B[j] / scale[j] - B[k] / scale[k]
        if norms[j] > 0 and norms[k] > 0 and (d.nnz == 0 or np.abs(d.data).max() <= 1e-12):
            labels[k] = labels[j]
    return None if np.unique(labels).size == m else labels


def group_sum(labels: np.ndarray | None, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """sum_{j in group} w_j v_j for each row's group, per row (v itself without groups)."""
    if labels is None:
        return v
    return np.bincount(labels, weights=w * v, minlength=labels.size)[labels]


def group_forces(qp: QP, A: np.ndarray, mu: np.ndarray, mu1: np.ndarray) -> tuple:
    """(labels, in_A, mu1_g, err_mu): duplicated rows (one constraint, several rows: the split of its force is
    not unique) are judged as one: the force of the group (each row's multiplier times its row's size), and
    no gap test for a row whose constraint is active through another row of its group (``in_A``); err_mu the
    multipliers' error against mu1, relative to the force scale."""
    labels = parallel_rows(qp.B) if qp.m else None
    size = np.sqrt(np.asarray(qp.B.multiply(qp.B).sum(axis=1)).ravel()) if labels is not None else np.ones(qp.m)
    in_A = group_sum(labels, A.astype(float), np.ones(qp.m)) > 0
    mu1_g = group_sum(labels, mu1, size) / size if labels is not None else mu1
    err_mu = float(np.abs(group_sum(labels, mu - mu1, size) / size).max(initial=0.0)) / force_scale(qp, mu1)
    return labels, in_A, mu1_g, err_mu


#: a row off A is implied by A (its normal in the span of A's, so B_A x = 0 makes its gap 0) when the part of
#: it outside that span, in the K^-1 norm (a Schur complement of D), is below this fraction of its own
IMPLIED_RTOL = 1e-10


def implied_rows(D: np.ndarray, A: np.ndarray, rows: np.ndarray, face) -> np.ndarray:
    """Mask of the rows (of ``rows``) whose normals are combinations of A's (dependent rows): their gap at
    the exact point of A is 0 by construction, no separate constraint, so no gap margin is asked of them.
    ``D_jj - D_jA D_AA^+ D_Aj <= IMPLIED_RTOL D_jj`` (dense D only)."""
    idx = np.flatnonzero(rows)
    DAo = D[np.ix_(A, idx)]
    schur = np.diag(D)[idx] - np.einsum("ij,ij->j", DAo, face.solve(DAo))
    out = np.zeros(rows.size, bool)
    out[idx] = schur <= IMPLIED_RTOL * np.diag(D)[idx]
    return out


def groups_explain(labels: np.ndarray | None, A: np.ndarray, face) -> bool:
    """True when the rank of a singular D_AA is the number of constraints (groups of duplicated rows) in A:
    the duplicates are the whole dependence, and the group forces are unique."""
    return labels is not None and face.pinv is not None and face.pinv[1].size == np.unique(labels[A]).size


#: the nonnegative forces of a dependent face must reproduce B_A'mu1 to this fraction of its size
#: (energy norm |.|_{K^-1}); a larger mismatch means a force of the wrong sign: the set is not verified
NNLS_RTOL = 1e-6


def nonnegative_forces(face, mu1_A: np.ndarray) -> tuple[float, bool]:
    """(|B_A'(nu - mu1_A)|_{K^-1} for the nonnegative nu closest in that norm, whether it is within
    :data:`NNLS_RTOL` of |B_A'mu1_A|_{K^-1}): nonnegative least squares with D_AA^1/2 from the face's
    eigendecomposition (|B_A'v|_{K^-1}^2 = v'D_AA v)."""
    from scipy.optimize import nnls

    V, w = face.pinv
    M = (V * np.sqrt(w)).T
    d = M @ mu1_A
    _, res = nnls(M, d)
    return float(res), bool(res <= NNLS_RTOL * float(np.linalg.norm(d)))
