"""Benchmark sweeps: spec validation, rows and statuses, references, resume after a kill, the
wall-clock guard, joblib and dask executors, the report. Small scenes only (N <= 32)."""
from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dualfem.core.errors import InputError
from dualfem.experiments import bench, harness, store, stress
from dualfem.experiments.progress import Progress
from dualfem.experiments.spec import load_spec
from dualfem.experiments.tasks import expand_scenes, expand_tasks

SMALL = """
name = "t"
repeats = 2
time_limit = 60
[tiers]
low = 1e-3
high = 1e-8
[[scenes]]
scene = ["f1", "f3"]
N = [8, 16]
delta = [1e-3, 1e-9]
[[solvers]]
name = "osqp"
[[solvers]]
name = "clarabel"
tiers = ["high"]
max = {N = 8}
[[solvers]]
name = "no_such_solver_xyz"
optional = true
"""

RUN_STATUSES = {"solved", "inaccurate", "max_iter", "time_limit", "stagnation", "numerical_error", "infeasible",
                "error", "skipped"}


def write(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def run_rows(out: Path) -> dict[str, dict]:
    return {json.loads(p.read_text())["run_id"]: json.loads(p.read_text()) for p in (out / "rows").glob("*.json")}


# ------------------------------------------------------------------ spec validation
@pytest.mark.parametrize("text, words", [
    (SMALL.replace('name = "osqp"', 'name = "osqq"'), ["unknown solver", "osqq"]),
    (SMALL + "\nbogus = 1\n", ["unknown key", "bogus"]),
    (SMALL.replace('tiers = ["high"]', 'tiers = ["ultra"]'), ["tier", "ultra"]),
    (SMALL.replace('name = "clarabel"', 'name = "clarabel"\nparams = {no_param = 1}'), ["no_param"]),
    (SMALL.replace("repeats = 2", "repeats = 0"), ["repeats"]),
    (SMALL.replace("time_limit = 60", "time_limit = -1"), ["time_limit"]),
    (SMALL.replace("low = 1e-3", "low = 0"), ["tier 'low'"]),
])
def test_bad_spec_is_input_error(tmp_path, text, words):
    with pytest.raises(InputError) as exc:
        load_spec(write(tmp_path, text))
    for w in words:
        assert w in str(exc.value)


def test_bad_scene_parameter_is_input_error(tmp_path):
    spec = load_spec(write(tmp_path, SMALL.replace("N = [8, 16]", "N = [8, 1]")))
    with pytest.raises(InputError, match="N"):
        expand_tasks(spec)


def test_cli_bad_spec_exit_2(tmp_path, capsys):
    from dualfem.cli.main import main

    rc = main(["bench", str(write(tmp_path, SMALL.replace('name = "osqp"', 'name = "osqq"'))),
               "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "osqq" in err[0]
    assert main(["bench", str(tmp_path / "missing.toml")]) == 2


def test_task_expansion(tmp_path):
    spec = load_spec(write(tmp_path, SMALL))
    tasks = expand_tasks(spec)
    # 8 scenes x (osqp: 2 tiers, missing solver: 2 tiers) + clarabel (1 tier) on the 4 scenes with N <= 8
    assert len(tasks) == 8 * 4 + 4
    assert len({t["run_id"] for t in tasks}) == len(tasks)
    osqp = [t for t in tasks if t["solver"] == "osqp"]
    assert {t["params"]["tol"] for t in osqp} == {1e-3, 1e-8}      # tiers via tolerance_params
    assert all(t["params"]["time_limit"] == 60.0 for t in osqp)          # solver's own time limit
    clar = [t for t in tasks if t["solver"] == "clarabel"]
    assert len(clar) == 4 and all(t["scene_params"]["N"] == 8 and t["skip"] is None for t in clar)
    missing = [t for t in tasks if t["solver"] == "no_such_solver_xyz"]
    assert all("not registered" in t["skip"] for t in missing)
    # the run id is a function of the run's definition: same spec -> same ids, other repeats -> other ids
    assert [t["run_id"] for t in expand_tasks(spec)] == [t["run_id"] for t in tasks]
    spec3 = load_spec(write(tmp_path, SMALL.replace("repeats = 2", "repeats = 3"), "s3.toml"))
    assert not {t["run_id"] for t in expand_tasks(spec3)} & {t["run_id"] for t in tasks}


# ------------------------------------------------------------------ a whole small sweep
@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    spec = load_spec(write(d, SMALL))
    summary = bench.run_sweep(spec, d / "out", progress=False, stream=open(os.devnull, "w"))
    return spec, d / "out", summary


def test_sweep_rows_and_statuses(small_sweep):
    spec, out, summary = small_sweep
    rows = store.read_results(out / "results.csv")
    runs = [r for r in rows if r["kind"] == "run"]
    assert len(runs) == summary.total == 36
    assert {r["status"] for r in runs} <= RUN_STATUSES
    skipped = [r for r in runs if r["status"] == "skipped"]
    assert len(skipped) == 16 and all("not registered" in r["message"] for r in skipped)
    done = [r for r in runs if r["status"] != "skipped"]
    for r in done:
        assert r["cpu"] and r["cores"] >= 1 and "numpy" in json.loads(r["versions"])
        assert r["repeats_done"] >= 1 and r["setup_s"] >= 0 and r["solve_s"] >= 0
        assert math.isclose(r["setup_s"] + r["solve_s"], r["total_s"], rel_tol=0.5)
        assert len(json.loads(r["solve_s_all"])) == r["repeats_done"]
        if r["status"] == "solved":
            assert r["kkt_error"] is not None and r["err_x_energy"] is not None
            assert r["ref_solver"] in ("pdas", "clarabel")
            assert r["within_tol"] == (r["kkt_error"] <= r["tol"])
    # OSQP at 1e-8 must actually be close to the certified reference on these tiny scenes
    hi = [r for r in done if r["solver"] == "osqp" and r["tier"] == "high" and r["status"] == "solved"]
    assert hi and max(r["err_x_energy"] for r in hi) < 1e-4
    refs = [r for r in rows if r["kind"] == "reference"]
    assert len(refs) == 8 and all(r["status"] == "solved" and r["kkt_error"] <= 1e-8 for r in refs)
    assert len(list((out / "refs").glob("*.npz"))) == 8
    floors = [r for r in rows if r["kind"] == "floor"]
    assert {r["scene_N"] for r in floors} == {8, 16} and all(r["total_s"] > 0 for r in floors)


def test_rerun_recomputes_nothing(small_sweep):
    spec, out, _ = small_sweep
    before = {p.name: p.read_bytes() for p in (out / "rows").glob("*.json")}
    s2 = bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
    assert s2.ran == 0 and s2.aux == 0                      # no run, reference or floor redone
    after = {p.name: p.read_bytes() for p in (out / "rows").glob("*.json")}
    for name, data in before.items():                       # every finished row kept byte for byte
        if json.loads(data)["status"] != "skipped":
            assert after[name] == data


def test_report(small_sweep, tmp_path):
    from dualfem.reports.bench import build_report

    _, out, _ = small_sweep
    md = build_report(out / "results.csv", tmp_path / "benchmark.md", tmp_path / "bench", ours=["osqp"])
    assert "## Performance targets" not in md.read_text()       # dualfem's own checklist only when asked
    md = build_report(out / "results.csv", tmp_path / "benchmark.md", tmp_path / "bench", ours=["osqp"],
                      show_targets=True)
    text = md.read_text()
    for section in ("## Machine and versions", "## Per tolerance tier", "### tier high", "## Performance targets",
                    "## Work-precision", "## Scaling", "shifted GM", "dualfem bench"):
        assert section in text
    pngs = sorted(p.name for p in (tmp_path / "bench").glob("*.png"))
    assert "wp_f1_N16.png" in pngs and "scaling_f3.png" in pngs
    assert all((tmp_path / "bench" / p).stat().st_size > 1000 for p in pngs)


def test_report_cli(small_sweep, tmp_path):
    from dualfem.cli.main import main

    _, out, _ = small_sweep
    assert main(["report", "bench", "--", str(out), "--md", str(tmp_path / "b.md"),
                 "--figdir", str(tmp_path / "f")]) == 0
    assert (tmp_path / "b.md").is_file()
    assert main(["report", "bench", str(tmp_path / "nothing.csv")]) == 2


def test_tier_statistics_by_hand():
    from dualfem.reports.bench import tier_table

    def row(var, scene, status, kkt, t):
        return {"variant": var, "scene_key": scene, "tier": "x", "status": status, "kkt_error": kkt,
                "total_s": t, "time_limit": 100.0, "err_x_energy": 1e-9}

    runs = [row("a", "s1", "solved", 1e-9, 1.0), row("a", "s2", "solved", 1e-3, 2.0),     # 2nd: claims, wrong
            row("b", "s1", "solved", 1e-9, 4.0), row("b", "s2", "max_iter", 1e-3, 3.0),    # honest failure
            row("c", "s1", "solved", 1e-9, 0.5)]                                           # s2 not run by c
    stats, ncommon = tier_table(runs, "x", 1e-6, shift=10.0)
    s = {d["variant"]: d for d in stats}
    assert ncommon == 1                                       # only s1 was run by every solver
    assert s["a"]["success"] == 0.5 and s["a"]["correct"] == 0.5
    assert s["b"]["success"] == 0.5 and s["b"]["correct"] == 1.0
    assert s["c"]["sgm_rel"] == 1.0
    assert math.isclose(s["b"]["sgm"], 4.0) and math.isclose(s["b"]["sgm_rel"], 4.0 / 0.5)
    # a failed run is never charged a time; qpbenchmark's convention (at the time limit) is its own column
    stats2, _ = tier_table([row("a", "s1", "solved", 1e-9, 1.0), row("b", "s1", "error", None, 0.1)], "x", 1e-6, 10.0)
    b = {d["variant"]: d for d in stats2}["b"]
    assert math.isnan(b["sgm"]) and b["n_timed"] == 0 and math.isclose(b["sgm_qpb"], 100.0)


# ------------------------------------------------------------------ failed references
def test_failed_reference_is_never_cached(tmp_path):
    text = SMALL.replace('N = [8, 16]', 'N = [8]').replace('delta = [1e-3, 1e-9]', 'delta = [1e-3]') \
        .replace('scene = ["f1", "f3"]', 'scene = "f1"') + \
        '\n[reference]\nsolvers = ["clarabel"]\nparams = {clarabel = {max_iter = 1}}\n'
    out = tmp_path / "out"
    for reps in (2, 1):    # the 2nd sweep has new runs on the same scene
        spec = load_spec(write(tmp_path, text.replace("repeats = 2", f"repeats = {reps}")))
        if reps == 1:      # the same name, other contents: refused without --force
            with pytest.raises(InputError, match="other contents"):
                bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
        s = bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"), force=reps == 1)
        assert s.refs == 1                                  # the failed reference is tried again every time
        assert not list((out / "refs").glob("*.npz"))
        rows = store.read_results(out)
        ref = [r for r in rows if r["kind"] == "reference"]
        assert len(ref) == 1 and ref[0]["status"] == "error" and "no certified reference" in ref[0]["message"]
        assert "max_iter" in ref[0]["message"]
        # (clarabel's `solved` at the 1e-8 tier is `inaccurate` since its multipliers are certified too:
        # 1.2e-8 off on f1, N = 8, issue 26)
        runs = [r for r in rows if r["kind"] == "run" and r["status"] in ("solved", "inaccurate")]
        assert len(runs) == 3 * (3 - reps)     # results.csv keeps the rows of the first version too
        assert all(r["err_x_energy"] is None and "no certified reference" in r["message"] for r in runs)


# ------------------------------------------------------------------ wall-clock guard
def test_guard_kills_a_run_over_its_budget(tmp_path):
    spec = load_spec(write(tmp_path, SMALL))
    task = next(t for t in expand_tasks(spec) if t["solver"] == "clarabel" and not t["skip"])
    task = {**task, "scene_params": {"N": 32, "delta": 1e-9}, "hard_limit": 1e-4, "ref": None}
    w = harness.GuardedWorker()
    try:
        row, payload = w.run(task)
        assert row["status"] == "time_limit" and "wall-clock guard" in row["message"] and payload is None
        assert w.proc is None                                 # the child was killed
        ok, _ = w.run({**task, "scene_params": {"N": 8, "delta": 1e-3}, "hard_limit": 60.0})
        assert ok["status"] in ("solved", "inaccurate") and ok["n_unknowns"] > 0   # a fresh child serves on
    finally:
        w.close()


def test_worker_exception_becomes_error_row(tmp_path):
    spec = load_spec(write(tmp_path, SMALL))
    task = next(t for t in expand_tasks(spec) if t["solver"] == "osqp")
    row, _ = harness.run_guarded({**task, "scene": "no_such_scene", "ref": None})
    assert row["status"] == "error" and "no_such_scene" in row["message"]
    harness._close_local_worker()


# ------------------------------------------------------------------ kill and resume
RESUME = """
name = "resume"
repeats = 2
time_limit = 60
[tiers]
low = 1e-3
high = 1e-8
[floor]
enabled = false
[[scenes]]
scene = ["f1", "f2", "f3"]
N = [8, 16]
delta = [1e-3, 1e-9]
[[solvers]]
name = "osqp"
[[solvers]]
name = "clarabel"
tiers = ["high"]
"""


def _session_pids(sid: int) -> list[int]:
    """Live processes of a session (Linux /proc)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(d.name))
    return pids


def test_resume_after_killing_a_sweep(tmp_path):
    spec_path = write(tmp_path, RESUME)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "dualfem", "bench", str(spec_path), "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    total = len(expand_tasks(load_spec(spec_path)))
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            n = [p for p in (out / "rows").glob("*.json") if not p.name.startswith(("ref-", "floor-", "."))] \
                if (out / "rows").is_dir() else []
            if len(n) >= 3 or proc.poll() is not None:
                break
            time.sleep(0.005)
        assert proc.poll() is None, "the sweep finished before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)                   # kill -9 of the sweep alone
        proc.wait()
        deadline = time.monotonic() + 15                    # its worker dies with it: no orphans
        while _session_pids(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _session_pids(proc.pid), "a worker process outlived the killed sweep"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    # whatever was written is complete: every row file parses, the CSV (if any) parses
    kept = {}
    for p in (out / "rows").glob("[!.]*.json"):
        r = json.loads(p.read_text())
        kept[r["run_id"]] = p.read_bytes()
    if (out / "results.csv").exists():
        with open(out / "results.csv", newline="") as fh:
            list(csv.DictReader(fh))
    finished_runs = [k for k, v in kept.items() if not k.startswith(("ref-", "floor-"))
                     and json.loads(v)["status"] in store.FINAL_STATUSES]
    assert 3 <= len(finished_runs) < total
    (out / ".gitignore").write_text("rows/\n")              # a user's file in the results directory
    # run again: completes the sweep, recomputes nothing finished
    s = bench.run_sweep(load_spec(spec_path), out, progress=False, stream=open(os.devnull, "w"))
    assert s.total == total and s.skipped_done == len(finished_runs) and s.ran == total - len(finished_runs)
    for rid in finished_runs:
        assert (out / "rows" / f"{rid}.json").read_bytes() == kept[rid]
    rows = store.read_results(out)
    assert {r["run_id"] for r in rows if r["kind"] == "run"} == {t["run_id"] for t in
                                                                 expand_tasks(load_spec(spec_path))}
    # no temporary file left (.lock is the folder's lock file, released, not a result)
    assert sorted(p.name for p in out.rglob(".*") if p.is_file()) == [".gitignore", ".lock"]


# ------------------------------------------------------------------ executors
PAR = SMALL.replace('N = [8, 16]', 'N = [8]').replace("repeats = 2", "repeats = 1")


def _statuses(out: Path) -> dict[str, str]:
    return {r["run_id"]: r["status"] for r in store.read_results(out)}


@pytest.fixture(scope="module")
def serial_par(tmp_path_factory):
    d = tmp_path_factory.mktemp("par")
    spec = load_spec(write(d, PAR))
    bench.run_sweep(spec, d / "serial", progress=False, stream=open(os.devnull, "w"))
    return spec, _statuses(d / "serial")


def test_joblib_executor(serial_par, tmp_path):
    pytest.importorskip("joblib")
    spec, expected = serial_par
    s = bench.run_sweep(spec, tmp_path / "out", jobs=2, progress=False, stream=open(os.devnull, "w"))
    assert s.skipped_done == 0 and s.ran == 12 and _statuses(tmp_path / "out") == expected


def test_dask_executor_on_local_cluster(serial_par, tmp_path):
    distributed = pytest.importorskip("distributed")
    spec, expected = serial_par
    with distributed.LocalCluster(processes=False, n_workers=1, threads_per_worker=1, host="127.0.0.1",
                                  protocol="tcp", dashboard_address=None) as cluster:      # loopback TCP
        s = bench.run_sweep(spec, tmp_path / "out", dask=cluster.scheduler_address, progress=False,
                            stream=open(os.devnull, "w"))
    harness._close_local_worker()
    assert s.skipped_done == 0 and s.ran == 12 and _statuses(tmp_path / "out") == expected


def test_dask_bad_address_is_input_error(tmp_path, capsys):
    """A scheduler address nobody listens on is refused: an InputError naming --dask, within the
    ``connect_timeout`` given (harness default 20 s), before anything is written; on the command
    line (``--dask-timeout``) one error line and exit 2. A malformed address too."""
    pytest.importorskip("distributed")
    from dualfem.cli.main import main

    spec = load_spec(write(tmp_path, PAR))                   # no sweep needed: the connection fails first
    t0 = time.monotonic()
    with pytest.raises(InputError, match="--dask.*within 1 s"):
        bench.run_sweep(spec, tmp_path / "out", dask="tcp://127.0.0.1:9", progress=False,
                        stream=open(os.devnull, "w"), connect_timeout=1.0)
    assert time.monotonic() - t0 < 10, "the 1 s connect timeout did not reach dask"
    assert not (tmp_path / "out").exists()                   # refused before anything is written
    with pytest.raises(InputError, match="--dask"):
        stress.run_grid([], tmp_path / "grid", dask="tcp://127.0.0.1:9", connect_timeout=1.0)
    assert not (tmp_path / "grid").exists()
    capsys.readouterr()
    for addr in ("tcp://127.0.0.1:9", "tcp://127.0.0.1:notaport"):
        t0 = time.monotonic()
        rc = main(["bench", str(tmp_path / "spec.toml"), "--dask", addr, "--dask-timeout", "1",
                   "--out", str(tmp_path / "cli")])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and err.startswith("dualfem bench: error: --dask"), err
        assert time.monotonic() - t0 < 10 and not (tmp_path / "cli").exists()


# ------------------------------------------------------------------ progress
def test_progress_plain_lines_and_bar():
    import io

    s = io.StringIO()
    p = Progress(2, "x", s, tty=False)
    p.update("one")
    p.update("two")
    assert s.getvalue().count("\n") == 2 and "[1/2] one" in s.getvalue() and "[2/2] two" in s.getvalue()
    s = io.StringIO()
    p = Progress(2, "x", s, tty=True)
    p.update("one")
    assert "\r" in s.getvalue() and "\n" not in s.getvalue()
    p.update("two")
    assert s.getvalue().endswith("\n")


def test_shipped_specs_are_valid():
    root = Path(__file__).resolve().parent.parent / "benchmarks"
    for name in ("default.toml", "small.toml", "target.toml"):
        spec = load_spec(root / name)
        tasks = expand_tasks(spec)
        assert tasks and len({t["run_id"] for t in tasks}) == len(tasks)
    spec = load_spec(root / "default.toml")
    scenes = expand_scenes(spec)
    from dualfem.core.scene import library

    assert {s.scene for s in scenes} == {"f1", "f2", "f3"} | set(library(dim=2))   # the 2D scene library too
    assert {1e-1, 1e-3, 1e-5, 1e-7, 1e-9} <= {s.params.get("delta") for s in scenes}
    assert max(s.params.get("N", 0) for s in scenes) >= 512


def test_solver_block_time_limit_and_repeats(tmp_path):
    text = SMALL.replace('name = "clarabel"\ntiers = ["high"]',
                         'name = "clarabel"\ntiers = ["high"]\ntime_limit = 7.5\nrepeats = 1')
    spec = load_spec(write(tmp_path, text))
    tasks = expand_tasks(spec)
    clar = [t for t in tasks if t["solver"] == "clarabel"]
    osqp = [t for t in tasks if t["solver"] == "osqp"]
    assert all(t["time_limit"] == 7.5 and t["params"]["time_limit"] == 7.5 and t["repeats"] == 1 for t in clar)
    assert all(t["repeats"] == 2 for t in tasks if t["solver"] != "clarabel")
    assert all(t["hard_limit"] == 7.5 * spec.guard_factor + spec.guard_slack for t in clar)
    assert all(t["time_limit"] == 60.0 and t["hard_limit"] == spec.hard_limit for t in osqp)
    # a block without its own limit keeps the run ids it had before the option existed
    plain = {t["run_id"] for t in expand_tasks(load_spec(write(tmp_path, SMALL, "s0.toml")))}
    assert {t["run_id"] for t in osqp} <= plain and not {t["run_id"] for t in clar} & plain
    with pytest.raises(InputError, match="time_limit of solver 'clarabel'"):
        load_spec(write(tmp_path, text.replace("time_limit = 7.5", "time_limit = 0"), "bad.toml"))
    with pytest.raises(InputError, match="repeats of solver 'clarabel'"):
        load_spec(write(tmp_path, text.replace("repeats = 1", "repeats = 1.5"), "bad2.toml"))


def test_report_merges_sweeps_later_wins(small_sweep, tmp_path):
    from dualfem.reports.bench import build_report, load_sources

    _, out, _ = small_sweep
    rows = store.read_results(out / "results.csv")
    redo = next(r for r in rows if r["kind"] == "run" and r["solver"] == "osqp" and r["status"] == "solved")
    second = tmp_path / "second"
    second.mkdir()
    store.write_csv(second / "results.csv", [{**redo, "status": "error", "message": "redone by a later sweep"}])
    merged, sources = load_sources([out, second])
    assert len(merged) == len(rows) and [s["kept"] for s in sources] == [len(rows) - 1, 1]
    again = [r for r in merged if r["run_id"] == redo["run_id"]]
    assert len(again) == 1 and again[0]["status"] == "error" and again[0]["_source"] == 1
    assert len(load_sources([second, out])[0]) == len(rows)    # order matters: the earlier one is replaced
    assert next(r for r in load_sources([second, out])[0] if r["run_id"] == redo["run_id"])["status"] == "solved"
    text = build_report([out, second], tmp_path / "b.md", tmp_path / "f", ours=["osqp"]).read_text()
    assert "[1]" in text and "[2]" in text and "merged" in text and "redone by a later sweep" in text


def test_targets_table_by_hand():
    from dualfem.reports.bench import targets

    def run(solver, status, t, err, delta=1e-9):
        return {"kind": "run", "scene": "f2", "scene_N": 1024, "scene_delta": delta, "solver": solver,
                "variant": solver, "tier": "high", "status": status, "total_s": t, "setup_s": t - 1,
                "solve_s": 1.0, "err_x_energy": err, "time_limit": 900.0, "message": "proximal bound 3e-7",
                "assembly_s": 4.0, "peak_rss_mb": 4800.0}

    floors = [{"kind": "floor", "scene_N": 1024, "status": "solved", "total_s": 80.0, "solver": "floor_cholmod"}]
    runs = [run("pdas", "solved", 88.0, 0.0), run("uzawa", "inaccurate", 96.0, 2.5e-10),
            run("uzawa_auto", "solved", 130.0, 1e-10), run("osqp", "solved", 900.0, 7e-10),
            run("clarabel", "time_limit", 1150.0, 1e-2)]
    text = "\n".join(targets(runs, floors, ["pdas", "uzawa", "uzawa_auto"], 1e-8, 1.5, 10.0))
    assert "| pdas | 88 (87 + 1) | 92 | 4800 | 80 (cholmod) | 1.10 ok | 900 (osqp, tier high) | 10.2 ok |" in text
    assert "uzawa | status inaccurate: error 2.5e-10 in 96 s (1.20 x the floor), not claimed" in text
    assert "uzawa_auto at f2 N=1024 delta=1e-09: 1.62 x the floor" in text       # over 1.5: missed, with why
    assert "6.9 x faster than osqp (target 10 x: 31 % short)" in text and "Targets missed (3)" in text


# ------------------------------------------------------------------ nothing lost
def test_rows_kept_only_in_results_csv_survive_a_new_sweep(small_sweep, tmp_path):
    """rows/ is not committed: a sweep on a fresh clone must keep the committed results.csv rows."""
    import shutil

    spec, out, _ = small_sweep
    clone = tmp_path / "clone"
    clone.mkdir()
    shutil.copy(out / "results.csv", clone / "results.csv")
    shutil.copy(out / "spec.toml", clone / "spec.toml")
    before = {r["run_id"]: r["status"] for r in store.read_results(clone)}
    s = bench.run_sweep(spec, clone, progress=False, stream=open(os.devnull, "w"))
    after = {r["run_id"]: r["status"] for r in store.read_results(clone)}
    assert s.ran == 0 and before == after             # nothing recomputed, nothing dropped


def test_results_folder_belongs_to_one_spec_and_is_locked(small_sweep, tmp_path):
    spec, out, _ = small_sweep
    other = load_spec(write(tmp_path, SMALL.replace('name = "t"', 'name = "other"'), "other.toml"))
    before = (out / "results.csv").read_bytes()
    with pytest.raises(InputError, match="another spec"):
        bench.run_sweep(other, out, progress=False, stream=open(os.devnull, "w"))
    assert (out / "results.csv").read_bytes() == before
    from dualfem.experiments.store import lock_folder

    with lock_folder(out), pytest.raises(InputError, match="in use by another running sweep"):
        bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
    assert (out / "results.csv").read_bytes() == before


@pytest.mark.parametrize("name", ["../escape", "/abs", "a/b", ".hidden", ""])
def test_unsafe_spec_names_are_refused(name):
    from dualfem.experiments.store import default_out

    with pytest.raises(InputError, match="results folder"):
        default_out("bench", name)


def test_results_load_as_a_dataframe(small_sweep):
    """dualfem.results.load: one row per run with the Row columns; parquet beside results.csv."""
    pd = pytest.importorskip("pandas")
    from dualfem import results

    spec, out, summary = small_sweep
    df = results.load(out, kind="all")
    runs = df[df["kind"] == "run"]
    assert len(runs) == summary.total and list(df.columns[:3]) == ["run_id", "kind", "spec"]
    assert results.load(out)["run_id"].tolist() == runs["run_id"].tolist()      # the default: runs only
    assert runs["total_s"].dtype.kind == "f" and set(runs["status"]) <= RUN_STATUSES
    import importlib.util

    if importlib.util.find_spec("pyarrow") is not None:      # written whenever pyarrow is installed
        pq = pd.read_parquet(out / "results.parquet")
        assert set(pq["run_id"]) == set(df["run_id"])
    with pytest.raises(InputError, match="not a dualfem bench folder"):
        results.load(out / "rows")


def test_stress_results_load_as_a_dataframe(tmp_path):
    pytest.importorskip("pandas")
    from dualfem import results

    (tmp_path / "runs.jsonl").write_text('{"id": "a", "axis": "nu", "outcome": "correct", "solver": "pdas", '
                                         '"status": "solved", "err": 1e-12, "tolerance": 1e-9, "kkt": 1e-13}\n')
    df = results.load(tmp_path, kind="stress")
    assert df.loc[0, "grade"] == "correct" and df.loc[0, "err_x_energy"] == 1e-12


def test_method_text_follows_the_specs_warmup(tmp_path):
    from dualfem.reports.bench import _method

    def text(spec: str) -> str:
        d = tmp_path / str(abs(hash(spec)))
        d.mkdir()
        (d / "spec.toml").write_text(spec, encoding="utf-8")
        return " ".join(_method([], 10.0, [{"dir": d}]))

    assert "after no warm-up run" in text('warmup = false\n[[scenes]]\nscene = "f1"\n')
    assert "after one untimed warm-up run." in text('[[scenes]]\nscene = "f1"\n')
    assert "in some scene blocks, none in others" in text(
        '[[scenes]]\nscene = "f1"\n[[scenes]]\nscene = "f2"\nwarmup = false\n')


def _clone(out: Path, dest: Path) -> Path:
    """results.csv and spec.toml of a sweep (a fresh clone: no rows/, no refs/)."""
    import shutil

    dest.mkdir()
    shutil.copy(out / "results.csv", dest / "results.csv")
    shutil.copy(out / "spec.toml", dest / "spec.toml")
    return dest


def test_a_damaged_results_csv_loses_no_readable_row(small_sweep, tmp_path, capsys):
    """A results.csv cut by a kill (or with a damaged line, undecodable bytes) is read without a
    traceback by read_results, dualfem.results.load and dualfem report bench (a warning naming the
    lines, nothing changed on disk); a sweep resumed on it keeps every readable row, keeps the damaged
    file aside under a new name (an earlier one untouched) and redoes only the runs of the bad lines."""
    from dualfem.cli.main import main

    spec, out, _ = small_sweep
    good = store.read_results(out)
    clone = _clone(out, tmp_path / "clone")
    text = (clone / "results.csv").read_bytes()
    lines = text.splitlines(keepends=True)
    k = next(i for i, r in enumerate(good) if r["kind"] == "run") + 1      # a run's line; the last is a run too
    damaged_id = good[k - 1]["run_id"]
    damaged = lines[:k] + [lines[k][:40] + b"\n"] + lines[k + 1:-1] + [lines[-1][: len(lines[-1]) // 2]]
    (clone / "results.csv").write_bytes(b"".join(damaged))
    (clone / "results.csv.corrupt-20200101T000000Z").write_text("an earlier copy kept aside\n")
    before_csv = (clone / "results.csv").read_bytes()
    rows = store.read_results(clone)
    err = capsys.readouterr().err
    assert len(rows) == len(good) - 2 and "2 unreadable line(s)" in err and f"lines {k + 1}, " in err
    assert damaged_id not in {r["run_id"] for r in rows}
    pytest.importorskip("pandas")
    from dualfem import results

    assert len(results.load(clone, kind=None)) == len(good) - 2
    assert main(["report", "bench", str(clone), "--md", str(tmp_path / "rep" / "b.md")]) == 0
    assert "unreadable line" in capsys.readouterr().err
    assert (clone / "results.csv").read_bytes() == before_csv            # reading changes nothing
    # the sweep resumed on it: readable rows kept, damaged file kept aside, the two bad runs redone
    warned = []
    st = store.ResultStore(clone, warn=warned.append).open()
    st.close()
    assert len(warned) == 1 and "kept as" in warned[0]
    asides = sorted(p.name for p in clone.glob("results.csv.corrupt-*"))
    assert len(asides) == 2 and (clone / "results.csv.corrupt-20200101T000000Z").read_text().startswith("an earlier")
    kept_aside = next(clone / n for n in asides if not n.endswith("20200101T000000Z"))
    assert kept_aside.read_bytes() == before_csv
    assert {r["run_id"] for r in store.read_results(clone)} == {r["run_id"] for r in rows}
    cut_log = '{"invocations": [{"command": "dualfem bench'
    (clone / "sweep.json").write_text(cut_log)                          # the invocation log cut too
    s = bench.run_sweep(spec, clone, progress=False, stream=open(os.devnull, "w"))
    assert s.ran + s.aux <= 4                                # only the runs of the damaged lines
    assert [p.read_text() for p in clone.glob("sweep.json.corrupt-*")] == [cut_log]
    assert len(json.loads((clone / "sweep.json").read_text())["invocations"]) == 1
    after = {r["run_id"]: r for r in store.read_results(clone)}
    assert {r["run_id"] for r in good} <= set(after)
    for r in rows:          # every readable row kept as it was (a reference of refs/, not cloned, is recomputed)
        if r["kind"] == "reference":
            continue
        assert (after[r["run_id"]]["status"], after[r["run_id"]]["total_s"]) == (r["status"], r["total_s"]), r


@pytest.mark.parametrize("garbage", [b"", b"run_id\n", b"\xff\xfe\x00\x00garbage", b"name,age\nada,36\n"])
def test_results_csv_without_a_header_is_moved_aside_not_a_traceback(tmp_path, garbage):
    (tmp_path / "results.csv").write_bytes(garbage)
    with pytest.raises(InputError, match="results.csv"):
        store.read_results(tmp_path)
    warned = []
    st = store.ResultStore(tmp_path / ".", warn=warned.append).open()
    st.close()
    assert not (tmp_path / "results.csv").exists() and len(warned) == 1
    assert [p.read_bytes() for p in tmp_path.glob("results.csv.corrupt-*")] == [garbage]


def test_set_aside_and_backup_names_never_collide(tmp_path):
    """Two copies kept aside in one second get two names; an existing one is never replaced."""
    from dualfem.core.io import backup, move_aside, write_aside

    p = tmp_path / "results.csv"
    names = []
    for i in range(3):
        p.write_text(f"version {i}\n")
        names.append(backup(p, "bak"))
    for i in range(3):
        p.write_text(f"moved {i}\n")
        names.append(move_aside(p, "corrupt"))
        names.append(write_aside(p, "corrupt", f"lines {i}\n"))
    assert len(set(names)) == 9 and all(n.parent == tmp_path for n in names)
    texts = sorted(n.read_text() for n in names)
    assert texts == sorted([f"version {i}\n" for i in range(3)] + [f"moved {i}\n" for i in range(3)]
                           + [f"lines {i}\n" for i in range(3)])


def test_a_spec_of_the_same_name_with_other_contents_is_refused(small_sweep, tmp_path, capsys):
    """Same-name bench spec (issue 26, item 5): a spec whose name matches the folder's but whose contents
    differ (another spec, or an edited one) is refused before anything is written; --force adds its rows
    and keeps every earlier row and the earlier spec.toml (a new backup name each time). The same spec
    with other comments or spacing is the same spec."""
    from dualfem.cli.main import main

    spec, out, _ = small_sweep
    clone = _clone(out, tmp_path / "clone")
    first = {r["run_id"] for r in store.read_results(clone)}
    before = {p.name: p.read_bytes() for p in clone.iterdir()}
    other = write(tmp_path, PAR.replace('name = "t"', 'name = "t"  # same name').replace('"f3"', '"f2"'), "o.toml")
    with pytest.raises(InputError, match="named 't' with other contents.*--force"):
        bench.run_sweep(load_spec(other), clone, progress=False, stream=open(os.devnull, "w"))
    capsys.readouterr()
    assert main(["bench", str(other), "--out", str(clone), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "other contents" in err
    assert {p.name: p.read_bytes() for p in clone.iterdir()} == before          # nothing written
    # the same spec, reformatted, is accepted (nothing to do)
    same = write(tmp_path, "# a comment\n" + SMALL.replace("repeats = 2", "repeats   =   2"), "same.toml")
    s = bench.run_sweep(load_spec(same), clone, progress=False, stream=open(os.devnull, "w"))
    assert s.ran == 0 and not list(clone.glob("spec.toml.*"))
    # --force: every row kept, the old spec.toml kept under a new name (twice in one second: two names)
    for i in range(2):
        bench.run_sweep(load_spec(other if i == 0 else same), clone, progress=False, stream=open(os.devnull, "w"),
                        force=True)
    kept = sorted(clone.glob("spec.toml.replaced-*"))
    assert len(kept) == 2 and {p.read_text() for p in kept} == {(clone / "spec.toml").read_text(),
                                                                other.read_text()}
    assert first <= {r["run_id"] for r in store.read_results(clone)}


# ------------------------------------------------------------------ cached references are checked
REFCHECK = """
name = "refcheck"
repeats = 1
warmup = false
time_limit = 60
[tiers]
low = 1e-3
high = 1e-8
[floor]
enabled = false
[[scenes]]
scene = "f1"
N = 8
delta = 1e-3
[[solvers]]
name = "osqp"
[[solvers]]
name = "pdas"
"""


@pytest.fixture(scope="module")
def refcheck_base(tmp_path_factory) -> Path:
    """One untampered REFCHECK sweep (its results folder), copied by each test that attacks it."""
    base = tmp_path_factory.mktemp("refcheck")
    bench.run_sweep(load_spec(write(base, REFCHECK)), base / "out", progress=False, stream=open(os.devnull, "w"))
    return base / "out"


def _refcheck_copy(base: Path, tmp_path: Path):
    shutil.copytree(base, tmp_path / "out")
    return load_spec(write(tmp_path, REFCHECK)), tmp_path / "out"


def _forget_runs(out: Path) -> None:
    """Drop the run rows (rows/ and results.csv) so that the next sweep runs them again."""
    keep = [r for r in store.read_results(out) if r["kind"] != "run"]
    for p in (out / "rows").glob("*.json"):
        if json.loads(p.read_text())["kind"] == "run":
            p.unlink()
    store.write_csv(out / "results.csv", keep)


@pytest.mark.parametrize("attack", ["content", "forged_hash", "forged_bound", "other_qp"])
def test_a_tampered_cached_reference_never_changes_a_grade(tmp_path, attack, refcheck_base):
    """refs/*.npz is checked before anything is graded against it: its content hash (in the parent),
    then its KKT error and certified error recomputed against the scene's QP (in a worker). A file
    that fails is moved aside (a new name, with a warning) and the reference recomputed: the grades
    and errors are those of the untampered sweep."""
    import numpy as np

    spec, out = _refcheck_copy(refcheck_base, tmp_path)
    graded = {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "run"}
    assert len(graded) == 4 and all(r["err_x_energy"] is not None for r in graded.values())
    (ref_file,) = (out / "refs").glob("*.npz")
    st = store.ResultStore(out)
    ref = st.load_ref(ref_file.stem)
    ref["params"] = ref.get("params", "{}")
    if attack == "content":                  # the numbers changed, the hash not
        ref["x"] = ref["x"] * 1.01
        digest = ref["sha256"]
    elif attack == "forged_hash":            # the numbers changed and the hash recomputed to match
        ref["x"] = ref["x"] * 1.01
        digest = store.ref_hash(ref)
    elif attack == "forged_bound":           # a huge certified bound: every run would grade correct
        ref["bound"], ref["kkt"] = 1e3, 1e-20
        ref["x"] = ref["x"] * 1.01
        digest = store.ref_hash(ref)
    else:                                    # a reference of another QP under this scene's name
        ref["qp_key"] = "0123456789abcdef"
        digest = store.ref_hash(ref)
    with open(ref_file, "wb") as fh:
        np.savez(fh, x=ref["x"], multipliers=ref["multipliers"], qp_key=np.array(ref["qp_key"]),
                 solver=np.array(ref["solver"]), kkt=np.array(ref["kkt"]), bound=np.array(ref["bound"]),
                 params=np.array(ref["params"]), sha256=np.array(digest))
    tampered = ref_file.read_bytes()
    _forget_runs(out)
    warned = []
    bench_store = bench.ResultStore

    class Recording(bench_store):
        def __init__(self, out, warn=None):
            super().__init__(out, warn=warned.append)

    try:
        bench.ResultStore = Recording
        s = bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
    finally:
        bench.ResultStore = bench_store
    assert s.refs == 1 and s.ran == 4                       # the reference was recomputed
    assert warned and any("recomputed" in w for w in warned), warned
    again = {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "run"}
    for rid, r in graded.items():
        assert again[rid]["grade"] == r["grade"], (rid, r["grade"], again[rid]["grade"])
        assert again[rid]["err_x_energy"] == pytest.approx(r["err_x_energy"], rel=1e-3, abs=1e-12)
        assert again[rid]["ref_bound"] == pytest.approx(r["ref_bound"], rel=1e-3, abs=1e-15)
    # the tampered file is kept aside, never overwritten; the new one passes its own check
    aside = [p for p in (out / "refs").iterdir() if p.name.startswith(ref_file.name + ".")]
    assert [p.read_bytes() for p in aside] == [tampered]
    assert store.ResultStore(out).load_ref(ref_file.stem) is not None


def test_a_good_cached_reference_is_checked_not_recomputed(tmp_path, refcheck_base):
    spec, out = _refcheck_copy(refcheck_base, tmp_path)
    graded = {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "run"}
    refs_before = {p.name: p.read_bytes() for p in (out / "refs").iterdir()}
    ref_rows = {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "reference"}
    _forget_runs(out)
    s = bench.run_sweep(spec, out, progress=False, stream=open(os.devnull, "w"))
    assert s.refs == 0 and s.ran == 4 and s.aux == 0
    assert {p.name: p.read_bytes() for p in (out / "refs").iterdir()} == refs_before
    assert {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "reference"} == ref_rows
    again = {r["run_id"]: r for r in store.read_results(out) if r["kind"] == "run"}
    assert {k: r["grade"] for k, r in again.items()} == {k: r["grade"] for k, r in graded.items()}


def test_a_cut_row_file_is_recovered_from_results_csv(small_sweep, tmp_path):
    """A row file cut by a kill whose row results.csv still holds: the row is kept (not redone),
    the cut file kept aside; two cut in a row get two names."""
    import shutil

    spec, out, _ = small_sweep
    clone = _clone(out, tmp_path / "clone")
    shutil.copytree(out / "rows", clone / "rows")
    done = next(r for r in store.read_results(out) if r["kind"] == "run" and r["status"] == "solved")
    row_file = clone / "rows" / f"{done['run_id']}.json"
    for i in range(2):
        row_file.write_text(row_file.read_text()[:25] if i == 0 else "{")
        warned = []
        st = store.ResultStore(clone, warn=warned.append).open()
        st.close()
        assert st.done(done["run_id"]) and st.rows[done["run_id"]]["status"] == "solved"
        assert len(warned) == 1 and "unreadable row file" in warned[0]
    assert len(list((clone / "rows").glob(f"{done['run_id']}.json.corrupt-*"))) == 2
    assert json.loads(row_file.read_text())["run_id"] == done["run_id"]
