"""One parameter vocabulary: tol, max_iter, time_limit (finite), verbose; old names still accepted."""
from __future__ import annotations

import math

import pytest

from dualfem.core.errors import InputError
from dualfem.core.registry import solvers
from dualfem.core.solver import RenamedParameterWarning

BUILTIN = [n for n, c in solvers().items() if c.__module__.startswith("dualfem.solvers.")]


def test_the_builtin_solvers_are_found():
    assert {"uzawa", "uzawa_auto", "pdas", "penalty", "osqp", "clarabel", "cvxpy", "dual_gradient",
            "mprgp"} <= set(BUILTIN)


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_common_parameters(name):
    d = solvers()[name].defaults
    assert {"tol", "max_iter", "time_limit", "verbose"} <= set(d), sorted(d)
    assert isinstance(d["time_limit"], float) and 0 < d["time_limit"] < math.inf
    assert isinstance(d["verbose"], bool)


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_tolerance_params_use_new_names(name):
    cls = solvers()[name]
    if cls.missing():
        pytest.skip(cls.missing())
    assert not set(cls.tolerance_params(1e-6)) & set(cls.renamed)


@pytest.mark.parametrize("name, old, new", [
    ("osqp", "eps_abs", "tol"), ("osqp", "polishing", "polish"), ("clarabel", "tol_feas", "tol"),
    ("cvxpy", "eps", "tol"), ("uzawa", "tol_outer", "tol"), ("uzawa", "max_outer", "max_iter"),
    ("penalty", "penetration_tol", "tol"), ("penalty", "max_newton", "max_iter"),
])
def test_old_names_warn_and_map(name, old, new):
    cls = solvers()[name]
    value = True if old == "polishing" else 7e-7 if "tol" in old or old.startswith("eps") else 7
    if old == "polishing":
        value = False
    with pytest.warns(RenamedParameterWarning, match=f"'{old}'.*'{new}'"):
        s = cls(**{old: value})
    assert s.params[new] == value and old not in s.params


def test_old_and_new_name_must_agree():
    with pytest.raises(InputError, match="disagree"):
        solvers()["uzawa"](tol_outer=1e-3, tol=1e-4)
    with pytest.warns(RenamedParameterWarning):
        assert solvers()["uzawa"](tol_outer=1e-4, tol=1e-4).params["tol"] == 1e-4
