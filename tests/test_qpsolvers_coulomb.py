"""2D Coulomb friction through the qpsolvers backends (solvers/qpsolvers_.py): the fixed point of
dualfem.numerics.coulomb over each backend's Tresca solves (the linear epigraph of the boxes), as clarabel, cvxpy
and osqp do. Every installed qp_ backend that takes Tresca agrees with pdas's monolithic Coulomb answer to 1e-6
and is certified, reports its fixed-point count and contraction, and a fixed point that stalls or runs out of
iterations is never ``solved``; 3D discs stay skipped with the reason."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.registry import solvers
from dualfem.core.solution import Status
from dualfem.experiments.runner import run
from dualfem.scene import load_scene
from dualfem.solvers.qpsolvers_ import BILATERAL, NEEDS_DEFINITE_P

COULOMB = {"friction": "coulomb", "friction_coefficient": 0.3}


@pytest.fixture(scope="module")
def coulomb():
    qp = load_scene("f2", {"N": 16, **COULOMB}).build()
    ref = run("pdas", qp)
    assert ref.status == Status.SOLVED
    return qp, ref


def _installed(name):
    cls = solvers().get(name)
    if cls is None or cls.missing():
        pytest.skip(f"{name} is not installed: {cls.missing() if cls else 'no such solver'}")
    return cls


@pytest.mark.parametrize("backend", BILATERAL)
def test_every_qp_backend_solves_2d_coulomb_like_pdas(coulomb, backend):
    qp, ref = coulomb
    cls = _installed(f"qp_{backend}")
    assert "coulomb" in cls.accepts
    sol = run(cls.name, qp, cls.tolerance_params(1e-6))
    if backend in NEEDS_DEFINITE_P:
        assert sol.status == Status.SKIPPED and "positive definite" in sol.message
        return
    assert sol.status == Status.SOLVED, sol.message
    assert sol.info["certificate"]["value"] <= 1e-6
    rel = np.abs(sol.x - ref.x).max() / np.abs(ref.x).max()
    assert rel < 1e-6, rel
    assert np.abs(sol.multipliers - ref.multipliers).max() < 1e-6 * np.abs(ref.multipliers).max()
    assert sol.iterations["coulomb"] >= 2 and "Coulomb fixed point" in sol.message
    assert 0 <= sol.info["coulomb"]["contraction"] < 1 and not sol.info["coulomb"]["stalled"]


def test_the_fixed_point_is_not_a_frictionless_answer(coulomb):
    """The fixed point really iterates: one Tresca solve (the frictionless start) is not the Coulomb answer."""
    qp, ref = coulomb
    _installed("qp_proxqp")
    one = run("qp_proxqp", qp, {"coulomb_max_iter": 1})
    assert one.claim == "max_iter" and one.status == Status.MAX_ITER and one.iterations["coulomb"] == 1
    assert "max_iter = 1 reached" in one.message
    assert np.abs(one.x - ref.x).max() > 1e-4 * np.abs(ref.x).max()


def test_a_stalled_fixed_point_is_never_solved(coulomb):
    """A relative change of 1e-16 is below the threshold's rounding: the change stops falling and the loop stops
    as stalled, with the last Tresca answer and status max_iter."""
    qp, _ = coulomb
    _installed("qp_proxqp")
    sol = run("qp_proxqp", qp, {"coulomb_tol": 1e-16, "coulomb_max_iter": 200})
    assert sol.claim == "max_iter" and sol.status == Status.MAX_ITER, sol.message
    assert sol.info["coulomb"]["stalled"] and "stalled" in sol.message
    assert sol.iterations["coulomb"] < 200 and sol.x is not None


def test_3d_coulomb_discs_are_skipped_with_the_reason():
    _installed("qp_proxqp")
    qp = load_scene("three_d", {"N": 4, **COULOMB}).build()
    sol = run("qp_proxqp", qp)
    assert sol.status == Status.SKIPPED and "second-order cones" in sol.message
