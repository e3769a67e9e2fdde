"""PDAS (semismooth Newton / primal-dual active set): exactness, iteration counts, globalization."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from _lcp import enumerate_lcp

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver, run

# A 3-constraint QP (K = D^-1, B = I, so D is the Delassus matrix) on which plain PDAS cycles
# from the cold start: found by a random search over SPD matrices (not an M-matrix).
D3 = np.array([[1.0834364270314840e+01, -1.8187564264928437e+00, -1.7122009243640542e+02],
               [-1.8187564264928437e+00, 1.1428256646650456e+02, 1.2118712207360728e+02],
               [-1.7122009243640542e+02, 1.2118712207360728e+02, 2.7875770397606798e+03]])
F3 = np.array([0.7641323237314777, -1.564918257665843, 1.725856082248691])


def cycling_qp() -> QP:
    K = np.linalg.inv(D3)
    return QP(K=sp.csc_matrix(0.5 * (K + K.T)), F=F3, B=sp.eye(3, format="csr"))


@pytest.mark.parametrize("load", ["f1", "f2", "f3"])
@pytest.mark.parametrize("delta", [1e-1, 1e-3, 1e-5, 1e-7, 1e-9])
def test_exact_and_fast_on_the_paper_scenes(load, delta):
    qp = load_scene(load, {"N": 32, "delta": delta}).build()
    sol = run("pdas", qp, {"refine_tol": 1e-16})           # refined to the rounding floor
    assert sol.status == Status.SOLVED, sol.message
    assert sol.iterations["newton"] <= 15
    x_ref, mu_ref, _ = enumerate_lcp(qp.K, qp.F, qp.B) if qp.m <= 12 else (None, None, None)
    assert evaluator.kkt_error(sol.residuals) < 1e-11, sol.residuals
    default = run("pdas", qp)                              # refined only when the step exceeds 2.5e-10
    assert default.status == Status.SOLVED and default.info["certificate"]["value"] <= 2.5e-10
    assert np.all(sol.multipliers >= 0)
    if x_ref is not None:
        d = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
        assert d["x_energy"] < 1e-10 and d["multipliers"] < 1e-8 and d["contact_mismatch"] == 0


@pytest.mark.parametrize("delta", [1e-1, 1e-9])
def test_matches_enumeration(delta):
    qp = load_scene("f2", {"N": 16, "delta": delta}).build()
    x_ref, mu_ref, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    sol = run("pdas", qp)
    d = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
    assert d["x_energy"] < 1e-11 and d["multipliers"] < 1e-9
    # f2 has a partial contact zone: the Newton iteration does real work
    assert 0 < (sol.multipliers > 0).sum() < qp.m


def test_plain_pdas_cycles_and_is_told():
    sol = run("pdas", cycling_qp(), {"globalize": "none"})
    assert sol.status == Status.STAGNATION
    assert "cycling" in sol.message


def test_globalized_pdas_solves_the_cycling_case():
    qp = cycling_qp()
    sol = run("pdas", qp)
    x_ref, mu_ref, _ = enumerate_lcp(qp.K, qp.F, qp.B)
    assert sol.status == Status.SOLVED, sol.message
    d = evaluator.compare(qp, sol.x, sol.multipliers, x_ref, mu_ref)
    assert d["x_energy"] < 1e-10 and d["multipliers"] < 1e-10
    kinds = {h.get("kind") for h in sol.history}
    assert kinds & {"damped", "projected", "cycle detected: switch to projected Newton"}


def test_refinement_keeps_small_delta_accurate():
    """Refinement never makes the answer worse, and PARDISO's reduced solve at delta = 1e-9 needs a step
    (SuperLU's answer is already as accurate here: its steps do not lower the residual and are not kept)."""
    qp = load_scene("f1", {"N": 32, "delta": 1e-9}).build()
    raw = run("pdas", qp, {"refine": 0})
    ref = run("pdas", qp, {"refine_tol": 1e-16})
    # a step is kept only if it lowers the residual: under SuperLU the unrefined answer is already at the
    # rounding floor here (KKT error 2.8e-14), under PARDISO it is not
    assert ref.info["refinement_steps"] >= 1 or evaluator.kkt_error(raw.residuals) <= 1e-13
    assert evaluator.kkt_error(ref.residuals) <= evaluator.kkt_error(raw.residuals)
    assert evaluator.kkt_error(ref.residuals) < 1e-11


def test_history_and_counters():
    qp = load_scene("f2", {"N": 16, "delta": 1e-5}).build()
    sol = run("pdas", qp)
    assert sol.iterations["newton"] == len([h for h in sol.history if "active" in h])
    assert all(h["step"] > 0 for h in sol.history if "step" in h)


@pytest.mark.parametrize("bad", [{"tol": 0}, {"max_iter": -1}, {"globalize": "wolfe"}, {"sigma": 0.7},
                                 {"c": -1.0}, {"refine": -1}, {"refine_tol": 0}])
def test_bad_parameters(bad):
    with pytest.raises(InputError):
        make_solver("pdas", bad)


def test_tolerance_params():
    from dualfem.core.registry import get_solver

    cls = get_solver("pdas")
    assert cls.tolerance_params(1e-6)["tol"] <= cls.defaults["tol"]
