"""The verify room (issue 34 item 4): grading, the reference policy and the one judge in one room;
old import paths keep working with a DeprecationWarning."""
from __future__ import annotations

import importlib
import sys
import warnings

import numpy as np
import pytest


def test_old_grade_path_is_a_deprecated_shim_to_the_same_objects():
    sys.modules.pop("dualfem.core.grade", None)
    with pytest.warns(DeprecationWarning, match="dualfem.verify"):
        old = importlib.import_module("dualfem.core.grade")
    from dualfem.verify import grading as new

    for name in old.__all__:
        assert getattr(old, name) is getattr(new, name), name


def test_the_room_re_exports_evaluator_and_certificate():
    import dualfem.verify as v
    from dualfem.core import evaluator
    from dualfem.numerics import certify

    assert v.residuals is evaluator.residuals and v.kkt_error is evaluator.kkt_error
    assert v.certified_error is certify.certified_error and v.KSolver is certify.KSolver
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # the room itself does not touch a deprecated path
        importlib.reload(v)
    assert set(v.__all__) <= set(dir(v))


def test_verify_sits_between_the_plugins_and_experiments():
    from _imports import LEVEL, SHIMS, room

    assert LEVEL["numerics"] < LEVEL["post"] < LEVEL["verify"] < LEVEL["experiments"]
    assert room("dualfem.verify.grading") == "verify" and "dualfem.core.grade" in SHIMS


def test_reference_policy_lives_in_the_room_and_compare_uses_it(monkeypatch):
    """choose() ranks trusted runs by certificate, KKT error, time; the first that may serve is the
    reference; a run above its own kkt_max or without a finite certificate is never trusted."""
    from dualfem.experiments import reference as old
    from dualfem.verify import reference as ref

    assert old.trusted is ref.trusted and old.choose is ref.choose and old.Reference is ref.Reference
    monkeypatch.setattr(ref, "may_serve", lambda name: name != "third_party")
    C = ref.Candidate
    runs = [C("slow", "solved", True, 1e-12, 1e-9, 5.0, 1e-8), C("fast", "solved", True, 1e-12, 1e-9, 1.0, 1e-8),
            C("third_party", "solved", True, 1e-13, 1e-12, 0.1, 1e-8),
            C("loose", "solved", True, 1e-6, 1e-9, 0.1, 1e-8),
            C("inexact", "solved", False, 0.0, 0.0, 0.1, 1e-8), C("nan", "solved", True, 0.0, float("nan"), 0.1, 1e-8),
            C("failed", "max_iter", True, 0.0, 0.0, 0.1, 1e-8)]
    assert ref.choose(runs) == ("fast", ["third_party", "slow"])
    assert ref.choose(runs[2:]) == (None, ["third_party"])


@pytest.fixture(scope="module")
def small():
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    qp = load_scene("f2", {"N": 8}).build()
    return qp, run("pdas", qp)


def test_the_runner_keeps_claim_and_verdict_apart(small):
    """A claim the judge demotes: ``claim`` and ``info["claimed_status"]`` keep the plugin's word,
    ``status`` (as before) and ``verdict.status`` the certified one, ``verdict.why`` the reason."""
    from dualfem.core.solution import Solution, Status
    from dualfem.experiments.runner import attach_residuals, certify_status
    from dualfem.verify import Verdict

    qp, sol = small
    assert sol.claim == "solved" and isinstance(sol.verdict, Verdict) and sol.verdict.status == str(sol.status)
    assert sol.verdict.outcome == "unverified" and sol.verdict.cert_x is not None  # no reference: at best unverified
    loose = Solution("pdas", Status.SOLVED, x=sol.x + 1e-3 * abs(sol.x).max(), multipliers=sol.multipliers)
    certify_status(qp, attach_residuals(qp, loose), 1e-9, exact=True)
    v = loose.verdict
    assert loose.claim == loose.info["claimed_status"] == "solved" and loose.status == Status.INACCURATE
    assert v.demoted and v.status == "inaccurate" and v.outcome == "failed" and v.why in loose.message
    assert Solution("s", Status.SOLVED).verdict is None and Solution("s", Status.SOLVED).claim is None


def test_judge_against_a_reference(small):
    """judge() reuses the runner's certification and grades against a trusted answer: the same answer is
    correct; one off by more than tol + the reference's bound whose residuals look fine is silent_wrong."""
    from dataclasses import replace

    from dualfem.verify import Answer, judge

    qp, sol = small
    tol = sol.verdict.tol
    same = judge(qp, sol, tol, reference=Answer("ref", sol.x, sol.multipliers, 0.0))
    assert same.outcome == "correct" and same.err_x == 0.0 and same.certificate is sol.verdict.certificate
    far = Answer("ref", 2.0 * sol.x, 2.0 * sol.multipliers, 0.0)
    assert judge(qp, sol, tol, reference=far).outcome == "silent_wrong"
    assert judge(qp, sol, tol, reference=replace(far, bound=10.0)).outcome == "correct"   # the slack it grants


def test_one_outcome_vocabulary_documented_once():
    """docs/conventions.md's "Outcomes" table lists exactly the judge's outcomes, and every command's
    vocabulary derives from it (compare's deprecated verdict words, the harness's lost tasks)."""
    import re

    from _imports import ROOT

    from dualfem.experiments.compare import VERDICT_OF_GRADE
    from dualfem.verify import OUTCOMES, outcome_without_answer

    text = (ROOT / "docs" / "conventions.md").read_text()
    table = text.split("### Outcomes", 1)[1].split("\n\n")[2]
    assert sorted(re.findall(r"^\| `(\w+)` \|", table, re.M)) == sorted(OUTCOMES)
    assert set(VERDICT_OF_GRADE) == set(OUTCOMES)
    assert {outcome_without_answer(s) for s in ("time_limit", "crashed", "skipped", "error")} <= set(OUTCOMES)


def test_the_verdict_agrees_with_the_status_on_a_non_finite_answer(small):
    """x = 1e308 (K x overflows, NaN > tol is False): the judge itself makes it numerical_error, so the
    verdict, not only the runner's status, says so; a plugin cannot hand in its own claim or verdict."""
    from dualfem.core.solution import Solution, Status
    from dualfem.core.solver import Solver
    from dualfem.experiments.runner import run

    qp, sol = small

    class Huge(Solver):
        name = "verify_huge"

        def solve(self):
            return Solution(self.name, Status.SOLVED, x=np.full(self.qp.n, 1e308),
                            multipliers=np.full(self.qp.m, 1e308), claim="max_iter", verdict=sol.verdict)

    with np.errstate(all="ignore"):
        out = run(Huge(), qp)
    assert out.status == Status.NUMERICAL_ERROR and out.claim == "solved"
    assert out.verdict is not sol.verdict and out.verdict.status == "numerical_error" and out.verdict.demoted
    assert out.verdict.outcome == "failed" and "not finite" in out.verdict.why


def test_judge_re_certifies_the_claim_at_another_tolerance(small):
    """At a tolerance the runner did not certify, judge() judges the plugin's claim afresh, without
    touching the solution it was given."""
    from dualfem.verify import Answer, judge

    qp, sol = small
    status, verdict = sol.status, sol.verdict
    v = judge(qp, sol, 1e-30, reference=Answer("ref", sol.x, sol.multipliers, 0.0))
    assert v.tol == 1e-30 and v.demoted and v.status == "inaccurate" and v.outcome == "failed" and v.err_x == 0.0
    assert sol.status is status and sol.verdict is verdict
