"""The toy bilateral law (a test plugin: law_bilateral.py, qp_glued.py, this file) through the whole runner.

Every registered solver that lists ``"bilateral"`` in ``accepts`` solves the glued QP (checked against an
independent solve: scipy's sparse LU of the KKT system on the exact active set, found by a primal-dual
active-set iteration written here); every other one is ``skipped`` with the reason, never run on it.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from law_bilateral import Bilateral
from qp_glued import glued_qp

from dualfem import evaluator
from dualfem.errors import InputError
from dualfem.laws import Constraint
from dualfem.qp import QP
from dualfem.registry import solvers
from dualfem.runner import run
from dualfem.solution import Status


def kkt_reference(qp: QP) -> tuple[np.ndarray, np.ndarray]:
    """(x, mu) of ``min 1/2 x'Kx - F'x, B x >= 0, G_glued x = 0`` by scipy alone: the Signorini rows in the
    set A = {mu - c gap > 0} and every glued row held as equalities, A updated until it repeats."""
    B, G = qp.B, qp.blocks[0].G
    A = np.ones(qp.m, bool)
    for _ in range(50):
        E = sp.vstack([B[A], G], format="csc")
        kkt = sp.bmat([[qp.K, E.T], [E, None]], format="csc")
        sol = sla.splu(kkt).solve(np.r_[qp.F, np.zeros(E.shape[0])])
        x, lam = sol[:qp.n], -sol[qp.n:]
        mu = np.zeros(qp.m)
        mu[A] = lam[:A.sum()]
        new = mu - (B @ x) > 0
        if np.array_equal(new, A):
            return x, np.r_[mu, lam[A.sum():]]
        A = new
    raise AssertionError("the reference active-set iteration did not settle")


@pytest.fixture(scope="module")
def glued():
    qp = glued_qp()
    return qp, kkt_reference(qp)


def test_reference_is_a_kkt_point_of_both_laws(glued):
    qp, (x, mu) = glued
    res = evaluator.residuals(qp, x, mu)
    assert evaluator.kkt_error(res) < 1e-12
    assert mu[qp.m:].min() < 0 < mu[:qp.m].max()      # glued rows pull (tension): not a Signorini answer
    # the same (x, mu) read as if every row were Signorini is not a solution: the law decides
    assert evaluator.residuals(QP(K=qp.K, F=qp.F, B=qp.G, weights=np.ones(qp.m_total)), x, mu)["dual"] > 1e-3


@pytest.mark.parametrize("name", sorted(solvers()))
def test_every_solver_solves_or_is_skipped(glued, name):
    qp, (x_ref, mu_ref) = glued
    cls = solvers()[name]
    if cls.missing():
        pytest.skip(f"{name} is not installed")
    sol = run(name, qp)
    if "bilateral" in cls.accepts:
        assert sol.status == Status.SOLVED, sol.message
        cmp = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
        assert cmp["x_energy"] < cls.tolerance and cmp["multipliers"] < 10 * cls.tolerance, cmp
        # the certificate's face step on both laws measures the true error (the bound is only sqrt-tight)
        assert sol.info["certificate"]["active_set"] < 10 * cmp["x_energy"] + 1e-12, sol.info["certificate"]
    else:
        assert sol.status == Status.SKIPPED
        assert "does not handle the 'bilateral' law" in sol.message and name in sol.message


def test_an_instance_narrows_what_it_accepts(glued):
    qp, _ = glued
    if solvers()["cvxpy"].missing():
        pytest.skip("cvxpy is not installed")
    sol = run("cvxpy", qp, {"solver": "ECOS"})        # untested backend: Signorini only
    assert sol.status == Status.SKIPPED and "does not handle the 'bilateral' law" in sol.message


def test_fully_glued_crack_has_no_signorini_rows():
    qp = glued_qp(signorini=False)
    assert qp.m == 0 and qp.m_total == qp.blocks[0].m
    kkt = sp.bmat([[qp.K, qp.G.T], [qp.G, None]], format="csc")
    sol = sla.splu(kkt).solve(np.r_[qp.F, np.zeros(qp.m_total)])
    out = run("clarabel", qp)
    assert out.status == Status.SOLVED, out.message
    assert evaluator.compare(qp, out.x, out.multipliers, sol[:qp.n], -sol[qp.n:])["x_energy"] < 1e-5


def test_a_block_without_a_file_format_is_not_exported(glued, tmp_path):
    qp, _ = glued
    with pytest.raises(InputError, match="bilateral"):
        qp.save(tmp_path / "glued.npz")
    with pytest.raises(InputError, match="columns"):
        Constraint.make(qp.B[:, :-1], None, Bilateral()).validate(qp.n)
