"""The certificate at a weakly degenerate solution (rows closed and without force: strict complementarity fails),
dualfem/numerics/degenerate.py: an exact answer gets a rigorous bound at rounding through the face's exact point,
a perturbed one never a bound below its true error."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core.evaluator import size_energy
from dualfem.core.qp import QP
from dualfem.numerics.certify import active_set_check, certified_error


def degenerate_qp() -> tuple[QP, np.ndarray, np.ndarray]:
    """min 1/2 x'Kx - F'x s.t. x >= 0 with the exact solution x* = (0, 0, 1), mu* = (1, 0, 0): row 1 is closed and
    carries no force (K x* - F = 0 on it), row 0 is closed with force, row 2 open."""
    K = sp.csc_matrix(np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.5], [0.0, 0.5, 2.0]]))
    xs, ms = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    F = K @ xs - ms                                      # stationarity K x* - F - mu* = 0
    return QP(K=K, F=F, B=sp.identity(3, format="csr")), xs, ms


def rel_error(qp: QP, x: np.ndarray, xs: np.ndarray) -> float:
    """|x - x*|_K relative to the certificate's size of x (:func:`dualfem.core.evaluator.size_energy`)."""
    e = x - xs
    return float(np.sqrt(e @ (qp.K @ e)) / size_energy(qp, x))


def test_exact_degenerate_answer_is_certified_at_rounding():
    qp, xs, ms = degenerate_qp()
    assert np.isnan(active_set_check(qp, xs, ms)[0])     # the strict check cannot verify the set
    c = certified_error(qp, xs, ms)
    assert c["degenerate"] <= 1e-14 and c["value"] <= 1e-14
    assert np.isnan(c["multipliers"]) and "degenerate" in c["notes"]


def test_perturbed_answers_are_never_certified_below_their_error():
    # 300 answers off the solution by 1e-14 .. 1e-1 (x kept feasible), some entries exact: the degenerate rows'
    # bound, where it applies, holds the true error (without its rounding term eps |x|_K it fell below it 5e-5
    # of itself at errors ~1e-12)
    qp, xs, ms = degenerate_qp()
    applied = 0
    for seed in range(300):
        rng = np.random.default_rng(seed)
        s = 10.0 ** rng.uniform(-14, -1)
        x = np.maximum(xs + s * rng.standard_normal(3) * (rng.random(3) < 0.7), 0.0)
        mu = np.maximum(ms + s * rng.standard_normal(3) * (rng.random(3) < 0.7), 0.0)
        c = certified_error(qp, x, mu)
        if np.isfinite(c["degenerate"]):
            applied += 1
            assert c["degenerate"] >= rel_error(qp, x, xs), seed
    assert applied > 180


@pytest.mark.parametrize("x, mu", [([0.0, 0.0, 1e-8], [1.0, 0.0, 0.5]), (None, [0.0, 0.0, 0.0])],
                         ids=["open_row_claimed_closed", "unconstrained_minimiser"])
def test_wrong_face_gets_no_small_bound(x, mu):
    # the face point of a wrong set: an open row claimed closed pulls (a negative force, its n'D_AA n counted);
    # the unconstrained minimiser K^-1 F (no set) penetrates (no bound through it)
    qp, xs, ms = degenerate_qp()
    x = np.asarray(x if x is not None else np.linalg.solve(qp.K.toarray(), qp.F), float)
    c = certified_error(qp, x, np.asarray(mu, float))
    assert not c["degenerate"] < rel_error(qp, x, xs)
    assert not c["value"] < rel_error(qp, x, xs)


def _solve_small(K: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The exact solution of min 1/2 x'Kx - F'x s.t. x >= 0 (n <= 4): the set whose KKT point holds."""
    n = F.size
    for r in range(n + 1):
        for A in itertools.combinations(range(n), r):
            x = np.zeros(n)
            free = [i for i in range(n) if i not in A]
            if free:
                x[free] = np.linalg.solve(K[np.ix_(free, free)], F[free])
            if (x >= -1e-12).all() and (K @ x - F)[list(A)].min(initial=0.0) >= -1e-12:
                return x
    raise AssertionError("no KKT point")


def test_random_answers_of_random_qps_hold_their_error():
    # 200 random 4 x 4 Signorini QPs with answers off the solution by O(0.3) in some entries: the bound through the
    # face point never falls below the true error (without the face point's feasibility test it did, e.g. seeds
    # 195 and 280: the face of a wrong set penetrates a row off it, and its duality bound does not apply there)
    for seed in range(200):
        rng = np.random.default_rng(seed)
        M = rng.standard_normal((4, 4))
        K, F = M @ M.T + 0.3 * np.eye(4), rng.standard_normal(4)
        xs = _solve_small(K, F)
        qp = QP(K=sp.csc_matrix(K), F=F, B=sp.identity(4, format="csr"))
        x = np.maximum(xs + 0.3 * rng.standard_normal(4) * (rng.random(4) < 0.5), 0.0)
        mu = np.maximum(K @ xs - F + 0.3 * rng.standard_normal(4) * (rng.random(4) < 0.5), 0.0)
        d = certified_error(qp, x, mu)["degenerate"]
        assert not d < rel_error(qp, x, xs) * (1 - 1e-9), seed
