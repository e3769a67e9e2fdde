"""The bound through the face's exact point for a QP with a Tresca block (dualfem/numerics/degenerate.py through
dualfem/numerics/faces.py): stick on the disc's edge is degenerate (no slip, force at the threshold), an answer
there gets a bound at rounding, and no perturbed answer a bound below its true error (exact solutions by
enumerating the faces of tiny QPs)."""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from dualfem.core.constraints import Constraint
from dualfem.core.evaluator import size_energy
from dualfem.core.laws import Tresca
from dualfem.core.qp import QP
from dualfem.numerics.certify import certified_error


def tresca_qp(K: np.ndarray, F: np.ndarray, b: np.ndarray, t: np.ndarray, g: float) -> QP:
    """min 1/2 x'Kx - F'x + g |t'x| s.t. b'x >= 0 (one Signorini row, one Tresca row of weight 1)."""
    block = Constraint.make(sp.csr_matrix(t[None, :]), None, Tresca(g))
    return QP(K=sp.csc_matrix(K), F=F, B=sp.csr_matrix(b[None, :]), blocks=(block,))


def exact(K: np.ndarray, F: np.ndarray, b: np.ndarray, t: np.ndarray, g: float) -> np.ndarray:
    """The solution of :func:`tresca_qp`'s problem: the face (row closed or open, stick or slip either way) whose
    KKT point holds."""
    G = np.vstack([b, t])
    for closed, mode in itertools.product((True, False), ("stick", "plus", "minus")):
        rows = [i for i, on in ((0, closed), (1, mode == "stick")) if on]
        fixed = np.array([0.0, {"stick": 0.0, "plus": -g, "minus": g}[mode]])
        m = len(rows)
        M = np.block([[K, -G[rows].T], [G[rows], np.zeros((m, m))]])
        sol = np.linalg.solve(M, np.concatenate([F + G.T @ fixed, np.zeros(m)]))
        x, mu = sol[:K.shape[0]], fixed.copy()
        mu[rows] = sol[K.shape[0]:]
        s = t @ x
        ok = b @ x >= -1e-12 and mu[0] >= -1e-12 and abs(mu[1]) <= g + 1e-12
        ok &= {"stick": True, "plus": s >= -1e-12, "minus": s <= 1e-12}[mode]
        if ok:
            return x
    raise AssertionError("no KKT point")


def rel_error(qp: QP, x: np.ndarray, xs: np.ndarray) -> float:
    e = x - xs
    return float(np.sqrt(e @ (qp.K @ e)) / size_energy(qp, x))


def test_stick_on_the_disc_edge_is_certified_at_rounding():
    # x* = (0, 0, 1): the Signorini row closed with force 1, the Tresca row stuck with its force -g = -0.5 at the
    # disc's edge (degenerate); the answer x* + 1e-15 (a solver's rounding): the duality-gap bound alone is
    # sqrt(rounding) (~1e-8), the face step not verified
    K = np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.5], [0.0, 0.5, 2.0]])
    b, t, g = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), 0.5
    xs, mu = np.array([0.0, 0.0, 1.0]), np.array([1.0, -0.5])
    F = K @ xs - np.vstack([b, t]).T @ mu
    qp = tresca_qp(K, F, b, t, g)
    assert np.allclose(exact(K, F, b, t, g), xs)
    x = xs + np.array([1e-15, 1e-15, 0.0])
    c = certified_error(qp, x, mu)
    assert np.isnan(c["active_set"]) and c["bound"] > 1e-10
    assert c["value"] == c["degenerate"] <= 1e-13 and c["degenerate"] >= rel_error(qp, x, xs)


def test_random_tresca_answers_hold_their_error():
    # 150 random tiny Tresca QPs, answers off the solution by O(0.3) in some entries (x kept feasible)
    applied = 0
    for seed in range(150):
        rng = np.random.default_rng(seed)
        M = rng.standard_normal((4, 4))
        K, F = M @ M.T + 0.3 * np.eye(4), rng.standard_normal(4)
        b, t, g = rng.standard_normal(4), rng.standard_normal(4), float(rng.uniform(0.1, 1.0))
        xs = exact(K, F, b, t, g)
        qp = tresca_qp(K, F, b, t, g)
        x = xs + 0.3 * rng.standard_normal(4) * (rng.random(4) < 0.5)
        x -= min(b @ x, 0.0) * b / (b @ b)                          # feasible
        mu = np.array([max(b @ np.linalg.solve(K, F), 0.0), 0.0]) + 0.3 * rng.standard_normal(2)
        d = certified_error(qp, x, mu)["degenerate"]
        applied += bool(np.isfinite(d))
        assert not d < rel_error(qp, x, xs) * (1 - 1e-9), seed
    assert applied > 50
