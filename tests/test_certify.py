"""The a-posteriori certificate: one solve, the same numbers as the explicit refinement step, valid bounds."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from dualfem.core import certify
from dualfem.core.certify import KSolver, certified_error, refinement_step
from dualfem.numerics import linalg


def _exact(qp):
    """The exact (x, mu) by the active-set solver pdas at its tightest tolerance."""
    from dualfem.core.runner import run

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


def test_certificate_counts_one_solve(scene, monkeypatch):
    """The certificate costs one solve with the cached factorization, not seven."""
    _, qp = scene("f2", 16, 1e-5)
    x, mu = _exact(qp)
    ks = KSolver(qp)
    calls = []
    orig = ks.red.factor.solve
    monkeypatch.setattr(ks.red.factor, "solve", lambda b: calls.append(1) or orig(b))
    certify.certified_error(qp, x, mu, ks)
    assert len(calls) == 1
