"""A bound for every frictional answer (dualfem.numerics.feasible_bound): a penetrating frictional answer where
the dense Delassus matrix is not formed (above faces.MAX_ROWS rows; the limit is monkeypatched to 0 here, so that
small scenes stand for the 400-crack body) gets the feasible correction's bound, which holds the true error
against a pdas reference; an answer with no bound at all is never ``solved`` on a frictional QP."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.evaluator import size_energy
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.experiments.runner import run
from dualfem.numerics import certify, faces
from dualfem.numerics.certify import certified_error
from dualfem.scene import load_scene
from dualfem.verify.judge import NO_FRICTION_BOUND

LAWS = {"tresca": {"friction": "tresca", "friction_bound": 5.0},
        "coulomb": {"friction": "coulomb", "friction_coefficient": 0.3}}


@pytest.fixture(scope="module", params=sorted(LAWS))
def solved(request):
    qp = load_scene("f2", {"N": 16, **LAWS[request.param]}).build()
    ref = run("pdas", qp)
    assert ref.status == Status.SOLVED and ref.info["certificate"]["value"] < 1e-12
    return qp, ref


@pytest.fixture
def no_dense_d(monkeypatch):
    """The scene behaves as one above the face step's row limit: no dense D, no face step, no dense bound."""
    monkeypatch.setattr(faces, "MAX_ROWS", 0)


def _true(qp, x, ref):
    """|x - x_ref|_K / size, less the reference's own certified error and rounding (the slack a bound needs)."""
    d = x - ref.x
    return float(np.sqrt(d @ (qp.K @ d))) / size_energy(qp, x) - ref.info["certificate"]["value"] - 1e-14


def _penetrating(qp, ref, size, rng):
    """The exact answer pushed through the contact row that carries the largest force, by ``size`` x |x|_inf,
    plus noise of a hundredth of that on every unknown."""
    xs, B = ref.x, qp.B.toarray()
    j = int(np.argmax(ref.multipliers[:qp.m]))
    scale = np.abs(xs).max()
    x = xs - size * scale * B[j] / (B[j] @ B[j]) + 1e-2 * size * scale * rng.standard_normal(qp.n)
    assert (qp.B @ x).min() < -0.5 * size * scale          # it penetrates beyond rounding
    return x


def test_penetrating_answer_gets_a_bound_that_holds_the_true_error(solved, no_dense_d):
    qp, ref = solved
    rng = np.random.default_rng(3)
    for size in (1e-10, 1e-8, 1e-6, 1e-4):
        x = _penetrating(qp, ref, size, rng)
        cert = certified_error(qp, x, ref.multipliers)
        assert np.isnan(cert["bound"]) and np.isnan(cert["active_set"])     # only the correction applies
        true = _true(qp, x, ref)
        assert np.isfinite(cert["infeasible"]) and cert["value"] == cert["infeasible"]
        assert cert["value"] >= true, (size, cert, true)
        assert cert["value"] < 100 * true + 1e-12                             # and not vacuous


def test_bound_holds_with_inexact_multipliers_too(no_dense_d):
    """Tresca (convex: its solution is the reference whatever mu): x and mu both off, x penetrating."""
    qp = load_scene("f2", {"N": 16, **LAWS["tresca"]}).build()
    ref = run("pdas", qp)
    rng = np.random.default_rng(4)
    for size in (1e-8, 1e-5, 1e-3):
        x = _penetrating(qp, ref, size, rng)
        mu = ref.multipliers * (1 + size * rng.standard_normal(qp.m_total))
        cert = certified_error(qp, x, mu)
        true = _true(qp, x, ref)
        assert np.isfinite(cert["value"]) and cert["value"] >= true, (size, cert, true)


def test_dense_and_correction_bounds_agree_where_both_exist(solved):
    qp, ref = solved
    x = _penetrating(qp, ref, 1e-6, np.random.default_rng(5))
    dense = certified_error(qp, x, ref.multipliers)["infeasible"]
    faces_rows = faces.MAX_ROWS
    try:
        faces.MAX_ROWS = 0
        corr = certified_error(qp, x, ref.multipliers)["infeasible"]
    finally:
        faces.MAX_ROWS = faces_rows
    assert np.isfinite(dense) and np.isfinite(corr) and corr <= 2 * dense


def _hostile(register, x, mu):
    @register
    class Penetrates(Solver):
        name = "hostile_penetrating_friction"
        accepts = ("signorini", "tresca", "coulomb")
        defaults = {"tol": 1e-8}

        def solve(self):
            return Solution(solver=self.name, status=Status.SOLVED, x=x.copy(), multipliers=mu.copy())


def test_hostile_penetrating_answer_is_never_solved_without_a_bound(solved, no_dense_d, register):
    """Residuals within the declared 1e-8 (penetration 1e-10 of |x|): before the correction's bound this answer
    had no bound and was ``solved`` on its residuals; now it is ``solved`` only with a bound <= tol that holds."""
    qp, ref = solved
    x = _penetrating(qp, ref, 1e-10, np.random.default_rng(6))
    _hostile(register, x, ref.multipliers)
    sol = run("hostile_penetrating_friction", qp)
    cert = sol.info["certificate"]
    assert sol.claim == "solved" and max(sol.residuals[k] for k in ("stationarity", "primal")) < 1e-8
    assert np.isfinite(cert["value"]) and cert["value"] >= _true(qp, x, ref) * (1 - 1e-9), cert
    assert sol.status == (Status.SOLVED if cert["value"] <= 1e-8 else Status.INACCURATE), sol.message


def test_frictional_answer_without_any_bound_is_never_solved(solved, no_dense_d, register, monkeypatch):
    """Where no bound can be had (here: the correction switched off), the exact solver's claim is demoted and the
    certificate's notes say why (a Signorini answer without a bound stands on its residuals; a frictional one not)."""
    qp, ref = solved
    monkeypatch.setattr(certify, "correction_bound", lambda *a, **k: float("nan"))
    x = _penetrating(qp, ref, 1e-10, np.random.default_rng(7))
    _hostile(register, x, ref.multipliers)
    sol = run("hostile_penetrating_friction", qp)
    assert np.isnan(sol.info["certificate"]["value"])
    assert sol.status == Status.INACCURATE and NO_FRICTION_BOUND in sol.info["certificate"]["notes"], sol.message


def test_bound_stays_near_the_error_of_an_iterative_answer(no_dense_d):
    """An answer as an iterative dual method leaves it (uzawa): x penetrates a little, a sticking node slips a
    little, the slipping nodes' forces are a little off their radius. The support term of such an answer is first
    order in those defects and enters under a square root (the dense bound's 1.8e-5 for a true error of 1.4e-8 on
    50 cracks); the face correction (contact rows and sticking nodes held closed) and the slipping nodes' forces set
    onto their radius keep the bound within a small factor of the true error."""
    qp = load_scene("f2", {"N": 16, **LAWS["coulomb"]}).build()
    ref = run("pdas", qp)
    b = qp.blocks[0]
    lam, mu_t = ref.multipliers[:qp.m], ref.multipliers[qp.m:]
    r = b.law.radius(b.weights, (lam, mu_t))
    stick = np.flatnonzero((np.abs(mu_t) < 0.99 * r) & (r > 0))
    slip = np.flatnonzero(np.abs(mu_t) >= (1 - 1e-12) * r)
    assert stick.size and slip.size
    T, B = b.G.toarray(), qp.B.toarray()
    scale, size = np.abs(ref.x).max(), 1e-9
    j, k = stick[0], int(np.argmax(lam))
    x = ref.x + size * scale * (T[j] / (T[j] @ T[j]) - B[k] / (B[k] @ B[k]))
    mu = ref.multipliers.copy()
    mu[qp.m + slip] *= 1 - 1e-9
    cert = certified_error(qp, x, mu)
    true = _true(qp, x, ref)
    assert np.isnan(cert["bound"]) and cert["value"] >= true
    assert cert["value"] < 10 * (true + ref.info["certificate"]["value"]), (cert, true)


def test_frictionless_penetrating_answer_without_dense_d_gets_the_correction_bound(monkeypatch):
    """A Signorini answer above the Delassus matrix's size (delassus() None, as at scale) that penetrates beyond
    rounding had no bound (it stood on its residuals); the feasible correction bounds it, and the bound holds."""
    qp = load_scene("f2", {"N": 16}).build()
    ref = run("pdas", qp)
    assert ref.status == Status.SOLVED and not qp.blocks
    monkeypatch.setattr(certify.KSolver, "delassus", lambda self: None)
    rng = np.random.default_rng(6)
    for size in (1e-10, 1e-7, 1e-4):
        x = _penetrating(qp, ref, size, rng)
        cert = certified_error(qp, x, ref.multipliers)
        assert np.isnan(cert["bound"])
        true = _true(qp, x, ref)
        assert np.isfinite(cert["value"]) and cert["value"] >= true, (size, cert, true)
        assert cert["value"] < 100 * true + 1e-12
