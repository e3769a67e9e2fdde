"""The evaluator trusts no solver: it must flag perturbed answers."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.experiments.runner import run


@pytest.fixture
def solved(scene):
    _, qp = scene("f2", 16, 1e-5)
    sol = run("clarabel", qp)
    assert sol.ok
    return qp, sol


def test_exact_solution_has_small_residuals(solved):
    qp, sol = solved
    res = evaluator.residuals(qp, sol.x, sol.multipliers)
    assert evaluator.kkt_error(res) < 1e-8
    assert 0 < evaluator.contact_set(qp, sol.x).sum() < qp.m  # f2: partial contact


def test_perturbed_x_is_caught(solved):
    qp, sol = solved
    x = sol.x.copy()
    x[np.argmax(np.abs(x))] *= 1.001
    assert evaluator.residuals(qp, x, sol.multipliers)["stationarity"] > 1e-4


def test_penetration_is_caught(solved):
    qp, sol = solved
    nd, up = qp.geometry.node_dofs, qp.interface.upper
    x = sol.x.copy()
    j = int(np.flatnonzero(evaluator.contact_set(qp, sol.x))[0])
    x[nd[1, up[j]]] -= 1e-3 * np.abs(x).max()
    res = evaluator.residuals(qp, x, sol.multipliers)
    assert res["primal"] >= 1e-3 * 0.99


def test_negative_multiplier_and_complementarity_are_caught(solved):
    qp, sol = solved
    mu = sol.multipliers.copy()
    open_ = np.flatnonzero(~evaluator.contact_set(qp, sol.x))
    mu[open_[0]] = -0.1 * np.abs(mu).max()
    res = evaluator.residuals(qp, sol.x, mu)
    assert res["dual"] > 1e-3 and res["stationarity"] > 1e-3
    mu = sol.multipliers.copy()
    mu[open_[-1]] = 0.1 * np.abs(mu).max()           # force on an open node
    assert evaluator.residuals(qp, sol.x, mu)["complementarity"] > 1e-4


def test_nan_is_caught(solved):
    qp, sol = solved
    x = sol.x.copy()
    x[0] = np.nan
    res = evaluator.residuals(qp, x, sol.multipliers)
    assert not res["finite"] and np.isnan(evaluator.kkt_error(res))


def test_compare(solved):
    qp, sol = solved
    d0 = evaluator.compare(qp, sol.x, sol.multipliers, sol.x, sol.multipliers)
    assert d0["x_energy"] == 0 and d0["contact_mismatch"] == 0
    d = evaluator.compare(qp, 1.01 * sol.x, sol.multipliers, sol.x, sol.multipliers)
    assert d["x_energy"] == pytest.approx(0.01, rel=1e-9) and d["x_max"] == pytest.approx(0.01, rel=1e-9)


def test_residuals_are_scale_free(solved):
    """Same answer in other units (forces x 1e6, lengths x 1e-3) -> same residuals."""
    qp, sol = solved
    from dualfem.core.qp import QP

    a, b = 1e6, 1e-3  # force and length scale factors: K ~ force/length
    qp2 = QP(K=qp.K * (a / b), F=qp.F * a, B=qp.B, weights=qp.weights * b)
    x = sol.x * (1 + 1e-3 * np.cos(np.arange(qp.n)))        # residuals well above round-off
    mu = sol.multipliers - 1e-3 * np.abs(sol.multipliers).max()
    r1 = evaluator.residuals(qp, x, mu)
    r2 = evaluator.residuals(qp2, x * b, mu * a)
    assert min(r1[k] for k in ("stationarity", "dual", "complementarity")) > 1e-9
    for k in ("stationarity", "primal", "dual", "complementarity"):
        assert r2[k] == pytest.approx(r1[k], rel=1e-6, abs=1e-18)
