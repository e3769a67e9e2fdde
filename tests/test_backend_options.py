"""Backend options pass through (issue 33): ``-s 'osqp[rho=0.1]'``, ``-s 'clarabel[max_iter=50]'`` become
solver parameters validated against the installed library's own option list (Solver.backend_options)."""
from __future__ import annotations

import pytest

from dualfem.core.errors import InputError
from dualfem.core.registry import get_solver
from dualfem.core.solver import Solver
from dualfem.experiments.runner import make_solver


def _needs(module: str) -> None:
    pytest.importorskip(module)


def test_osqp_backend_option_reaches_osqp():
    _needs("osqp")
    s = make_solver("osqp", {"rho": "0.25", "polish_refine_iter": "7"})
    assert s.params["rho"] == 0.25 and s.params["polish_refine_iter"] == 7
    import numpy as np
    import scipy.sparse as sp

    from dualfem.core.qp import QP

    qp = QP(K=sp.csr_matrix(np.eye(2)), F=np.array([1.0, -1.0]), B=sp.csr_matrix(np.eye(2)), name="tiny")
    s.setup(qp)
    assert s._solver.settings.rho == 0.25      # OSQP's own settings object holds what was given


def test_unknown_option_is_refused_naming_the_backend_list():
    _needs("osqp")
    with pytest.raises(InputError) as e:
        make_solver("osqp", {"rhoo": 0.1})
    msg = str(e.value)
    assert "'rhoo'" in msg and "backend options" in msg and "rho," in msg and "sigma" in msg


def test_clarabel_settings_pass_and_bad_values_are_refused():
    _needs("clarabel")
    assert make_solver("clarabel", {"max_iter": "50"}).params["max_iter"] == 50
    s = make_solver("clarabel", {"static_regularization_constant": "1e-9"})
    assert s.params["static_regularization_constant"] == 1e-9
    with pytest.raises(InputError, match="max_threads"):
        make_solver("clarabel", {"max_threads": "many"})


def test_qpsolvers_backend_options_exclude_what_dualfem_sets():
    _needs("qpsolvers")
    _needs("piqp")
    opts = get_solver("qp_piqp").backend_options({})
    assert "eps_abs" not in opts and "max_iter" not in opts and "delta_init" in opts
    s = make_solver("qp_piqp", {"delta_init": 1e-3})
    assert s.settings()["delta_init"] == 1e-3
    with pytest.raises(InputError, match="allowed"):
        make_solver("qp_quadprog", {"delta_init": 1e-3})       # no readable option list: refused


def test_a_solver_without_the_hook_refuses_unknown_names():
    class Plain(Solver):
        name = "plain_test"
        defaults = {"tol": 1e-6}

    with pytest.raises(InputError, match="allowed: tol$"):
        Plain(rho=1)


def test_cvxpy_takes_the_options_of_its_backend():
    _needs("cvxpy")
    _needs("osqp")
    assert make_solver("cvxpy", {"solver": "OSQP", "rho": "0.2"}).params["rho"] == 0.2
    with pytest.raises(InputError, match="'rho'"):
        make_solver("cvxpy", {"solver": "CLARABEL", "rho": 0.2})     # not a Clarabel setting
    assert "eps_abs" not in get_solver("cvxpy").backend_options({"solver": "OSQP"})   # dualfem sets it (tol)
