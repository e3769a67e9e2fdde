"""The exact face polish of a multi-block answer (friction): the certificate's face step, repeated until it holds.

An interior-point answer of a frictional QP (:mod:`dualfem.numerics.epigraph`) is accurate to its tolerance only.
Each step (:func:`newton_step`) solves, in the multipliers, the QP's conditions on the face the laws guess from
(x, mu) (:meth:`dualfem.core.laws.Law.face`): rows on the face held at gap 0 (Signorini contact, stick friction
nodes), other rows at the law's complementary force (:meth:`dualfem.core.laws.Law.complementary`: 0 for an
open Signorini row), except slipping friction nodes, whose force ``-r_j s_j / ||s_j||`` is linearised in the
slip ``s_j`` (a Newton step for its direction: ``mu_j + r_j / ||s_j|| (I - d_j d_j') s_j' = -r_j d_j``, d_j the
unit slip). In 2D (a slip has a sign, not a direction) one step lands on the solution when the face is right;
in 3D the directions converge quadratically. The polish is accepted only when a step's point passes the laws'
own check (:meth:`dualfem.numerics.faces.FaceStep.holds`, with margins 10 times the step) and lowers the
evaluator's KKT error; otherwise the caller keeps, and says it keeps, the backend's answer. Coulomb's radius is
taken at the current normal forces (not linearised): a Coulomb answer is polished only where that holds.

Dense: the Delassus matrix of all ``m_total`` rows from as many K-solves (up to
:data:`dualfem.numerics.faces.MAX_ROWS` rows; beyond, or with AMG K-solves, no polish).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from dualfem.core import constraints, evaluator
from dualfem.core.laws import Friction
from dualfem.core.qp import QP
from dualfem.numerics.faces import MAX_ROWS, FaceStep, delassus

#: Newton steps tried before the polish gives up
STEPS = 12


def face_polish(qp: QP, x: np.ndarray, mu: np.ndarray, steps: int = STEPS, margin: float = 10.0):
    """(x, mu, info) on the verified exact face, or None (not finite, too many rows, AMG, no step held)."""
    from dualfem.numerics.ksolver import solver_for

    if x is None or mu is None or not (np.all(np.isfinite(x)) and np.all(np.isfinite(mu))) \
            or qp.m_total > MAX_ROWS:
        return None
    ksolve = solver_for(qp)
    if getattr(ksolve, "amg", False):
        return None
    D, c = delassus(qp, ksolve)
    x, mu = np.asarray(x, float), np.asarray(mu, float)
    for k in range(steps):
        st = newton_step(qp, x, mu, ksolve, D, c)
        if st is None:
            return None
        x, mu = st.x1(qp, x, ksolve), st.mu1
        if st.holds(qp, margin):
            return x, mu, {"face_steps": k + 1, "face_rows": int(st.A.sum())}
    return None


def newton_step(qp: QP, x: np.ndarray, mu: np.ndarray, ksolve, D: np.ndarray, c: float) -> FaceStep | None:
    """One step of the module docstring: the face point as a :class:`dualfem.numerics.faces.FaceStep` (None when
    its linear system is singular). With ``delta = mu' - mu`` the gaps are ``g0 + D delta``, ``g0 = G (x - z)``,
    ``z = K^-1 (K x - F - G' mu)``."""
    blocks, G = qp.constraints, qp.G
    gap = G @ x
    A = constraints.face(blocks, mu, gap, c)
    mus, gaps = tuple(constraints.split(blocks, mu)), constraints.split(blocks, gap)
    held = np.concatenate([b.law.complementary(mk, gk, b.weights, mus) for b, mk, gk in zip(blocks, mus, gaps)])
    r = qp.K @ x - qp.F - G.T @ mu
    z = ksolve(r)
    Gz = G @ z
    g0 = gap - Gz
    M = np.zeros_like(D)
    rhs = np.zeros(mu.size)
    M[A] = D[A]                                   # face rows: g0 + D delta = 0
    rhs[A] = -g0[A]
    off = np.flatnonzero(~A)                      # off the face: mu' = held ...
    M[off, off] = 1.0
    rhs[off] = held[off] - mu[off]
    o = constraints.offsets(blocks)
    for k, b in enumerate(blocks):                # ... but slipping friction nodes: linearised in their slip
        if isinstance(b.law, Friction):
            _slip_rows(M, rhs, b, o[k], A[o[k]:o[k + 1]], gap[o[k]:o[k + 1]], g0, D, mu, held, mus)
    try:
        delta = sla.solve(M, rhs)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(delta)):
        return None
    Dd = D @ delta
    return FaceStep(A, mu + delta, g0 + Dd, z, float(r @ z), Gz, delta, Dd, float(np.abs(delta).max(initial=0.0)),
                    float(np.abs(Dd - Gz).max(initial=0.0)))


def _slip_rows(M, rhs, block, start, face, gap, g0, D, mu, held, mus) -> None:
    """Rows of the slipping nodes of a friction block: ``delta_j + T_j (g0 + D delta)_j = held_j - mu_j`` with
    ``T_j = r_j / ||s_j|| (I - d_j d_j')`` (the derivative of ``-r_j s / ||s||`` at the current slip)."""
    law, c = block.law, block.law.components
    r = law.radius(block.weights, mus)
    s = law.nodes(gap)
    norm = np.linalg.norm(s, axis=1)
    for j in np.flatnonzero(~face[::c] & (r > 0) & (norm > 0)):
        rows = start + j * c + np.arange(c)
        d = s[j] / norm[j]
        T = r[j] / norm[j] * (np.eye(c) - np.outer(d, d))
        M[rows] = T @ D[rows]
        M[np.ix_(rows, rows)] += np.eye(c)
        rhs[rows] = held[rows] - mu[rows] - T @ g0[rows]


def polish_if_better(qp: QP, x: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """(x, mu, info): :func:`face_polish`, kept only if it lowers the evaluator's KKT error (``info["polished"]``
    says which, ``info["kkt_before_polish"]`` the error before)."""
    before = evaluator.kkt_error(evaluator.residuals(qp, x, mu))
    out = face_polish(qp, x, mu)
    if out is not None and evaluator.kkt_error(evaluator.residuals(qp, out[0], out[1])) < before:
        return out[0], out[1], {"polished": True, "kkt_before_polish": before, **out[2]}
    return x, mu, {"polished": False, "kkt_before_polish": before}
