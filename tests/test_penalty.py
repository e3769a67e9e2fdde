"""Penalty solver: penetration reported, force as multiplier, continuation, scale awareness."""
from __future__ import annotations

import numpy as np
import pytest
from _lcp import enumerate_lcp

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.registry import get_solver
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver, run


@pytest.fixture(scope="module")
def f2():
    return load_scene("f2", {"N": 16, "delta": 1e-5}).build()


def test_declares_inexact():
    cls = get_solver("penalty")
    assert cls.exact is False
    assert cls.tolerance_params(1e-6)["tol"] < 1e-6


@pytest.mark.parametrize("delta", [1e-1, 1e-9])
def test_agrees_with_exact_and_reports_penetration(delta):
    qp = load_scene("f2", {"N": 16, "delta": delta}).build()
    sol = run("penalty", qp)
    assert sol.status == Status.SOLVED, sol.message
    x_ref, mu_ref, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    d = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
    assert d["x_energy"] <= get_solver("penalty").tolerance
    pen = sol.info["penetration"]
    assert pen == pytest.approx(max(0.0, -(qp.B @ sol.x).min()), rel=1e-3, abs=1e-30)
    assert sol.info["penetration_rel"] <= sol.params["tol"] * 1.0001
    # the multiplier estimate is the penalty force: >= 0, zero where the faces are open
    mu = sol.multipliers
    assert np.all(mu >= 0)
    gap = qp.B @ sol.x
    assert np.all(mu[gap > 0] == 0)
    # mu = rho w (-gap)^+ (computed stably on the active set; recomputing it from the rounded
    # x is meaningful only where the penetration is well above the rounding of x)
    if sol.info["penetration_rel"] > 1e-12:
        assert np.allclose(mu, sol.info["rho"] * qp.weights * np.maximum(-gap, 0), rtol=1e-3,
                           atol=1e-9 * mu.max())
    assert evaluator.residuals(qp, sol.x, mu)["stationarity"] < 1e-10


def test_continuation_raises_rho(f2):
    sol = run("penalty", f2)
    assert sol.info["rho"] > sol.info["rho0"]
    assert sol.iterations["continuation"] >= 2
    rhos = [h["rho"] for h in sol.history]
    assert rhos == sorted(rhos)


def test_rho0_is_scale_aware(f2):
    """Changing the force unit (K and F times 1e6) scales rho0 and leaves x unchanged."""
    s1 = make_solver("penalty")
    s1.setup(f2)
    big = QP(K=f2.K * 1e6, F=f2.F * 1e6, B=f2.B, weights=f2.weights, K_fixed=f2.K_fixed * 1e6,
             local_dofs=f2.local_dofs, maps=f2.maps)
    s2 = make_solver("penalty")
    s2.setup(big)
    assert s2.rho0 == pytest.approx(1e6 * s1.rho0, rel=1e-12)
    a, b = run("penalty", f2), run("penalty", big)
    assert b.status == Status.SOLVED
    assert evaluator.compare(f2, b.x, b.multipliers / 1e6, a.x, a.multipliers)["x_energy"] < 1e-9
    # order E/h: E = 69000, h = 1/16
    E, h = 69000.0, 1 / 16
    assert 0.1 * E / h < s1.rho0 < 100 * E / h


def test_rho_cap_gives_inaccurate_not_solved(f2):
    sol = run("penalty", f2, {"rho_max_factor": 1.0})
    assert sol.status == Status.INACCURATE
    assert "penetration" in sol.message
    assert sol.info["penetration_rel"] > sol.params["tol"]
    assert evaluator.residuals(f2, sol.x, sol.multipliers)["primal"] > 1e-10


def test_open_defect_needs_no_penalty():
    qp = load_scene("f3", {"N": 16, "delta": 1e-1}).build()
    sol = run("penalty", qp)
    assert sol.status == Status.SOLVED
    assert sol.iterations["continuation"] == 1 and np.all(sol.multipliers == 0)


@pytest.mark.parametrize("bad", [{"rho_growth": 1.0}, {"tol": 0}, {"sigma": 0.6}, {"rho0_factor": -1}])
def test_bad_parameters(bad):
    with pytest.raises(InputError):
        make_solver("penalty", bad)
