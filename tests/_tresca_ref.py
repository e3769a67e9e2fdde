"""An independent reference for frictional QPs (tests only): cvxpy + Clarabel on the norm formulation.

Tresca blocks enter as ``sum_j r_j ||s_j||`` with ``s = G_t x`` an auxiliary variable whose equality
constraint's dual is the friction multiplier (``K x - F = B' lambda + G_t' mu_t``, the QP's sign)."""
from __future__ import annotations

import numpy as np


def tresca_reference(qp, warm=None):
    """(x, mu stacked over every block, {}) of a QP whose extra blocks are all Tresca, by cvxpy + Clarabel."""
    import cvxpy as cp

    x = cp.Variable(qp.n)
    energy = 0.5 * cp.quad_form(x, cp.psd_wrap(qp.K)) - qp.F @ x
    cons, eqs = [], []
    if qp.B.shape[0]:
        cons.append(qp.B @ x >= 0)
    for b in qp.blocks:
        c = b.law.components
        s = cp.Variable(b.m)
        r = b.law.radius(b.weights)
        energy = energy + r @ cp.norm(cp.reshape(s, (b.m // c, c), order="C"), 2, axis=1)
        eqs.append(s == b.G @ x)
    cp.Problem(cp.Minimize(energy), cons + eqs).solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10,
                                                      tol_feas=1e-10)
    lam = np.asarray(cons[0].dual_value, float) if cons else np.zeros(0)
    mus = [np.asarray(e.dual_value, float).ravel() for e in eqs]
    return np.asarray(x.value, float), np.concatenate([lam, *mus]), {"solves": 1}
