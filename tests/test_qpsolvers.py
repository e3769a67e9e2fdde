"""qp_<backend>: every qpsolvers backend as a dualfem solver (solvers/qpsolvers_.py)."""
from __future__ import annotations

import types

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.registry import solvers
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import run
from dualfem.solvers.qpsolvers_ import _BACKENDS, DENSE_MAX_N, QpsolversSolver, known_backends

QP_SOLVERS = sorted(n for n in solvers() if n.startswith("qp_"))
INSTALLED = [n for n in QP_SOLVERS if solvers()[n].missing() is None]
#: the jax backends take seconds per solve (JIT): one scene only
SLOW = {"qp_qpax", "qp_jaxopt_osqp"}
_QP: dict = {}


def qp_for(load: str, delta: float):
    if (load, delta) not in _QP:
        qp = load_scene(load, {"N": 16, "delta": delta}).build()
        _QP[(load, delta)] = (qp, run("pdas", qp))
    return _QP[(load, delta)]


def test_every_backend_of_qpsolvers_is_registered():
    assert {f"qp_{b}" for b in known_backends()} == set(QP_SOLVERS)
    assert set(_BACKENDS) <= set(known_backends())
    qpsolvers = pytest.importorskip("qpsolvers")
    assert {f"qp_{b}" for b in qpsolvers.available_solvers} <= set(INSTALLED)


@pytest.mark.parametrize("name", INSTALLED)
@pytest.mark.parametrize("load, delta", [("f1", 1e-1), ("f2", 1e-5), ("f2", 1e-9)])
def test_within_declared_tolerance(name, load, delta):
    if name in SLOW and (load, delta) != ("f1", 1e-1):
        pytest.skip("jax backend: one scene only (seconds per solve)")
    qp, ref = qp_for(load, delta)
    cls = solvers()[name]
    sol = run(name, qp)
    assert sol.status != Status.ERROR, sol.message
    if sol.status == Status.SKIPPED:
        pytest.skip(sol.message)
    if sol.status != Status.SOLVED:
        assert sol.message.startswith(cls.backend)
        return
    d = evaluator.compare(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)
    assert d["x_energy"] <= cls.tolerance, (name, d)
    assert evaluator.kkt_error(sol.residuals) <= cls.tolerance, (name, sol.residuals)


@pytest.mark.parametrize("name", [n for n in ("qp_piqp", "qp_quadprog", "qp_proxqp") if n in INSTALLED])
def test_multiplier_sign(name):
    """z of G y <= h (G = -A) is our contact force: mu >= 0 and K x - F = B'mu."""
    qp, ref = qp_for("f2", 1e-5)
    sol = run(name, qp)
    assert sol.ok
    assert ref.multipliers.max() > 0
    assert np.all(sol.multipliers >= -1e-8 * ref.multipliers.max())
    assert np.abs(sol.multipliers - ref.multipliers).max() <= 1e-4 * ref.multipliers.max()
    assert np.abs(qp.K @ sol.x - qp.F - qp.B.T @ sol.multipliers).max() <= 1e-6 * np.abs(qp.F).max()


def test_missing_backend_has_an_install_hint():
    fake = type("QpFake", (QpsolversSolver,), {"name": "qp_fake_xyz", "backend": "fake_backend_xyz",
                                               "description": "x"})
    msg = fake.missing()
    assert "fake_backend_xyz" in msg and "pip install qpsolvers fake_backend_xyz" in msg
    sol = run(fake(), load_scene("f1", {"N": 4}).build())
    assert sol.status == Status.SKIPPED and "pip install" in sol.message
    for name in QP_SOLVERS:
        m = solvers()[name].missing()
        assert m is None or "pip install" in m


def test_dense_backends_skip_large_qps():
    big = types.SimpleNamespace(n=DENSE_MAX_N + 1, m=10)
    dense = [n for n in QP_SOLVERS if solvers()[n].info().dense]
    assert {"qp_daqp", "qp_quadprog", "qp_cvxopt", "qp_qpax"} <= set(dense)
    for name in dense:
        reason = solvers()[name]().skip(big)
        assert reason and "dense" in reason and str(DENSE_MAX_N) in reason
    assert "max_n = 100" in solvers()["qp_daqp"](max_n=100).skip(qp_for("f1", 1e-1)[0])


def test_settings_follow_the_vocabulary():
    cls = solvers()["qp_scs"]
    s = cls(tol=1e-7, max_iter=50, time_limit=3.0).settings()
    assert s == {"eps_abs": 1e-7, "eps_rel": 1e-7, "max_iters": 50, "time_limit_secs": 3.0}
    assert cls.tolerance_params(1e-4) == {"tol": 1e-8, "polish": True}
    assert cls.tolerance_params(1e-9) == {"tol": pytest.approx(1e-11), "polish": True}
    assert set(QpsolversSolver.defaults) >= {"tol", "max_iter", "time_limit", "verbose"}
