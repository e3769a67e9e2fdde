"""The template solver solvers/dual_gradient.py: right answers, honest failure statuses."""
import pytest

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import solvers
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import run


def reference_name():
    reg = solvers()
    for n in ("pdas", "clarabel"):
        if n in reg and reg[n].missing() is None:
            return n
    pytest.skip("no exact reference solver installed")


@pytest.mark.parametrize("scene", ["f1", "f2", "f3"])
@pytest.mark.parametrize("accelerate", [True, False])
def test_agrees_with_reference(scene, accelerate):
    qp = load_scene(scene, {"N": 8}).build()
    ref = run(reference_name(), qp)
    sol = run("dual_gradient", qp, {"accelerate": accelerate})
    assert sol.status == Status.SOLVED, sol.message
    d = evaluator.compare(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)
    assert d["x_energy"] < solvers()["dual_gradient"].tolerance
    assert d["contact_mismatch"] == 0
    assert evaluator.kkt_error(sol.residuals) < 1e-8


def test_acceleration_needs_fewer_iterations():
    qp = load_scene("signorini", {"N": 16}).build()
    fast = run("dual_gradient", qp, {"accelerate": True})
    slow = run("dual_gradient", qp, {"accelerate": False})
    assert fast.ok and slow.ok
    assert fast.iterations["gradient"] < slow.iterations["gradient"]


def test_not_converged_is_reported_honestly():
    qp = load_scene("f2", {"N": 8}).build()
    sol = run("dual_gradient", qp, {"max_iter": 2})
    assert sol.status == Status.MAX_ITER and sol.iterations["gradient"] == 2
    assert "not converged" in sol.message
    assert sol.residuals is not None       # the last iterate is returned and certified
    assert evaluator.kkt_error(sol.residuals) > 1e-10


def test_time_limit():
    qp = load_scene("f2", {"N": 8}).build()
    sol = run("dual_gradient", qp, {"time_limit": 1e-9})
    assert sol.status == Status.TIME_LIMIT


def test_skip_large():
    qp = load_scene("f2", {"N": 8}).build()
    sol = run("dual_gradient", qp, {"max_n": 10})
    assert sol.status == Status.SKIPPED and "max_n" in sol.message


@pytest.mark.parametrize("params,needle", [
    ({"step_safety": 2.5}, "step_safety"), ({"tol": -1}, "tol"), ({"max_iter": 0}, "max_iter"),
    ({"bogus": 1}, "unknown parameter"),
])
def test_bad_params(params, needle):
    with pytest.raises(InputError, match=needle):
        run("dual_gradient", load_scene("f1", {"N": 4}).build(), params)


def test_tolerance_params_tighten_the_stop():
    cls = solvers()["dual_gradient"]
    assert cls.tolerance_params(1e-6)["tol"] < 1e-6
    qp = load_scene("f2", {"N": 8}).build()
    loose = run("dual_gradient", qp, cls.tolerance_params(1e-2), tol=1e-2)
    tight = run("dual_gradient", qp, cls.tolerance_params(1e-8), tol=1e-8)
    assert loose.ok and tight.ok and loose.iterations["gradient"] < tight.iterations["gradient"]
