"""dualfem compare: reference choice, grades (one Row type, one grade function), JSON interface, exit status."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core import registry
from dualfem.core.scene import load_scene
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.experiments.compare import RUN_FIELDS, compare_solvers
from dualfem.experiments.row import Row
from dualfem.verify.grading import grade


@pytest.fixture(scope="module")
def qp():
    return load_scene("f2", {"N": 16, "delta": 1e-5}).build()


class _FromPdas(Solver):
    """Test double: pdas's answer with x multiplied by ``x_factor``, claiming success."""

    description = "test double"
    x_factor = 1.0

    def solve(self):
        ref = registry.get_solver("pdas")()
        ref.setup(self.qp)
        s = ref.solve()
        return Solution(solver=self.name, status=Status.SOLVED, x=s.x * self.x_factor,
                        multipliers=s.multipliers.copy())


class _WrongSolver(_FromPdas):
    """Returns a slightly wrong answer and claims success (a silent wrong answer)."""

    name = "test_wrong"
    tolerance = 1e-6
    x_factor = 1 + 1e-3


class _HonestFailure(Solver):
    """Returns a poor answer and says so."""

    name = "test_honest"
    description = "test double"

    def solve(self):
        return Solution(solver=self.name, status=Status.MAX_ITER, x=np.zeros(self.qp.n),
                        multipliers=np.zeros(self.qp.m), message="gave up")


@pytest.fixture
def doubles(monkeypatch):
    monkeypatch.setitem(registry._SOLVERS, "test_wrong", _WrongSolver)
    monkeypatch.setitem(registry._SOLVERS, "test_honest", _HonestFailure)


def test_reference_and_verdicts(qp):
    res = compare_solvers(qp, ["pdas", "clarabel", "penalty"])
    assert res["reference"]["solver"] == "pdas"
    assert res["reference"]["error_bound"] < 1e-10
    cc = res["reference"]["cross_check"]
    assert cc["solver"] == "clarabel" and cc["agrees"]
    g = {r["solver"]: r["grade"] for r in res["runs"]}
    assert g == {"pdas": "correct", "clarabel": "correct", "penalty": "correct"}
    v = {r["solver"]: r["verdict"] for r in res["runs"]}          # the deprecated alias, derived from grade
    assert v == {"pdas": "reference", "clarabel": "ok", "penalty": "ok"}
    assert res["silent_wrong"] == []
    for r in res["runs"]:
        assert set(RUN_FIELDS) <= set(r)
        assert r["diff"]["x_energy"] < 1e-6
    # the records are views of graded Rows, graded by the one policy
    assert [type(r) for r in res.rows] == [Row] * 3 and all(r.kind == "compare" for r in res.rows)
    for row, rec in zip(res.rows, res["runs"]):
        assert row.grade == rec["grade"] == grade(row.status, row.err_x_energy, row.kkt_error, row.tol,
                                                  row.ref_bound)
        assert row.ref_solver == "pdas" and row.err_x_energy == rec["diff"]["x_energy"]


def test_wrong_claim_is_demoted_by_the_runner_and_honest_failure_is_not(qp, doubles):
    res = compare_solvers(qp, ["pdas", "test_wrong", "test_honest"])
    v = {r["solver"]: r["verdict"] for r in res["runs"]}
    wrong = next(r for r in res["runs"] if r["solver"] == "test_wrong")
    # the runner certifies every plugin: the false 'solved' is reported as inaccurate, the claim kept
    assert wrong["status"] == "inaccurate" and wrong["claimed_status"] == "solved"
    assert "not certified" in wrong["message"] and "stationarity" in wrong["message"]
    assert v["test_wrong"] == "failed" and v["test_honest"] == "failed"
    assert {r["solver"]: r["grade"] for r in res["runs"]} == {"pdas": "correct", "test_wrong": "failed",
                                                              "test_honest": "failed"}
    assert res["silent_wrong"] == []
    assert wrong["diff"]["x_energy"] == pytest.approx(1e-3, rel=1e-6)


@pytest.mark.parametrize("kkt,diff,energy,expected", [(1e-12, 1e-3, -1.0, "silent_wrong"),
                                                      (1e-3, 1e-12, -1.0, "flagged"),
                                                      (1e-12, 1e-12, -1.0, "correct"),
                                                      (None, None, None, "flagged")])   # solved, no answer
def test_grade_of_a_solved_claim(kkt, diff, energy, expected):
    """compare's own check behind the runner's: a 'solved' record that is off is a wrong claim."""
    from dualfem.experiments.compare import VERDICT_OF_GRADE, grade_record

    rec = {"solver": "s", "status": "solved", "energy": energy, "kkt_error": kkt, "tolerance": 1e-6,
           "diff": {"x_energy": diff} if diff else None}
    g = grade_record(rec, {"solver": "pdas", "error_bound": 1e-12})
    assert g == expected
    assert VERDICT_OF_GRADE[g] == ("ok" if expected == "correct" else "wrong")


def test_no_exact_solver_means_no_reference(qp):
    res = compare_solvers(qp, ["penalty"])
    assert res["reference"] is None
    assert res["runs"][0]["verdict"] == "unchecked" and res["runs"][0]["grade"] == "unverified"
    assert res["silent_wrong"] == []


def test_cli_json(capsys):
    rc = main(["compare", "f2", "--set", "N=16", "--set", "delta=1e-9", "--solvers", "pdas,penalty,osqp", "--json"])
    out = capsys.readouterr().out
    data = json.loads(out)                       # exactly one JSON object on stdout
    assert rc == 0
    assert [r["solver"] for r in data["runs"]] == ["pdas", "penalty", "osqp"]
    for r in data["runs"]:
        for k in ("solver", "status", "iterations", "energy", "time_s", "residuals", "diff", "verdict", "grade"):
            assert k in r
        assert {"x_energy", "multipliers", "contact_mismatch"} <= set(r["diff"])
    assert data["reference"]["solver"] == "pdas"
    assert data["params"]["delta"] == 1e-9


def test_cli_exit_0_when_the_runner_demotes_a_wrong_claim(doubles, capsys):
    """A wrong 'solved' is caught by the runner's certification: reported as inaccurate, not silent."""
    rc = main(["compare", "f2", "--set", "N=16", "--solvers", "pdas,test_wrong,test_honest"])
    out = capsys.readouterr().out
    assert rc == 0 and "SILENT WRONG ANSWER" not in out
    assert re.search(r"test_wrong +inaccurate +failed", out) and "not certified" in out
    assert re.search(r"pdas +solved +correct", out)


def test_cli_exit_1_on_silent_wrong_answer(doubles, capsys, monkeypatch):
    """compare's own check behind the runner's: with certification bypassed, the verdict is 'wrong'."""
    import dualfem.experiments.runner as runner

    monkeypatch.setattr(runner, "certify_status", lambda qp, sol, tol, exact, **kw: sol)
    rc = main(["compare", "f2", "--set", "N=16", "--solvers", "pdas,test_wrong,test_honest"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "SILENT WRONG ANSWER: test_wrong" in out
    assert re.search(r"test_wrong +solved +(silent_wrong|flagged)", out)


def test_cli_exit_0_on_honest_failure(doubles, capsys):
    rc = main(["compare", "f2", "--set", "N=16", "--solvers", "pdas,test_honest"])
    assert rc == 0
    assert "gave up" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [
    ["compare", "f2", "--set", "N=16", "--solvers", "pdas,nosuch"],
    ["compare", "f2", "--set", "N=16", "--solvers", ","],
    ["compare", "f2", "--set", "N=16", "--solvers", "pdas,pdas"],
    ["compare", "f2", "--set", "N=16", "--solvers", "pdas", "--param", "tol=1"],
    ["compare", "f2", "--set", "N=16", "--solvers", "pdas", "--param", "osqp.eps_abs=1"],
    ["compare", "f2", "--set", "N=16", "--solvers", "pdas", "--param", "pdas.tol=-1"],
    ["compare", "f2", "--set", "N=-3"],
])
def test_cli_input_errors(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error" in err


def test_cli_solver_params(capsys):
    rc = main(["compare", "f2", "--set", "N=16", "--solvers", "pdas,penalty", "--param", "penalty.rho_growth=10",
               "--json"])
    data = json.loads(capsys.readouterr().out)
    assert rc == 0
    pen = next(r for r in data["runs"] if r["solver"] == "penalty")
    assert pen["params"]["rho_growth"] == 10.0


class _Clone(_FromPdas):
    """Returns exactly pdas's answer (same linear algebra): no independent confirmation."""

    name = "test_clone"
    tolerance = 1e-9


def test_identical_answer_is_not_a_cross_check(qp, monkeypatch):
    monkeypatch.setitem(registry._SOLVERS, "test_clone", _Clone)
    res = compare_solvers(qp, ["test_clone", "pdas", "clarabel"])
    ref = res["reference"]
    assert {ref["solver"], *ref["cross_check"]["identical_to_reference"]} == {"pdas", "test_clone"}
    assert ref["cross_check"]["solver"] == "clarabel" and ref["cross_check"]["agrees"]


class _ExactPlugin(_FromPdas):
    """A correct third-party solver (pdas's exact answer) that does not declare ``reference``."""

    name = "zz_exact_plugin"
    tolerance = 1e-9


def test_a_plugin_that_does_not_declare_reference_is_never_the_reference(qp, monkeypatch):
    """docs/plugins.md 1.5: the reference is chosen only among solvers declaring ``reference``, even when
    an undeclared exact solver has the smaller certificate; it still serves as the cross-check."""
    monkeypatch.setitem(registry._SOLVERS, "zz_exact_plugin", _ExactPlugin)
    res = compare_solvers(qp, ["zz_exact_plugin", "clarabel"])
    runs = {r["solver"]: r for r in res["runs"]}
    assert runs["zz_exact_plugin"]["error_bound"] < runs["clarabel"]["error_bound"]     # it would have won
    assert res["reference"]["solver"] == "clarabel"
    assert res["reference"]["cross_check"]["solver"] == "zz_exact_plugin"
    assert runs["zz_exact_plugin"]["grade"] == "correct"
    alone = compare_solvers(qp, ["zz_exact_plugin"])
    assert alone["reference"] is None and alone["runs"][0]["grade"] == "unverified"


def test_a_bench_spec_may_not_name_an_undeclared_reference(monkeypatch):
    from dualfem.core.errors import InputError
    from dualfem.experiments.spec import parse_spec

    monkeypatch.setitem(registry._SOLVERS, "zz_exact_plugin", _ExactPlugin)
    base = {"scenes": [{"scene": ["f2"], "N": [8]}], "solvers": [{"name": "pdas"}]}
    assert parse_spec({**base, "reference": {"solvers": ["clarabel"]}}).reference["solvers"] == ["clarabel"]
    for name in ("zz_exact_plugin", "mprgp"):
        with pytest.raises(InputError, match=rf"reference.solvers names '{name}', which does not declare reference"):
            parse_spec({**base, "reference": {"solvers": [name, "pdas"]}})


def test_table_is_compact_and_summarises_skipped_solvers():
    """At most 100 columns; skipped solvers in one line, not one row each; the scene as the user named it."""
    from dualfem.experiments.compare import TABLE_WIDTH, table

    def run(name, status="solved", grade="correct", msg=""):
        return {"solver": name, "status": status, "grade": grade, "iterations": {"outer": 12, "inner": 40},
                "time_s": {"setup": 0.5, "solve": 1.25}, "energy": -5.3e-4, "kkt_error": 1e-12,
                "error_bound": 2e-12, "tolerance": 1e-8, "message": msg,
                "diff": None if status == "skipped" else {"x_energy": 1e-12, "multipliers": 3e-11,
                                                          "contact_mismatch": 0}}

    runs = [run("plugin_solver_16"), run("osqp", "inaccurate", "failed", "osqp: not certified " + "x" * 200)]
    runs += [run(f"qp_missing{i}", "skipped", "skipped", f"needs module {i}") for i in range(14)]
    result = {"problem": "thin_defect[f2]", "ndof": 1810, "n_defect_nodes": 22, "runs": runs, "silent_wrong": [],
              "reference": {"solver": "pdas", "why": "exact " * 40, "kkt_error": 1e-14, "cross_check": None}}
    text = table(result, scene="benchmarks/scenes/plate.toml")
    lines = text.splitlines()
    assert max(map(len, lines)) <= TABLE_WIDTH == 100
    assert lines[0] == "plate: 1810 unknowns, 22 defect nodes" and "thin_defect" not in text
    assert not any(ln.startswith("qp_missing") for ln in lines)
    assert text.count("qp_missing") == 14 and "not run (14): qp_missing0," in text   # one (wrapped) line
    assert re.search(r"^plugin_solver_16 +solved +correct +12 +1\.750 ", text, re.M)
    assert table(result).startswith("thin_defect[f2]: 1810 unknowns")


def test_solve_summary_names_the_scene_as_given():
    from dualfem.cli.main import human_summary

    rec = {"problem": "thin_defect[f2]", "ndof": 1810, "n_defect_nodes": 22, "solver": "pdas", "status": "solved",
           "message": "", "iterations": {}, "time_s": {"setup": 0.1, "solve": 0.2}}
    assert human_summary(rec, scene="curved").startswith("curved: 1810 unknowns")
    assert human_summary(rec, scene="benchmarks/scenes/inclined_biaxial.toml").startswith("inclined_biaxial: ")
    assert human_summary(rec).startswith("thin_defect[f2]: ")
