"""The stable dual-solver base class (dualfem.dual_solver): a plugin deriving from it declares only its
own parameters and gets ``operator``/``factor``, the skip and the setup."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.runner import run
from dualfem.solution import Solution, Status


def test_stable_path_exports():
    import dualfem.dual_solver as ds
    from dualfem.numerics.dual_solver import DualOperatorSolver

    assert ds.DualOperatorSolver is DualOperatorSolver
    assert set(ds.__all__) == {"DualOperator", "DualOperatorSolver", "OPERATORS", "make_operator"}
    assert all(hasattr(ds, n) for n in ds.__all__)


def test_a_subclass_gets_the_operator_parameters(scene):
    from dualfem.dual_solver import OPERATORS, DualOperatorSolver

    class Exact(DualOperatorSolver):          # declares neither operator nor factor
        name = "zz_dual_exact"
        defaults = {"verbose": False}

        def solve(self):              # the dense dual by NNLS: min |R mu + R^-T b0|, mu >= 0, D = R'R
            import scipy.linalg as la
            from scipy.optimize import nnls

            op = self.op
            R = la.cholesky(op.apply(np.eye(self.qp.m)))
            mu = nnls(R, -la.solve_triangular(R, op.b0, trans="T"))[0]
            return Solution(solver=self.name, status=Status.SOLVED, x=op.x_of(mu), multipliers=mu)

    assert Exact.defaults == {"verbose": False, "operator": "auto", "factor": "auto"}
    assert Exact.ranges["operator"] == OPERATORS and Exact.family == "dual"
    s = Exact(operator="dense")
    assert s.params["operator"] == "dense" and s.params["factor"] == "auto"
    with pytest.raises(InputError, match="operator"):
        Exact(operator="nope")
    _, qp = scene("f2", 8, 1e-5)
    sol = run(Exact(operator="dense"), qp)
    assert sol.status == "solved", sol.message
    ref = run("pdas", qp)
    assert np.allclose(sol.x, ref.x, atol=1e-10 * np.abs(ref.x).max())
