"""One ``--tol`` on solve, compare and bench (issue 33): the certified tolerance; ``-p tol`` stays the
solver's raw stop rule and a mismatch is explained."""
from __future__ import annotations

import json

import pytest

from dualfem.cli.main import main
from dualfem.experiments.spec_select import Selection, apply_selection
from dualfem.experiments.tolerance import check_tol, with_tolerance


def test_check_tol_names_the_range():
    assert check_tol(None) is None and check_tol("1e-6") == 1e-6
    for bad in ("2", "0", "nan", "x", True):
        with pytest.raises(Exception, match=r"--tol must be a finite number in \(0, 1\)"):
            check_tol(bad)


def test_bad_tol_is_one_line_exit_2(capsys):
    assert main(["solve", "f2", "--set", "N=8", "--tol", "5"]) == 2
    err = capsys.readouterr().err
    assert "dualfem solve: error: --tol must be" in err and "Traceback" not in err


def test_user_params_win_over_the_tier_settings():
    from dualfem.core.registry import get_solver

    cls = get_solver("osqp")
    assert with_tolerance(cls, 1e-6, {"tol": "1e-3"}) == {**cls.tolerance_params(1e-6), "tol": "1e-3"}
    assert with_tolerance(cls, None, {"rho": 1}) == {"rho": 1}


def test_solve_tol_certifies_to_it_and_explains_a_raw_tol(capsys):
    assert main(["solve", "f2", "--set", "N=16", "--set", "delta=1e-9", "--solver", "pdas", "--tol", "1e-3",
                 "--quiet", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["status"] == "solved"
    # the case: the solver's own stop rule met, the certificate not: the message says why
    main(["solve", "f2", "--set", "N=16", "--set", "delta=1e-9", "--solver", "uzawa_auto", "-p", "tol=1e-2",
          "--quiet", "--json"])
    rec = json.loads(capsys.readouterr().out)
    assert rec["claimed_status"] == "solved" and rec["status"] == "inaccurate"
    assert "-p tol=1e-2 is uzawa_auto's own stop rule" in rec["message"]


def test_compare_tol_is_every_runs_certified_tolerance(capsys):
    assert main(["compare", "f2", "--set", "N=8", "--solvers", "pdas,osqp", "--tol", "1e-4", "--json"]) == 0
    runs = json.loads(capsys.readouterr().out)["runs"]
    assert {r["solver"]: r["tolerance"] for r in runs} == {"pdas": 1e-4, "osqp": 1e-4}
    assert all(r["grade_x"] == "correct" and r["grade_mu"] == "correct" for r in runs)


def test_bench_tol_replaces_the_tiers():
    data = {"tiers": {"low": 1e-3, "high": 1e-9}, "solvers": [{"name": "osqp", "tiers": ["low"]}]}
    out = apply_selection(data, Selection(tol=1e-7))
    assert out["tiers"] == {"tol": 1e-7} and "tiers" not in out["solvers"][0]
    assert data["tiers"] == {"low": 1e-3, "high": 1e-9}       # the parsed file is not changed
