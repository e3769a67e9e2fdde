"""The a-posteriori certificate: one solve, the same numbers as the explicit refinement step, valid bounds."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from dualfem.numerics import certify, linalg
from dualfem.numerics.certify import KSolver, certified_error, refinement_step


def _exact(qp):
    """The exact (x, mu) by the active-set solver pdas at its tightest tolerance."""
    from dualfem.experiments.runner import run

    sol = run("pdas", qp, {"tol": 1e-13})
    return sol.x, sol.multipliers


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9), ("f3", 1e-1)])
def test_k_quad_is_one_solve_of_the_whole_K(scene, name, delta):
    _, qp = scene(name, 16, delta)
    red = linalg.LocalReduction(qp)
    r = np.random.default_rng(1).standard_normal(qp.n)
    z = sla.spsolve(qp.K.tocsc(), r)
    q, zI = red.k_quad(r)
    assert q == pytest.approx(float(r @ z), rel=1e-10)
    assert np.abs(zI - z[red.I]).max() <= 1e-10 * np.abs(z).max()


def _explicit_active_set_error(qp, x, mu, margin=10.0):
    """The certificate's active-set part computed the long way (full dx from refinement_step)."""
    ks = KSolver(qp)
    A = mu > 0
    dx, dmu = refinement_step(qp, ks, ks.delassus(), x, mu, A)
    gap1, mu1 = qp.B @ (x + dx), mu + dmu
    if A.any() and mu1[A].min() <= margin * np.abs(dmu).max():
        return float("nan")
    if (~A).any() and gap1[~A].min() <= margin * np.abs(qp.B @ dx).max():
        return float("nan")
    return float(np.sqrt(dx @ (qp.K @ dx)) / np.sqrt(x @ (qp.K @ x)))


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9)])
def test_certificate_matches_the_explicit_refinement_and_bounds_the_error(scene, name, delta):
    _, qp = scene(name, 16, delta)
    x, mu = _exact(qp)
    rng = np.random.default_rng(2)
    for eps in (1e-8, 1e-5):
        # a perturbed answer: keep it feasible (jumps >= 0) so that the duality bound applies
        xp = x + eps * np.abs(x).max() * rng.standard_normal(qp.n)
        BBt = np.asarray((qp.B @ qp.B.T).diagonal())       # the rows of B touch disjoint unknowns
        xp = xp + qp.B.T @ (np.maximum(-(qp.B @ xp), 0.0) / BBt)
        assert (qp.B @ xp).min() >= -1e-14 * np.abs(xp).max()
        mup = mu * (1 + eps * rng.standard_normal(mu.size))
        cert = certified_error(qp, xp, mup)
        explicit = _explicit_active_set_error(qp, xp, mup)
        assert (np.isnan(explicit) and np.isnan(cert["active_set"])) or \
            cert["active_set"] == pytest.approx(explicit, rel=1e-6)
        err = np.sqrt((xp - x) @ (qp.K @ (xp - x)) / (xp @ (qp.K @ xp)))
        assert cert["bound"] >= err * (1 - 1e-6)                       # a bound, never an underestimate
        assert np.isfinite(cert["value"]) and cert["value"] <= 10 * err + 1e-12


def test_certificate_without_local_structure_agrees(scene, monkeypatch):
    """Without a usable local reduction (a third-party QP) the plain sparse path gives the same certificate."""
    _, qp = scene("f2", 16, 1e-5)
    x, mu = _exact(qp)
    xp = x * (1 + 1e-6)
    a = certified_error(qp, xp, mu)

    def no_structure(*args, **kwargs):
        raise ValueError("no local structure")

    monkeypatch.setattr(linalg, "LocalReduction", no_structure)
    assert KSolver(qp).red is None
    b = certified_error(qp, xp, mu)
    for k in ("bound", "active_set"):
        assert a[k] == pytest.approx(b[k], rel=1e-6)


def _count_solves(monkeypatch, ff) -> list[str]:
    """Record every solve with the cached factorization ``ff``: "solve", "forward", "backward" (halves)."""
    calls: list[str] = []
    for kind in ("solve", "forward", "backward"):
        orig = getattr(ff, kind)
        monkeypatch.setattr(ff, kind, lambda *a, _o=orig, _k=kind: calls.append(_k) or _o(*a))
    return calls


def test_certificate_counts_one_solve(scene, monkeypatch):
    """The certificate costs the forward half of one solve with the cached factorization, not seven solves."""
    _, qp = scene("f2", 16, 1e-5)
    x, mu = _exact(qp)
    ks = KSolver(qp)
    calls = _count_solves(monkeypatch, ks.red.factor)
    certify.certified_error(qp, x, mu, ks)
    assert calls == ["forward"]


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9)])
def test_reduced_refinement_step_equals_the_full_space_step(scene, name, delta, monkeypatch):
    """LocalReduction.refine (the two halves of one solve) takes the same step as refinement_step (four solves)."""
    _, qp = scene(name, 16, delta)
    x, mu = _exact(qp)
    rng = np.random.default_rng(3)
    xp = x + 1e-6 * np.abs(x).max() * rng.standard_normal(qp.n)
    mup = mu * (1 + 1e-6 * rng.standard_normal(mu.size))
    red = linalg.LocalReduction(qp)
    A = mup > 0
    dx, dmu = refinement_step(qp, red.k_solve, red.delassus(), xp, mup, A)
    calls = _count_solves(monkeypatch, red.factor)
    x1, mu1 = red.refine(xp, mup, A)
    assert calls == ["forward", "backward"]
    # the same step to six digits (rounding of the ill-conditioned D at delta = 1e-9 is ~1e-12 of mu)
    assert np.abs(x1 - (xp + dx)).max() <= 1e-6 * np.abs(dx).max() + 1e-12 * np.abs(xp).max()
    assert np.abs(mu1 - (mup + dmu)).max() <= 1e-6 * np.abs(dmu).max() + 1e-12 * np.abs(mup).max()


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9)])
def test_refine_skips_a_step_smaller_than_asked_and_the_certificate_reuses_its_solve(scene, name, delta,
                                                                                   monkeypatch):
    """refine(skip_below=) computes the exact step size after the forward half of a solve; a step below
    it is not taken (None), and certifying the unchanged x costs no further solve (remembered)."""
    _, qp = scene(name, 16, delta)
    x, mu = _exact(qp)
    rng = np.random.default_rng(5)
    xp = x + 1e-9 * np.abs(x).max() * rng.standard_normal(qp.n)
    A = mu > 0
    step = linalg.LocalReduction(qp).refine(xp, mu, A)      # the full step, for its size
    assert step is not None
    dx = step[0] - xp
    size = np.sqrt(dx @ (qp.K @ dx)) / np.sqrt(xp @ (qp.K @ xp))
    red = linalg.LocalReduction(qp)
    calls = _count_solves(monkeypatch, red.factor)
    assert red.refine(xp, mu, A, skip_below=2.0 * size) is None and calls == ["forward"]
    cert = certify.certified_error(qp, xp, mu, certify.KSolver(qp, reduction=red))
    assert calls == ["forward"]                           # the certificate's half was the skipped step's
    assert cert["value"] == pytest.approx(size, rel=1e-3)
    x1, _ = red.refine(xp, mu, A, skip_below=0.5 * size)   # taken: only its backward half is new
    assert calls == ["forward", "backward"] and np.array_equal(x1, step[0])


def test_runner_certifies_with_the_solvers_own_reduction_only_if_it_is_of_this_qp(scene, monkeypatch):
    """Certification reuses ``Solver.reduction`` (no second reduction) but never one of another QP."""
    from dualfem.experiments import runner

    _, qp = scene("f2", 16, 1e-5)
    _, other = scene("f2", 16, 1e-3)
    built = []
    orig = linalg.LocalReduction.__init__

    def counting(self, *a, **k):
        built.append(1)
        orig(self, *a, **k)

    monkeypatch.setattr(linalg.LocalReduction, "__init__", counting)
    sol = runner.run("pdas", qp)
    assert sol.status == "solved" and len(built) == 1            # the solver's own, reused by certify
    solver = runner.make_solver("pdas")
    solver.setup(qp)
    sol = solver.solve()
    runner.attach_residuals(qp, sol)
    built.clear()
    runner.certify_status(qp, sol, solver.tolerance, True, reduction=linalg.LocalReduction(other))
    assert len(built) == 2                                       # the foreign one, then a fresh one of qp
    assert sol.status == "solved" and sol.info["certificate"]["value"] < 1e-9


@pytest.mark.parametrize("solver", ["clarabel", "osqp"])
@pytest.mark.parametrize("name, delta", [("f1", 1e-5), ("f2", 1e-5), ("f3", 1e-1)])
def test_active_set_certificate_measures_the_error_of_interior_point_and_admm_answers(scene, solver, name, delta):
    """The primal-dual rule guesses the active set of an answer with mu > 0 everywhere (an IPM's):
    the verified estimate is the true error (to 10 %), where the duality bound is orders above it."""
    from dualfem.experiments.runner import run

    _, qp = scene(name, 16, delta)
    x, _ = _exact(qp)
    sol = run(solver, qp, {"polish": False} if solver == "clarabel" else {})
    err = np.sqrt((sol.x - x) @ (qp.K @ (sol.x - x)) / (x @ (qp.K @ x)))
    cert = certified_error(qp, sol.x, sol.multipliers)
    assert cert["active_set"] == pytest.approx(err, rel=0.1, abs=1e-13)
    assert cert["bound"] >= err * (1 - 1e-6) - 1e-13         # (the reference itself is exact to ~1e-14)


def test_active_set_certificate_never_vouches_for_a_wrong_contact_set(scene):
    """Open a closed node (or close an open one) by a visible amount: the estimate is either nan or the
    true error (to 10 %), never a small number for a far-off answer."""
    _, qp = scene("f2", 16, 1e-5)
    x, mu = _exact(qp)
    rng = np.random.default_rng(4)
    for _ in range(20):
        j = rng.integers(qp.m)
        mup = mu.copy()
        mup[j] = 0.0 if mu[j] > 0 else np.abs(mu).max()
        xp = x + 1e-3 * np.abs(x).max() * rng.standard_normal(qp.n)
        err = np.sqrt((xp - x) @ (qp.K @ (xp - x)) / (x @ (qp.K @ x)))
        a = certified_error(qp, xp, mup)["active_set"]
        assert np.isnan(a) or a == pytest.approx(err, rel=0.1)
