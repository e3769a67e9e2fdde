"""cvxpy plugin: backends, multiplier sign, honest status."""
from __future__ import annotations

import numpy as np
import pytest
from _lcp import enumerate_lcp

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import get_solver
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver, run

cp = pytest.importorskip("cvxpy")


@pytest.fixture(scope="module")
def f2():
    qp = load_scene("f2", {"N": 16, "delta": 1e-5}).build()
    x, mu, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    return qp, x, mu


@pytest.mark.parametrize("backend", ["CLARABEL", "SCS", "OSQP"])
def test_backends_and_multiplier_sign(f2, backend):
    if backend not in cp.installed_solvers():
        pytest.skip(f"{backend} not installed")
    qp, x_ref, mu_ref = f2
    solver = make_solver("cvxpy", {"solver": backend, "polish": False})
    sol = run(solver, qp)
    assert sol.status == Status.SOLVED, sol.message
    assert sol.info["backend"] == backend and sol.message.startswith(f"cvxpy/{backend}")
    # sign: contact forces >= 0 in compression and K x - F = B' mu
    assert (sol.multipliers > 0).sum() > 0
    assert np.all(sol.multipliers >= -1e-6 * np.abs(mu_ref).max())
    assert sol.residuals["stationarity"] < 1e-6
    d = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
    assert d["x_energy"] <= solver.tolerance
    assert d["multipliers"] < 1e-4
    # a flipped sign would make stationarity O(1): guard the test itself
    assert evaluator.residuals(qp, sol.x, -sol.multipliers)["stationarity"] > 1e-2


def test_declared_tolerance_follows_backend():
    assert make_solver("cvxpy", {"solver": "CLARABEL", "polish": False}).tolerance < \
        make_solver("cvxpy", {"solver": "SCS", "polish": False}).tolerance
    assert make_solver("cvxpy").tolerance == 1e-8


def test_polish_makes_clarabel_exact_at_small_delta():
    """Unpolished CLARABEL is ~1e-6 off at delta = 1e-9 (f2); the active-set polish is exact."""
    qp = load_scene("f2", {"N": 16, "delta": 1e-9}).build()
    x_ref, mu_ref, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    raw = run("cvxpy", qp, {"polish": False})
    pol = run("cvxpy", qp)
    assert pol.status == Status.SOLVED and pol.info["polish"]["applied"]
    e_raw = evaluator.compare(qp, raw.x, raw.multipliers, x_ref, mu_ref)["x_energy"]
    e_pol = evaluator.compare(qp, pol.x, pol.multipliers, x_ref, mu_ref)["x_energy"]
    assert e_pol < 1e-11 < e_raw
    assert e_pol <= make_solver("cvxpy").tolerance


def test_backend_name_is_case_insensitive_and_checked():
    assert make_solver("cvxpy", {"solver": "clarabel"}).params["solver"] == "CLARABEL"
    with pytest.raises(InputError, match="installed cvxpy backend"):
        make_solver("cvxpy", {"solver": "NO_SUCH_BACKEND"})


def test_iteration_cap_is_reported_honestly(f2):
    qp, _, _ = f2
    sol = run("cvxpy", qp, {"solver": "SCS", "max_iter": 2, "tol": 1e-12})
    assert sol.status != Status.SOLVED
    assert sol.status in (Status.MAX_ITER, Status.INACCURATE, Status.NUMERICAL_ERROR)
    assert sol.message


def test_tolerance_params():
    cls = get_solver("cvxpy")
    assert cls.tolerance_params(1e-7) == {"tol": 1e-8}      # the polish needs the backend at 1e-8 (measured)
    assert cls.tolerance_params(1e-9) == {"tol": 1e-9}
    cls(**cls.tolerance_params(1e-7))


def test_backend_output_does_not_reach_stdout(f2, capfd):
    qp, _, _ = f2
    if "OSQP" not in cp.installed_solvers():
        pytest.skip("OSQP not installed")
    run("cvxpy", load_scene("f3", {"N": 16, "delta": 1e-1}).build(), {"solver": "OSQP"})
    out, _ = capfd.readouterr()
    assert out == ""


def test_polish_refuses_an_inconsistent_guess():
    """f3 (faces open): guessing every node in contact gives negative forces -> no polish."""
    from dualfem.numerics.polish import active_set_polish

    qp = load_scene("f3", {"N": 16, "delta": 1e-1}).build()
    x_open, mu_open, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    assert active_set_polish(qp, np.zeros(qp.n), np.ones(qp.m)) is None
    x, mu, info = active_set_polish(qp, x_open, mu_open)
    assert info["n_active"] == 0 and np.all(mu == 0)
    assert evaluator.compare(qp, x, mu, x_open, mu_open)["x_energy"] < 1e-12
