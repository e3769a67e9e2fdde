"""The stress-grid harness (dualfem.stress) and its report (dualfem report stability)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.grade import grade
from dualfem.experiments import store, stress
from dualfem.experiments.stress import Task


@pytest.mark.parametrize("status,err,kkt,tol,slack,expected", [
    ("solved", 1e-8, 1e-9, 1e-6, 0.0, "correct"),
    ("solved", 1.9e-6, 1e-12, 1e-6, 1e-6, "correct"),       # within tolerance + the reference's bound
    ("solved", 1.9e-6, 1e-12, 1e-6, 0.0, "silent_wrong"),    # the same error, an exact reference
    ("solved", 1e-3, 1e-12, 1e-6, 0.0, "silent_wrong"),      # solved, residuals clean, answer wrong
    ("solved", 1e-3, 1e-2, 1e-6, 0.0, "flagged"),            # the evaluator sees it
    ("solved", 1e-8, 1e-2, 1e-6, 0.0, "flagged"),            # x right, residuals (multipliers) wrong
    ("solved", 1e-3, float("nan"), 1e-6, 0.0, "flagged"),
    ("max_iter", 1e-12, 1e-12, 1e-6, 0.0, "failed"),         # never 'correct' without a solved status
    ("stagnation", 1.0, 1.0, 1e-6, 0.0, "failed"),
    ("skipped", None, None, 1e-6, 0.0, "skipped"),
    ("time_limit", None, None, 1e-6, 0.0, "failed"),
    ("timeout", None, None, 1e-6, 0.0, "timeout"),
    ("solved", None, 1e-12, 1e-6, 0.0, "unverified"),        # no reference
])
def test_one_grading_policy(status, err, kkt, tol, slack, expected):
    assert grade(status, err, kkt, tol, slack) == expected


def test_units_map_the_physics():
    s = stress.scene_in_units(stress.BASE, 1e6, 1e-3)
    assert s["E"] == pytest.approx(6.9e10) and s["delta"] == pytest.approx(1e-5 * 1e-9)
    assert s["width"] == pytest.approx(1e-3) and s["defect"][1][0] == pytest.approx(0.75e-3)


def test_grid_covers_the_issue(monkeypatch):
    tasks = stress.build_grid(["clarabel", "uzawa"], quick=False)
    deltas = {t.coords["delta"] for t in tasks if t.axis == "delta"}
    assert deltas == {1e-12, 1e-9, 1e-6, 1e-3, 1.0, 1e3}
    rs = {t.params["r"] for t in tasks if t.axis == "r"}
    assert rs == {1e0, 1e3, 1e5, 1e7, 1e9, 1e12} and all(t.solver == "uzawa" for t in tasks if t.axis == "r")
    assert {t.coords["nu"] for t in tasks if t.axis == "nu"} == {0.0, 0.3, 0.45, 0.49, 0.4999}
    assert {t.scene["plane"] for t in tasks if t.axis == "nu"} == {"strain"}
    assert min(stress.LOAD_SCALES) == 1e-6 and max(stress.LOAD_SCALES) == 1e6
    assert {t.coords["N"] for t in tasks if t.axis == "N"} == {8, 16, 32, 64, 128, 256, 512, 1024}
    assert len({t.id for t in tasks}) == len(tasks)
    # N chain: each solver's N waits for its previous N
    chain = {t.id: t for t in tasks if t.axis == "N" and t.solver == "uzawa"}
    assert sum(t.after is None for t in chain.values()) == 1
    # units and load runs are graded against the mapped base reference, not a solve of scaled data
    assert all(t.ref["mode"] == "transform" for t in tasks if t.axis in ("units", "load"))


def _tasks():
    base = {**stress.BASE, "N": 8}
    out = []
    for s in ("pdas", "clarabel", "osqp"):
        out.append(Task(id=f"nu:{s}", axis="nu", coords={"nu": 0.3}, scene=base, solver=s, params={},
                        ref={"mode": "solve"}, time_limit=20.0))
        out.append(Task(id=f"load:{s}", axis="load", coords={"load_scale": 1e3}, scene={**base, "load_scale": 1e3},
                        solver=s, params={}, ref={"mode": "transform", "base": base, "x": 1e3, "mu": 1e3},
                        time_limit=20.0))
    return out


def test_run_grid_end_to_end_and_report(tmp_path):
    out = tmp_path / "res"
    recs = stress.run_grid(_tasks(), out, jobs=1)
    assert len(recs) == 6 and all(r.grade == "correct" for r in recs), [
        (r.run_id, r.grade, r.message) for r in recs]
    for r in recs:
        assert r.err_x_energy < 1e-5 and r.ref_solver and r.peak_rss_mb > 0
    # the reference solver (pdas) is graded against the second reference, never itself
    assert next(r for r in recs if r.run_id == "nu:pdas").ref_solver == "clarabel"
    assert "mapped exactly" in next(r for r in recs if r.run_id == "load:osqp").ref_solver
    # the one store of the bench engine: a row file per run and results.csv
    files = {p.name: p.read_bytes() for p in (out / "rows").glob("*.json")}
    assert len(files) == 6 and len(store.read_results(out)) == 6
    assert json.loads((out / "meta.json").read_text())["complete"] and not (out / "runs.jsonl").exists()
    # resume runs nothing again and keeps every record byte for byte
    again = stress.run_grid(_tasks(), out, jobs=1, resume=True)
    assert [r.run_id for r in again] == [r.run_id for r in recs]
    assert {p.name: p.read_bytes() for p in (out / "rows").glob("*.json")} == files

    # a silent wrong answer added by hand must be listed with its scene
    fake = dict(recs[0].to_dict(), run_id="fake", solver="osqp", third_party=True, grade="silent_wrong",
                err_x_energy=0.5, kkt_error=1e-12, status="solved", message="osqp: solved")
    store.write_csv(out / "results.csv", store.read_results(out) + [fake])
    md = tmp_path / "rep" / "stability.md"
    assert main(["report", "stability", str(out), str(md)]) == 0
    text = md.read_text()
    assert "Our solvers: 0" in text and "Third-party solvers: 1" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("| osqp | nu |"))
    assert "load=f2" in line and "N=8" in line
    assert (md.parent / "stability" / "nu.png").stat().st_size > 1000
    assert (md.parent / "stability" / "load.png").exists()


def test_harness_kills_a_run_past_its_hard_limit(tmp_path, monkeypatch):
    # a slow run: the paper's Uzawa with r = 1 at delta = 1e-3 needs ~20000 outer iterations
    monkeypatch.setattr(stress, "hard_limit", lambda task: 0.0)
    slow = Task(id="slow", axis="r", coords={"delta": 1e-3, "r": 1.0}, scene={**stress.BASE, "N": 16, "delta": 1e-3},
                solver="uzawa", params={"r": 1.0}, ref={"mode": "solve"}, time_limit=600.0)
    recs = stress.run_grid([slow], tmp_path / "r", jobs=1)
    assert recs[0].grade == "timeout" and "killed" in recs[0].message


def test_n_axis_skips_with_a_reason_when_too_slow(tmp_path):
    tasks = [t for t in stress.build_grid(["pdas"], quick=True, axes=("N",), max_n=32, time_limit=1e-6)]
    recs = stress.run_grid(tasks, tmp_path / "n", jobs=1)
    by_n = {r["scene"]["N"]: r for r in recs}
    assert by_n[8].grade in ("correct", "failed")
    assert by_n[16].grade == by_n[32].grade == "skipped"
    assert "exceeds" in by_n[16].message or "exceeded" in by_n[16].message
    assert np.isfinite(by_n[8].total_s)
