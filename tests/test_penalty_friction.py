"""Penalty with regularized friction (solvers/penalty.py + dualfem.numerics.friction_penalty): Tresca certified and
equal to the conic reference and to uzawa_auto, Coulomb through the fixed point (counters reported), mu_f = 0 the
frictionless answer, the polish needed for certified multipliers (without it the forces are rho x rounded slips)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.experiments.runner import run
from dualfem.problems._friction import with_friction

pytest.importorskip("gmsh")
pytest.importorskip("cvxpy")
from _tresca_ref import tresca_reference  # noqa: E402
from test_uzawa_friction import _rel, crack, raw  # noqa: E402


@pytest.mark.parametrize("dim,params", [(2, {}), (3, {}), (2, {"operator": "matrix_free"})])
def test_tresca_certified_and_equal_to_the_conic_solve(dim, params):
    qp = with_friction(crack(dim), "tresca", 0.1)
    sol = run("penalty", qp, params)
    assert sol.status == "solved" and sol.claim == "solved", (sol.message, sol.verdict.why)
    x, mu, _ = tresca_reference(qp)
    assert _rel(sol.x, x) < 1e-5 and _rel(sol.multipliers, mu) < 1e-4
    assert sol.iterations["continuation"] >= 2 and sol.info["penetration"] >= 0


@pytest.mark.parametrize("dim", [2, 3])
def test_coulomb_by_the_fixed_point_equals_uzawa(dim):
    qp = with_friction(crack(dim), "coulomb", 0.2)
    sol, ref = run("penalty", qp), raw("uzawa_auto", qp)
    assert sol.status == "solved", (sol.message, sol.verdict.why)
    assert _rel(sol.x, ref.x) < 1e-8 and _rel(sol.multipliers, ref.multipliers) < 1e-7
    assert 2 <= sol.iterations["coulomb_iterations"] <= 20 and sol.iterations["coulomb_stalled"] == 0
    capped = raw("penalty", qp, coulomb_max_iter=1)
    assert capped.status == "max_iter"


def test_zero_friction_is_the_frictionless_answer():
    base = raw("penalty", crack(2))
    sol = raw("penalty", with_friction(crack(2), "tresca", 0.0))
    assert sol.status == "solved" and _rel(sol.x, base.x) < 1e-12                 # measured 4e-16
    assert _rel(sol.multipliers[:crack(2).m], base.multipliers) < 1e-12
    assert np.abs(sol.multipliers[crack(2).m:]).max() == 0.0


def test_without_the_polish_the_forces_are_not_certified(monkeypatch):
    import dualfem.numerics.friction_penalty as fp

    monkeypatch.setattr(fp, "polish", lambda *a, **k: None)
    sol = run("penalty", with_friction(crack(2), "tresca", 0.1))
    assert sol.claim == "solved" and sol.status == "inaccurate"


def test_a_stuck_crack_is_solved_and_sticks():
    """g = 0.5 > tau = 0.3: every node sticks; each continuation stage starts from the predictor (forces kept,
    creep shrunk), else the warm start sees every node slip at the new rho and Newton crawls (measured: max_iter)."""
    qp = with_friction(crack(2), "tresca", 0.5)
    sol = run("penalty", qp)
    assert sol.status == "solved", (sol.message, sol.verdict.why)
    slip = np.abs(qp.blocks[0].G @ sol.x).max()
    assert slip <= 1e-10 * np.abs(sol.x).max() and sol.iterations["newton"] <= 30
