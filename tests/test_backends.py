"""OSQP and Clarabel: sign conventions mapped to ours, agreement with each other."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core import evaluator
from dualfem.experiments.runner import run


@pytest.mark.parametrize("name", ["f1", "f2", "f3"])
@pytest.mark.parametrize("delta", [1e-1, 1e-5])
def test_osqp_and_clarabel_agree(scene, name, delta):
    _, qp = scene(name, 16, delta)
    a, b = run("clarabel", qp), run("osqp", qp)
    assert a.ok and b.ok, (a.message, b.message)
    d = evaluator.compare(qp, b.x, b.multipliers, a.x, a.multipliers)
    assert d["x_energy"] < 1e-6 and d["x_max"] < 1e-6
    assert d["multipliers"] < 1e-5 and d["contact_mismatch"] == 0


@pytest.mark.parametrize("solver", ["osqp", "clarabel"])
def test_multiplier_sign_convention(scene, solver):
    """f1 presses the faces together: every mu_j > 0 and Kx - F = +B'mu."""
    _, qp = scene("f1", 16, 1e-5)
    sol = run(solver, qp)
    assert np.all(sol.multipliers > 0)
    r = qp.K @ sol.x - qp.F
    assert np.abs(r - qp.B.T @ sol.multipliers).max() < 1e-6 * np.abs(qp.F).max()
    assert np.abs(r + qp.B.T @ sol.multipliers).max() > 0.1 * np.abs(qp.F).max()


def test_osqp_raw_dual_is_nonpositive(scene):
    """Documents the library fact our mapping relies on: OSQP's y <= 0 at an active l <= Ax."""
    import osqp

    _, qp = scene("f1", 8, 1e-5)
    s = osqp.OSQP()
    s.setup(P=sp.triu(qp.K, format="csc"), q=-qp.F, A=qp.B.tocsc(), l=np.zeros(qp.m),
            u=np.full(qp.m, np.inf), verbose=False, eps_abs=1e-10, eps_rel=1e-10, polishing=True)
    res = s.solve()
    assert np.all(res.y < 0)


def test_clarabel_raw_dual_is_nonnegative(scene):
    import clarabel

    _, qp = scene("f1", 8, 1e-5)
    st = clarabel.DefaultSettings()
    st.verbose = False
    s = clarabel.DefaultSolver(sp.triu(qp.K, format="csc"), -qp.F, (-qp.B).tocsc(), np.zeros(qp.m),
                               [clarabel.NonnegativeConeT(qp.m)], st)
    assert np.all(np.array(s.solve().z) > 0)


@pytest.mark.parametrize("solver", ["osqp", "clarabel"])
def test_unscaled_option_still_maps_signs(scene, solver):
    _, qp = scene("f1", 8, 1e-1)
    sol = run(solver, qp, {"scale": False})
    assert sol.x is not None and np.all(sol.multipliers > -1e-8 * np.abs(sol.multipliers).max())


def test_solver_parameter_errors():
    from dualfem.core.errors import InputError
    from dualfem.experiments.runner import make_solver

    with pytest.raises(InputError, match="unknown parameter 'eps'"):
        make_solver("osqp", {"eps": 1})
    with pytest.raises(InputError, match="'tol'"):
        make_solver("osqp", {"tol": -1})
    with pytest.raises(InputError, match="max_iter"):
        make_solver("clarabel", {"max_iter": "many"})


def test_clarabel_polish_removes_its_small_delta_error(scene):
    _, qp = scene("f2", 16, 1e-9)
    xs, mus, ok = evaluator.certify(qp, run("uzawa_auto", qp).x)
    assert ok
    raw = run("clarabel", qp, {"polish": False})     # polish is on by default (docs/solvers_tolerances.md)
    pol = run("clarabel", qp, {"polish": True})
    e_raw = evaluator.compare(qp, raw.x, raw.multipliers, xs, mus)["x_energy"]
    e_pol = evaluator.compare(qp, pol.x, pol.multipliers, xs, mus)["x_energy"]
    assert pol.info["polished"] and e_pol < 1e-9 < e_raw < 1e-5


def test_missing_dependency_is_one_line_exit_2(monkeypatch, capsys):
    from dualfem.cli.main import main
    from dualfem.core.registry import get_solver

    monkeypatch.setattr(get_solver("osqp"), "requires", ("osqp_not_installed_here",))
    assert main(["solve", "f2", "--set", "N=8", "--solver", "osqp"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "osqp_not_installed_here" in err[0] and "pip install" in err[0]


@pytest.mark.parametrize("solver", ["osqp", "clarabel"])
@pytest.mark.parametrize("load_scale", [1e-6, 1e6])
def test_backends_invariant_to_load_magnitude(scene, solver, load_scale):
    """The scaling normalises the unknowns, so the load magnitude cannot hurt the backends."""
    from dualfem.core.scene import load_scene

    _, qp = scene("f2", 16, 1e-5)
    base = run(solver, qp)
    qps = load_scene("f2", {"N": 16, "delta": 1e-5, "load_scale": load_scale}).build()
    sol = run(solver, qps)
    assert sol.ok
    d = evaluator.compare(qps, sol.x, sol.multipliers, load_scale * base.x, load_scale * base.multipliers)
    assert d["x_energy"] < 1e-8 and d["contact_mismatch"] == 0
