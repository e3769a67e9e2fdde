"""Convergence curves (dualfem.experiments.curves): the iterate hook, the monitor's sampling and
timing, the errors per sample, curves.csv written by a bench with ``curves = true`` (resume, kills),
and dualfem.results.load's tables and row kinds. Tiny scenes only (f2, N = 8 and 16)."""
from __future__ import annotations

import csv
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.experiments import bench, curves
from dualfem.experiments.curves import COLUMNS, MAX_SAMPLES, CurveStore, IterateMonitor, sample_errors
from dualfem.experiments.runner import run
from dualfem.experiments.spec import load_spec
from dualfem.experiments.store import ResultStore, read_results

SPEC = """
name = "curves_t"
repeats = 1
warmup = false
time_limit = 30
curves = true
[tiers]
high = 1e-8
[floor]
repeats = 1
warmup = false
cholmod = false
[[scenes]]
scene = "f2"
N = [8, 16]
delta = 1e-5
[[solvers]]
name = "uzawa"
[[solvers]]
name = "pdas"
[[solvers]]
name = "osqp"
"""


@pytest.fixture(scope="module")
def qp():
    return load_scene("f2", {"N": 16, "delta": 1e-5}).build()


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    d = tmp_path_factory.mktemp("curves")
    (d / "spec.toml").write_text(SPEC, encoding="utf-8")
    spec = load_spec(d / "spec.toml")
    summary = bench.run_sweep(spec, d / "out", progress=False, stream=open(os.devnull, "w"))
    return spec, d / "out", summary


def curve_rows(out: Path) -> list[dict]:
    with open(out / "curves.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


class Counting(Solver):
    """A fake iterative solver: reports ``iters`` iterates (x = iteration number everywhere)."""

    name = "counting"
    defaults = {"iters": 1000, "sleep": 0.0}

    def solve(self) -> Solution:
        n, m = self.qp.n, self.qp.m

        def slow_x(k):
            time.sleep(self.params["sleep"])
            return np.full(n, float(k))

        for k in range(1, self.params["iters"] + 1):
            self.report_iterate(k, lambda k=k: slow_x(k), np.full(m, float(k)))
        return Solution(solver=self.name, status=Status.MAX_ITER, x=np.full(n, -1.0), multipliers=np.zeros(m),
                        iterations={"it": self.params["iters"]})


# ------------------------------------------------------------------------- the hook and the monitor
def test_the_hook_is_a_no_op_without_a_monitor(qp):
    def never():
        raise AssertionError("evaluated without a monitor")

    s = Counting()
    assert s._iterate_monitor is None
    s.report_iterate(3, never, never)                # nothing is evaluated, nothing raised
    sol = run(Counting(iters=50), qp)
    assert sol.status == Status.MAX_ITER and sol.iterations == {"it": 50}
    a, b = run("pdas", qp), run("pdas", qp, monitor=IterateMonitor(qp.n, qp.m))
    assert np.array_equal(a.x, b.x) and np.array_equal(a.multipliers, b.multipliers)


def test_samples_are_bounded_spread_and_end_with_the_answer(qp):
    mon = IterateMonitor(qp.n, qp.m)
    sol = run(Counting(iters=1000), qp, monitor=mon)
    its = [s.iteration for s in mon.samples]
    assert mon.count == 1000 and len(its) <= MAX_SAMPLES and len(its) >= MAX_SAMPLES // 2
    assert its == sorted(its) and its[0] == 1 and its[-1] == 1000
    assert max(np.diff(its)) <= 2 * 1000 / (MAX_SAMPLES // 2)        # evenly spread over the whole run
    assert np.array_equal(mon.samples[-1].x, sol.x)                  # the last sample is the answer
    for s in mon.samples[:-1]:                                       # copies of the reported iterates
        assert np.all(s.x == s.iteration) and np.all(s.mu == s.iteration)
    times = [s.time_s for s in mon.samples]
    assert times == sorted(times) and times[0] >= sol.time_s["setup"]
    assert times[-1] == pytest.approx(sol.time_s["setup"] + sol.time_s["solve"])
    few = IterateMonitor(qp.n, qp.m)
    run(Counting(iters=3), qp, monitor=few)
    assert [s.iteration for s in few.samples] == [1, 2, 3]           # a short run: every iterate


def test_memory_budget_keeps_fewer_samples_and_says_so():
    big = IterateMonitor(10_000_000, 1000)                           # 80 MB per copy of (x, mu)
    assert big.cap == 3 and "limited to 3 samples" in big.note
    tiny = IterateMonitor(100, 10, budget=1)
    assert tiny.cap == 2
    tiny.start(time.perf_counter())
    for k in range(1, 200):
        tiny.report(k, np.zeros(100), np.zeros(10))
    tiny.finish(np.ones(100), np.ones(10), 1.0)
    assert [s.iteration for s in tiny.samples] == [1, 199]          # the first and the answer


def test_monitor_time_is_excluded_from_solve_time(qp):
    """Each kept sample's x takes 0.1 s to compute (a dual method's x_of): 5 samples, 0.5 s in the
    monitor; the solve itself does nothing. Neither solve_s nor the sample times count it."""
    mon = IterateMonitor(qp.n, qp.m)
    sol = run(Counting(iters=5, sleep=0.1), qp, monitor=mon)
    assert mon.overhead >= 0.5
    assert sol.time_s["solve"] < 0.25
    assert mon.samples[-2].time_s - mon.samples[0].time_s < 0.25


def test_a_bad_iterate_ends_sampling_but_not_the_solve(qp):
    class Bad(Solver):
        name = "bad_iterates"

        def solve(self):
            self.report_iterate(1, np.zeros(self.qp.n), np.zeros(self.qp.m))
            self.report_iterate(2, np.zeros(3), np.zeros(self.qp.m))        # wrong shape
            self.report_iterate(3, np.zeros(self.qp.n), np.zeros(self.qp.m))
            return run("pdas", self.qp)

    mon = IterateMonitor(qp.n, qp.m)
    sol = run(Bad(), qp, monitor=mon)
    assert sol.status == Status.SOLVED
    assert "stopped at iteration 2" in mon.note and "shape (3,)" in mon.note
    assert [s.iteration for s in mon.samples] == [1, 3]               # then only the answer, at the last one
    assert np.array_equal(mon.samples[-1].x, sol.x)


def test_solvers_without_iterates_stay_points(qp):
    mon = IterateMonitor(qp.n, qp.m)
    sol = run("osqp", qp, monitor=mon)
    assert sol.status == Status.SOLVED and mon.count == 0 and not mon.samples
    assert sample_errors(qp, mon, None) is None


@pytest.mark.parametrize("name", ["uzawa", "uzawa_auto", "pdas", "mprgp", "penalty", "dual_gradient"])
def test_every_builtin_iterative_solver_reports_its_iterates(qp, name):
    """Errors along the iterates fall overall; the last one is the answer's KKT error exactly."""
    mon = IterateMonitor(qp.n, qp.m)
    sol = run(name, qp, monitor=mon)
    curve = sample_errors(qp, mon, None)
    errs = [e for _, _, e in curve["samples"]]
    assert sol.status == Status.SOLVED and curve["error_kind"] == "kkt" and 2 <= len(errs) <= MAX_SAMPLES
    assert errs[-1] == evaluator.kkt_error(sol.residuals)
    assert errs[-1] < 1e-3 * errs[0]


# ------------------------------------------------------------------------- a bench with curves = true
def test_bench_writes_curves_that_join_the_runs(sweep):
    spec, out, summary = sweep
    assert summary.statuses == {"solved": 6}
    text = (out / "curves.csv").read_text(encoding="utf-8")
    assert text.splitlines()[0] == ",".join(COLUMNS)
    rows = {r["run_id"]: r for r in read_results(out)}
    recs = curve_rows(out)
    ids = {r["run_id"] for r in recs}
    assert ids and ids <= {k for k, r in rows.items() if r["kind"] == "run"}
    assert {rows[i]["solver"] for i in ids} == {"uzawa", "pdas"}      # osqp: no iterates, a point
    for rid in ids:
        c = [r for r in recs if r["run_id"] == rid]
        row = rows[rid]
        assert all(r["solver"] == row["solver"] and r["tier"] == row["tier"] and r["scene_key"] == row["scene_key"]
                   and r["error_kind"] == "reference" for r in c)
        its, errs = [int(r["iteration"]) for r in c], [float(r["error"]) for r in c]
        assert its == sorted(its) and len(c) == len(set(its)) <= MAX_SAMPLES
        assert float(c[-1]["error"]) == row["err_x_energy"]          # the last sample is the row's answer
        assert float(c[-1]["time_s"]) == pytest.approx(row["setup_s"] + row["solve_s"])
        assert errs[-1] < errs[0] and errs[0] > 1e-3                  # the curve falls from the start
        if row["solver"] == "uzawa":                                  # linear convergence: falls at every step
            assert len(c) >= 4 and all(b < a for a, b in zip(errs, errs[1:]))


def test_resume_keeps_curves_and_never_duplicates(sweep, tmp_path):
    spec, out, _ = sweep
    before = (out / "curves.csv").read_bytes()
    s2 = bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
    assert s2.ran == 0 and (out / "curves.csv").read_bytes() == before
    # a fresh clone (no rows/, no curves/): results.csv and curves.csv alone, resumed: nothing lost or doubled
    clone = tmp_path / "clone"
    clone.mkdir()
    for name in ("results.csv", "curves.csv", "spec.toml"):
        shutil.copy(out / name, clone / name)
    s3 = bench.run_sweep(spec, clone, progress=False, stream=open(os.devnull, "w"))
    assert s3.ran == 0 and sorted(curve_rows(clone), key=str) == sorted(curve_rows(out), key=str)
    assert len(list((clone / "curves").glob("*.json"))) == len({r["run_id"] for r in curve_rows(out)})


def test_a_run_killed_before_its_row_leaves_no_curve(sweep, tmp_path):
    """Curves are kept only with the very row they were written with: a curve file without its row
    (killed between the two writes) is dropped and the run redone, once, with its own curve; a file of
    another attempt falls back to curves.csv's curve of the row there; a curve in curves.csv whose run
    was redone since (its row file newer, no curve) is dropped."""
    spec, out, _ = sweep
    work = tmp_path / "work"
    shutil.copytree(out, work)
    (work / ".lock").unlink(missing_ok=True)
    before = curve_rows(work)
    rid, other, third = list(dict.fromkeys(r["run_id"] for r in before))[:3]
    (work / "rows" / f"{rid}.json").unlink()              # 1. the row never written
    lines = (work / "results.csv").read_text().splitlines(keepends=True)
    (work / "results.csv").write_text("".join(ln for ln in lines if not ln.startswith(rid + ",")))
    cfile = work / "curves" / f"{other}.json"             # 2. a curve file of another attempt of a run
    c = json.loads(cfile.read_text())
    c["started_utc"], c["samples"] = "1999-01-01T00:00:00Z", c["samples"][:1]
    cfile.write_text(json.dumps(c))
    rfile = work / "rows" / f"{third}.json"               # 3. redone since, without a curve
    r = json.loads(rfile.read_text())
    r["started_utc"] = "2999-01-01T00:00:00Z"
    rfile.write_text(json.dumps(r))
    (work / "curves" / f"{third}.json").unlink()
    st = ResultStore(work).open()
    try:
        cs = CurveStore(st).open()
        assert rid not in cs.curves and third not in cs.curves
        assert len(cs.curves[other]["samples"]) == sum(x["run_id"] == other for x in before)
        assert not (work / "curves" / f"{rid}.json").exists()
        assert json.loads(cfile.read_text())["started_utc"] == st.rows[other]["started_utc"]
    finally:
        st.close()
    s2 = bench.run_sweep(spec, work, progress=False, stream=open(os.devnull, "w"))
    assert s2.ran == 1                                    # only the run without a row is redone
    after = curve_rows(work)
    ids = {x["run_id"] for x in after}
    assert rid in ids and third not in ids
    keep = [x for x in before if x["run_id"] not in (rid, third)]
    assert [x for x in after if x["run_id"] not in (rid, third)] == keep
    assert sum(x["run_id"] == rid for x in after) == sum(x["run_id"] == rid for x in before)


def test_curves_off_changes_the_run_ids(tmp_path):
    from dualfem.experiments.tasks import expand_tasks

    (tmp_path / "a.toml").write_text(SPEC, encoding="utf-8")
    (tmp_path / "b.toml").write_text(SPEC.replace("curves = true", "curves = false"), encoding="utf-8")
    on, off = expand_tasks(load_spec(tmp_path / "a.toml")), expand_tasks(load_spec(tmp_path / "b.toml"))
    assert all(t["curves"] for t in on) and not any(t["curves"] for t in off)
    assert not {t["run_id"] for t in on} & {t["run_id"] for t in off}
    (tmp_path / "c.toml").write_text(SPEC.replace("curves = true", "curves = 1"), encoding="utf-8")
    with pytest.raises(InputError, match="curves must be true or false"):
        load_spec(tmp_path / "c.toml")


# ------------------------------------------------------------------------- dualfem.results.load
def test_load_tables_and_kinds(sweep):
    pd = pytest.importorskip("pandas")
    from dualfem import results

    _, out, _ = sweep
    runs = results.load(out)
    assert set(runs["kind"]) == {"run"} and len(runs) == 6
    every = results.load(out, kind="all")
    assert set(every["kind"]) == {"run", "reference", "floor"}
    assert len(results.load(out, kind=None)) == len(every)
    assert set(results.load(out, kind="reference")["kind"]) == {"reference"}
    assert set(results.load(out, kind=["reference", "floor"])["kind"]) == {"reference", "floor"}
    assert len(results.load(out, kind="stress")) == 0
    cv = results.load(out, table="curves")
    assert isinstance(cv, pd.DataFrame) and list(cv.columns) == list(COLUMNS) and len(cv) == len(curve_rows(out))
    assert cv["iteration"].dtype.kind == "i" and cv["time_s"].dtype.kind == "f" and cv["error"].dtype.kind == "f"
    joined = cv.groupby("run_id").tail(1).merge(runs[["run_id", "err_x_energy"]], on="run_id")
    assert len(joined) == cv["run_id"].nunique() and (joined["error"] == joined["err_x_energy"]).all()
    assert len(results.load(out / "curves.csv", table="curves")) == len(cv)


def test_load_without_curves_and_bad_arguments(tmp_path, sweep):
    pytest.importorskip("pandas")
    from dualfem import results

    _, out, _ = sweep
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(out / "results.csv", bare / "results.csv")
    empty = results.load(bare, table="curves")
    assert list(empty.columns) == list(COLUMNS) and len(empty) == 0
    for kw, words in (({"table": "curve"}, "table must be one of runs, curves"),
                      ({"kind": "runs"}, "kind must be one of run, reference, floor, stress, compare"),
                      ({"kind": ["run", 3]}, "kind must be"), ({"kind": []}, "kind must be")):
        with pytest.raises(InputError, match=words):
            results.load(out, **kw)
    with pytest.raises(InputError, match="not a dualfem bench folder"):
        results.load(tmp_path / "nothing", table="curves")


def test_a_damaged_curves_csv_keeps_its_readable_lines(sweep, tmp_path):
    _, out, _ = sweep
    path = tmp_path / "curves.csv"
    lines = (out / "curves.csv").read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-1]) + lines[-1][:10])        # the last line cut by a kill
    warned = []
    recs = curves.read_curves(path, warn=warned.append)
    assert len(recs) == len(lines) - 2 and warned and f"line {len(lines)}" in warned[0].replace("lines", "line")
    path.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="not a dualfem curves.csv"):
        curves.read_curves(path)
