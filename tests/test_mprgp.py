"""mprgp: MPRGP on the reduced contact dual (solvers/mprgp.py).

Exact: agrees with pdas to 1e-8 (relative energy norm of x) at every delta, with both operators;
zero load gives mu = 0; the answer is scale-free (load x 1e-8 and x 1e8).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver, run

_QP: dict = {}


def qp_for(load: str, delta: float, N: int = 16):
    key = (load, delta, N)
    if key not in _QP:
        _QP[key] = load_scene(load, {"N": N, "delta": delta}).build()
    return _QP[key]


@pytest.mark.parametrize("operator", ["dense", "matrix_free"])
@pytest.mark.parametrize("delta", [1e-1, 1e-5, 1e-9])
@pytest.mark.parametrize("load", ["f1", "f2", "f3"])
def test_agrees_with_pdas(load, delta, operator):
    qp = qp_for(load, delta)
    ref = run("pdas", qp)
    sol = run("mprgp", qp, {"operator": operator})
    assert ref.ok and sol.status == Status.SOLVED, sol.message
    d = evaluator.compare(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)
    assert d["x_energy"] <= 1e-8 and d["contact_mismatch"] == 0, d
    assert np.all(sol.multipliers >= 0)
    assert evaluator.kkt_error(sol.residuals) <= 1e-9
    assert set(sol.iterations) == {"cg", "expansion", "proportioning"}
    assert sol.info["operator"] == operator


def test_iterations_are_counted_on_a_contact_scene():
    sol = run("mprgp", qp_for("f2", 1e-5, 32))
    assert sol.ok and sol.iterations["cg"] > 0 and sol.iterations["proportioning"] > 0
    assert sol.multipliers.max() > 0


@pytest.mark.parametrize("operator", ["dense", "matrix_free"])
def test_zero_load_gives_zero_forces(operator):
    qp = dataclasses.replace(qp_for("f2", 1e-5), F=np.zeros(qp_for("f2", 1e-5).n))
    sol = run("mprgp", qp, {"operator": operator})
    assert sol.status == Status.SOLVED
    assert np.all(sol.multipliers == 0) and np.allclose(sol.x, 0.0)
    assert sum(sol.iterations.values()) == 0


@pytest.mark.parametrize("factor", [1e-8, 1e8])
@pytest.mark.parametrize("operator", ["dense", "matrix_free"])
def test_scale_invariance(factor, operator):
    """Load x factor: x and mu scale by the factor, the status does not change."""
    qp = qp_for("f2", 1e-5)
    base = run("mprgp", qp, {"operator": operator})
    scaled = run("mprgp", dataclasses.replace(qp, F=qp.F * factor), {"operator": operator})
    assert base.status == scaled.status == Status.SOLVED
    assert np.abs(scaled.x / factor - base.x).max() <= 1e-10 * np.abs(base.x).max()
    assert np.abs(scaled.multipliers / factor - base.multipliers).max() <= 1e-10 * np.abs(base.multipliers).max()


def test_iteration_cap_is_an_honest_failure():
    sol = run("mprgp", qp_for("f1", 1e-1), {"max_iter": 1})
    assert sol.status == Status.MAX_ITER and "1 iterations" in sol.message
    assert sol.x is not None and evaluator.kkt_error(sol.residuals) > 1e-8


@pytest.mark.parametrize("bad", [{"operator": "sparse"}, {"alpha_factor": 2.5}, {"gamma": 0}, {"tol": -1},
                                 {"refine": -1}, {"time_limit": 0}])
def test_bad_parameters(bad):
    with pytest.raises(InputError, match=next(iter(bad))):
        make_solver("mprgp", bad)
