"""qpbenchmark's correct rate of solved claims in the bench and stability reports (known answers)."""
from __future__ import annotations

import math

import pytest

from dualfem.experiments.row import Row
from dualfem.reports._bench_rank import rank_table, ranking
from dualfem.reports._correct_rate import claim_stats, pct
from dualfem.reports._stability_correct import correct_rate_section, solver_stats

TOL = 1e-6


def bench_row(var, scene, status, *, claimed=None, kkt=1e-12, err=1e-10, t=1.0, delta=1e-5, msg=""):
    return {"kind": "run", "variant": var, "solver": var, "scene_key": scene, "tier": "mid", "tol": TOL,
            "status": status, "claimed_status": claimed or status, "kkt_error": kkt, "err_x_energy": err,
            "ref_bound": 1e-12, "total_s": t, "time_limit": 10.0, "scene_delta": delta, "message": msg}


def three_claims_one_wrong():
    """Solver a: 3 solved claims, one of them off the reference (silent wrong), plus 1 honest failure."""
    return [bench_row("a", "s1", "solved"), bench_row("a", "s2", "solved"),
            bench_row("a", "s3", "solved", err=1e-2),
            bench_row("a", "s4", "max_iter", kkt=1e-2, err=1e-1)]


def test_known_answer_two_of_three_claims():
    st = claim_stats(three_claims_one_wrong(), TOL)
    assert (st["runs"], st["claims"], st["certified"], st["silent_wrong"]) == (4, 3, 2, 1)
    assert math.isclose(st["correct_rate"], 2 / 3) and pct(st["correct_rate"]) == "67 %"
    assert math.isclose(st["success_rate"], 2 / 4)
    assert math.isclose(st["agree"], 3 / 4)          # qpbenchmark's formula: 1 - wrong claims / runs


def test_claim_is_the_solvers_word_not_the_certified_status():
    rows = [bench_row("a", "s1", "inaccurate", claimed="solved", kkt=1e-3),   # demoted by the certification
            bench_row("a", "s2", "solved"),
            bench_row("a", "s3", "inaccurate", claimed="inaccurate", kkt=1e-3)]  # honest: no claim
    st = claim_stats(rows, TOL)
    assert (st["claims"], st["certified"], st["demoted"]) == (2, 1, 1)
    assert st["correct_rate"] == 0.5
    # a claim certified to the solver's own looser tolerance but above the tier's: flagged at the tier
    st = claim_stats([bench_row("a", "s1", "solved", kkt=1e-4)], TOL)
    assert (st["claims"], st["certified"], st["flagged"]) == (1, 0, 1)


def test_over_time_is_correct_but_not_a_success():
    rows = [bench_row("a", "s1", "time_limit", claimed="solved", t=12.0,
                    msg="finished in 12 s, over the time limit 10 s (was solved)"),
            bench_row("a", "s2", "solved"),
            bench_row("a", "s3", "skipped")]                                  # skipped: not a run
    st = claim_stats(rows, TOL)
    assert (st["runs"], st["claims"], st["certified"], st["over_time"]) == (2, 2, 2, 1)
    assert st["correct_rate"] == 1.0 and st["success_rate"] == 0.5
    assert math.isnan(claim_stats([bench_row("a", "s1", "error", kkt=None, err=None)], TOL)["correct_rate"])


def test_bench_ranking_per_tier_and_delta():
    rows = three_claims_one_wrong() + [bench_row("b", f"s{i}", "solved", t=2.0) for i in range(1, 5)]
    rows += [bench_row("a", "s5", "solved", delta=1e-9, t=0.5), bench_row("b", "s5", "max_iter", delta=1e-9)]
    stats, ncommon = rank_table(rows, "mid", TOL, shift=10.0, delta=1e-5)
    assert ncommon == 4 and [s["variant"] for s in stats] == ["b", "a"]      # b: 4/4 successes
    a = {s["variant"]: s for s in stats}["a"]
    assert math.isclose(a["correct"], 2 / 3) and a["claims"] == 3
    # over every delta a has 3 of 5 successes, b 4 of 5: b still ranks first
    stats, _ = rank_table(rows, "mid", TOL, shift=10.0)
    assert [(s["variant"], s["success"]) for s in stats] == [("b", 0.8), ("a", 0.6)]
    text = "\n".join(ranking(rows + [{**bench_row("z", "s1", "skipped"), "message": "needs zlib"}], 10.0))
    assert "| 2 | a | 5 | 60 % | 4 | 3 | 75 % | 80 % | 1 silent wrong |" in text
    # per delta (1e-5, 1e-9): the time of successes only; a failed run is never charged a time (was: a's
    # failures at the 10 s time limit made a 2.42 times slower than b at 1e-5, b "20.00" at 1e-9)
    assert "| a | 50 % / 67 % / 1.00 | 100 % / 100 % / 1.00 |" in text
    assert "| b | 100 % / 100 % / 2.00 | 0 % / - / failed |" in text        # no claim: rate undefined
    assert "`z` (needs zlib)" in text


def stress_row(solver, axis, status, grade, claimed=None):
    return Row(kind="stress", solver=solver, axis=axis, status=status, grade=grade,
               claimed_status=claimed or status, coords={}, scene={})


def test_stability_correct_rate_table():
    recs = [stress_row("a", "delta", "solved", "correct"), stress_row("a", "delta", "solved", "correct"),
            stress_row("a", "load", "solved", "silent_wrong"), stress_row("a", "nu", "max_iter", "failed"),
            stress_row("b", "delta", "inaccurate", "failed", claimed="solved"),
            stress_row("b", "load", "solved", "correct"),
            stress_row("b", "nu", "solved", "unverified"),          # no reference: not in the correct rate
            stress_row("c", "delta", "skipped", "skipped")]
    stats = {s["solver"]: s for s in solver_stats(recs)}
    assert math.isclose(stats["a"]["correct_rate"], 2 / 3) and stats["a"]["silent_wrong"] == 1
    assert (stats["b"]["claims"], stats["b"]["demoted"], stats["b"]["unverified"]) == (3, 1, 1)
    assert stats["b"]["correct_rate"] == 0.5 and math.isclose(stats["b"]["agree"], 2 / 3)
    assert stats["c"]["runs"] == 0
    text = "\n".join(correct_rate_section(recs))
    assert "| 1 | a | 4 | 3 | 2 | 67 % | 75 % | 0 | 0 | 1 | 0 |" in text
    assert "| 2 | b | 3 | 3 | 1 | 50 % | 67 % | 1 | 0 | 0 | 1 |" in text
    assert "| b | 0/1 (0 %) | 1/1 (100 %) | 0/0 |" in text
    assert "| a | 2/2 (100 %) | 0/1 (0 %) | 0/0 |" in text                     # per axis: delta, load, nu
    assert "Every run skipped" in text and "`c`" in text


def test_stress_solvers_all():
    from dualfem.cli.stress import _choice
    from dualfem.core.errors import InputError

    assert _choice("--solvers", "all", ["x", "y"], "solver", "known") == ["x", "y"]
    assert _choice("--solvers", "y", ["x", "y"], "solver", "known") == ["y"]
    with pytest.raises(InputError, match="unknown solver 'z'"):
        _choice("--solvers", "x,z", ["x", "y"], "solver", "known")


def test_failed_runs_are_failures_not_times_and_qpbenchmark_is_labelled():
    """A solver that fails fast is shown as failed, not charged the time limit; qpbenchmark's convention
    (failures at the time limit) is its own labelled column."""
    rows = [bench_row("fast", f"s{i}", "solved", t=0.1) for i in range(1, 3)]
    rows += [bench_row("fails", f"s{i}", "inaccurate", claimed="solved", kkt=1e-3, t=0.2) for i in range(1, 3)]
    stats = {s["variant"]: s for s in rank_table(rows, "mid", TOL, shift=10.0)[0]}
    assert stats["fails"]["n_timed"] == 0 and math.isnan(stats["fails"]["sgm"])
    assert math.isclose(stats["fast"]["sgm"], 0.1)
    assert math.isclose(stats["fails"]["sgm_qpb"], 10.0)            # qpbenchmark: at the time limit
    text = "\n".join(ranking(rows, 10.0))
    assert "qpbenchmark convention: failures at the time limit" in text
    assert "| fails | 2 | 0 % |" in text and "failed (no success)" in text
