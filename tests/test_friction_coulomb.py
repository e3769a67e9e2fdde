"""Coulomb friction through the conic backends (the fixed point of dualfem.numerics.coulomb over clarabel's and
cvxpy's Tresca solves, dualfem.numerics.coulomb_run): mu_f = 0 is the frictionless answer to 1e-12, the 2D inclined
closed crack slips by 4 (1 - nu^2) (|tau| - mu_f sigma_n) / E sqrt(a^2 - x^2) and sticks exactly when
|tau| <= mu_f sigma_n, clarabel and cvxpy agree, the counters say how many Tresca solves it took."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.solution import Status
from dualfem.experiments import friction as fr
from dualfem.experiments.runner import run
from dualfem.scene import load_scene

pytest.importorskip("gmsh")
pytest.importorskip("clarabel")


def _rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def test_zero_coefficient_is_the_frictionless_answer():
    free = run("clarabel", load_scene("f2", {"N": 16}).build())
    zero = run("clarabel", load_scene("f2", {"N": 16, "friction": "coulomb", "friction_coefficient": 0.0}).build())
    assert zero.status == Status.SOLVED and zero.iterations["coulomb"] == 1
    assert _rel(zero.x, free.x) < 1e-12 and _rel(zero.multipliers[:free.multipliers.size], free.multipliers) < 1e-12


def test_inclined_crack_slips_by_the_coulomb_closed_form():
    sigma_n, tau = fr.resolved(60.0)
    assert abs(tau) > 0.2 * sigma_n
    c = fr.inclined_2d(60.0, "coulomb", 0.2, 0.05, 0.004)
    t = fr.inclined_2d(60.0, "tresca", 0.2 * sigma_n, 0.05, 0.004)
    assert c["status"] == "solved" and c["iterations"]["coulomb"] >= 2
    assert c["error"] < 0.10
    # the Coulomb threshold is mu_f times the nodal pressure, which is sigma_n to a few per cent: close to Tresca
    assert np.abs(np.asarray(c["slip"]) - np.asarray(t["slip"])).max() < 0.05 * t["max_slip"]


def test_inclined_crack_sticks_exactly_under_coulomb():
    sigma_n, tau = fr.resolved(20.0)
    assert abs(tau) < 0.5 * sigma_n
    out = fr.inclined_2d(20.0, "coulomb", 0.5, 0.05, 0.004)
    assert out["status"] == "solved" and "error" not in out and out["max_slip"] <= 1e-14 * out["scale"]


def test_clarabel_and_cvxpy_agree_on_coulomb():
    pytest.importorskip("cvxpy")
    qp = load_scene("f2", {"N": 16, "friction": "coulomb", "friction_coefficient": 0.3}).build()
    a, b = run("clarabel", qp), run("cvxpy", qp)
    assert a.status == b.status == Status.SOLVED, (a.message, b.message)
    assert _rel(a.x, b.x) < 1e-8 and "Coulomb fixed point" in a.message
    assert "Tresca problem whose threshold" in a.info["certificate"]["notes"]


@pytest.mark.parametrize("keys", [{"friction": "tresca", "friction_bound": 0.5},
                                  {"friction": "coulomb", "friction_coefficient": 0.3}], ids=["tresca", "coulomb"])
def test_every_solver_that_takes_the_law_agrees_to_1e_8(keys):
    from dualfem.core.registry import solvers

    qp = load_scene("f2", {"N": 16, **keys}).build()
    ref = run("clarabel", qp)
    assert ref.status == Status.SOLVED
    law = keys["friction"]
    names = [n for n, cls in solvers().items() if law in getattr(cls, "accepts", ()) and not cls.missing()
             and n != "clarabel" and not n.startswith("qp_")]
    assert {"cvxpy", "uzawa", "uzawa_auto", "penalty"} <= set(names)
    for name in names:
        sol = run(name, qp)
        if sol.status == Status.SKIPPED:
            continue
        assert sol.status == Status.SOLVED, (name, sol.message)
        assert _rel(sol.x, ref.x) < 1e-8, (name, _rel(sol.x, ref.x))
