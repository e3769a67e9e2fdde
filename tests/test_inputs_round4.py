"""Issue 37 item 8 and issue 33's stress items: one class of bad input per test, each failing without its fix.

Tracebacks (a minimal results.csv, an empty convergence.json, a plugin exception whose ``str()`` raises, a
stress meta.json that is not an object), special files (FIFOs refused before anything opens them),
"nothing was written" only when true, grid sizes checked before allocating (Signorini), ``defects = []``
as an uncracked body (2D and 3D), the 3D update keys of docs/loads.md, argparse errors in one line, and
``dualfem stress`` saying how long it will take and which scene it ran.
"""
from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.errors import InputError, OutputError

CORPUS = Path(__file__).parent / "bad_inputs"


def one_error_line(err: str, cmd: str, *needles: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"dualfem {cmd}: error: "), lines[0]
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


class _Hang(Exception):
    pass


def run_bounded(argv: list[str], seconds: float = 20.0) -> int:
    """``main(argv)``, failing the test (not hanging it) when it blocks longer than ``seconds``."""
    def alarm(*_):
        raise _Hang

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        return main(argv)
    except _Hang:
        pytest.fail(f"dualfem {' '.join(argv)} blocked for {seconds} s")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# ----------------------------------------------------------------------------- tracebacks
def test_report_bench_on_a_minimal_results_csv_is_one_line(tmp_path, capsys):
    (tmp_path / "results.csv").write_text("run_id,kind,status\nabc,run,solved\n")
    assert main(["report", "bench", str(tmp_path), "--md", str(tmp_path / "r.md")]) == 2
    one_error_line(capsys.readouterr().err, "report", "scene", "dualfem bench")
    assert not (tmp_path / "r.md").exists()


@pytest.mark.parametrize("text, needle", [
    ("{}", "'scene'"), ("[]", "JSON object"), ('{"scene": "f2", "solver": "pdas", "ref_N": 8, "Ns": [2], '
                                             '"deltas": {}, "time_s": 1}', "at least one delta"),
    ('{"scene": "f2", "solver": "pdas", "ref_N": 8, "Ns": [2], "deltas": {"0.1": {"levels": [{}], '
     '"reference": {}}}, "time_s": 1}', "reference"),
])
def test_convergence_from_json_checks_the_stored_study(tmp_path, capsys, text, needle):
    (tmp_path / "c.json").write_text(text)
    assert main(["report", "convergence", "--from-json", str(tmp_path / "c.json"), "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys.readouterr().err, "report", "--from-json", needle)
    assert not (tmp_path / "o").exists()


def test_the_committed_convergence_json_passes_the_check():
    from dualfem.reports.convergence import check_study

    root = Path(__file__).parents[1]
    check_study(json.loads((root / "reports" / "convergence.json").read_text()), "reports/convergence.json")


class _Unprintable(Exception):
    def __str__(self):
        raise RuntimeError("str() of a hostile exception")


def test_describe_exception_never_raises():
    from dualfem.core.errors import describe_exception

    assert describe_exception(ValueError("x")) == "ValueError: x"
    assert describe_exception(_Unprintable()).startswith("_Unprintable: <its message cannot be shown")


def test_a_plugin_exception_whose_str_raises_is_named_not_a_traceback(capsys):
    from dualfem.core import registry
    from dualfem.core.solver import Solver

    class Unprintable(Solver):
        name = "hostile_unprintable"
        defaults = {"tol": 1e-8}

        def solve(self):
            raise _Unprintable()

    registry.solvers()
    registry.register_solver(Unprintable)
    try:
        assert main(["solve", "f1", "--set", "N=8", "--solver", "hostile_unprintable", "--json"]) == 1
        rec = json.loads(capsys.readouterr().out)
        assert rec["status"] == "error" and "_Unprintable" in rec["message"]
        assert main(["compare", "f1", "--set", "N=8", "--solvers", "hostile_unprintable,pdas"]) == 0
        assert "_Unprintable: <its message cannot be shown" in capsys.readouterr().out
    finally:
        registry._SOLVERS.pop("hostile_unprintable", None)


@pytest.mark.parametrize("meta", ["[1]", "null", "7"])
def test_a_stress_meta_json_that_is_not_an_object_is_one_line(tmp_path, meta):
    from dualfem.experiments.stress import load_results

    (tmp_path / "results.csv").write_text("run_id,kind,status\nabc,stress,solved\n")
    (tmp_path / "meta.json").write_text(meta)
    with pytest.raises(InputError, match="meta.json"):
        load_results(tmp_path)


# ----------------------------------------------------------------------------- special files
def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("argv, cmd", [
    (["solve", "{d}/p.npz"], "solve"),
    (["export", "{d}/p.npz", "-o", "{d}/out.npz"], "export"),
    (["solve", "{d}/s.toml"], "solve"),
    (["bench", "{d}/s.toml", "--out", "{d}/res"], "bench"),
    (["report", "convergence", "--from-json", "{d}/p.json", "--out", "{d}/o"], "report"),
    (["report", "bench", "{d}/fifo_res"], "report"),
    (["report", "html", "{d}/fifo_res", "--out", "{d}/h"], "report"),
])
def test_a_fifo_is_refused_before_it_is_opened(tmp_path, capsys, argv, cmd):
    for name in ("p.npz", "s.toml", "p.json"):
        _fifo(tmp_path / name)
    (tmp_path / "fifo_res").mkdir()
    _fifo(tmp_path / "fifo_res" / "results.csv")
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    assert run_bounded(argv) == 2
    one_error_line(capsys.readouterr().err, cmd, "FIFO")


def test_a_results_folder_holding_a_fifo_is_refused_before_bench_reads_it(tmp_path, capsys):
    (tmp_path / "res" / "rows").mkdir(parents=True)
    _fifo(tmp_path / "res" / "rows" / "abc.json")
    assert run_bounded(["bench", str(CORPUS / "specs" / "good_small.toml"), "--out", str(tmp_path / "res")]) == 2
    one_error_line(capsys.readouterr().err, "bench", "FIFO", "abc.json")


def test_a_device_is_refused_as_a_scene_file(capsys):
    assert run_bounded(["solve", "/dev/zero"]) == 2
    one_error_line(capsys.readouterr().err, "solve", "character device")


# ----------------------------------------------------------------------------- "nothing was written"
def test_a_failed_write_names_what_bench_already_wrote(tmp_path, capsys, monkeypatch):
    """A disk that fills up after rows/, refs/ and sweep.json were written: the error line says they are
    there (and kept), not "(nothing was written)"."""
    from dualfem.experiments import bench

    def fill_up(spec, scenes, tasks, store, out, *rest):
        (store.rows_dir / "f1:pdas:1.json").write_text("{}")
        (store.out / "sweep.json").write_text("{}")
        raise OutputError(f"cannot write {str(out / 'results.csv')!r}: No space left on device "
                          "(nothing was written to it)")

    monkeypatch.setattr(bench, "_sweep", fill_up)
    out = tmp_path / "res"
    assert main(["bench", str(CORPUS / "specs" / "good_small.toml"), "--out", str(out)]) == 2
    line = one_error_line(capsys.readouterr().err, "bench", "results.csv", "No space left", "already in",
                          "rows/ (1 runs)", "sweep.json", "kept")
    assert not line.endswith("(nothing was written)")


# ----------------------------------------------------------------------------- sizes before allocating
@pytest.mark.parametrize("key", ["height=1e9", "width=1e-9"])
def test_signorini_grid_size_is_checked_before_allocating(capsys, key):
    assert run_bounded(["solve", "signorini", "--set", "N=8", "--set", key], 20) == 2
    one_error_line(capsys.readouterr().err, "solve", "height / width", "N = 4096")


def test_signorini_size_estimate_feeds_the_memory_guard():
    from dualfem.core.scene import load_scene

    p = load_scene("signorini", {"N": 16, "height": 2.0})
    assert p.size_estimate()[0] == 2 * 17 * 33 and p.grid() == (16, 32)


# ----------------------------------------------------------------------------- defects = []
def test_no_defects_in_2d_is_an_uncracked_body(tmp_path, capsys):
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    qp = load_scene("f2", {"N": 8, "defects": []}).build()
    assert qp.m == 0 and qp.n > 0
    assert load_scene("f2", {"N": 8}).build().m > 0          # not given: the single segment, as before
    for s in ("pdas", "uzawa_auto", "penalty"):
        assert str(run(s, qp).status) == "solved", s
    scene = tmp_path / "plate.toml"
    scene.write_text("N = 8\ndefects = []\n")
    assert main(["solve", str(scene), "--vtk", str(tmp_path / "u.vtu")]) == 0
    assert (tmp_path / "u.vtu").is_file()


def test_every_installed_solver_answers_or_skips_a_qp_without_constraints():
    """m = 0: solved, or skipped with the reason (SCS needs a constraint); never an error."""
    from dualfem.core.registry import solvers
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    qp = load_scene("f2", {"N": 4, "defects": []}).build()
    for name, cls in sorted(solvers().items()):
        if cls.missing() is None and name not in ("cvxpy",):      # cvxpy: its import alone takes seconds
            sol = run(name, qp)
            assert str(sol.status) in ("solved", "skipped"), (name, sol.status, sol.message)


def test_no_defects_in_3d_is_an_uncracked_box(tmp_path, capsys):
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    qp = load_scene("three_d", {"N": 3, "defects": []}).build()
    assert qp.m == 0 and qp.n > 0
    assert str(run("pdas", qp).status) == "solved"
    scene = tmp_path / "box.toml"
    scene.write_text("dim = 3\nN = 3\ndefects = []\n")
    assert main(["solve", str(scene), "--figure", str(tmp_path / "f.png")]) == 2
    one_error_line(capsys.readouterr().err, "solve", "defects = []", "--vtk")


# ----------------------------------------------------------------------------- 3D update keys
def test_workspace_update_of_3d_loads_reuses_the_assembly():
    from dualfem.core.scene import load_scene
    from dualfem.experiments.workspace import Workspace

    clamp = [{"side": "bottom", "support": "clamp"}]
    s1 = [[0, 0, 0], [0, 0, 0], [0, 0, 1.0]]
    ws = Workspace("three_d", {"N": 3, "boundary": clamp, "remote_stress": s1})
    ws.setup()
    ws.update(body_force=[0, 0, -0.1])
    ws.update(remote_stress=[[0, 0, 0], [0, 0, 0], [0, 0, 2.0]])
    assert ws.assemblies == 1 and ws.factorizations == 1
    fresh = load_scene("three_d", {"N": 3, "boundary": clamp, "body_force": [0, 0, -0.1],
                                   "remote_stress": [[0, 0, 0], [0, 0, 0], [0, 0, 2.0]]}).build()
    assert np.array_equal(fresh.F, ws.qp.F) and abs(fresh.K - ws.qp.K).max() == 0
    ws.update(boundary=[{"side": "bottom", "support": "roller"}, {"side": "left", "support": "clamp"}])
    assert ws.assemblies == 2                                 # other supports: the stiffness once more


# ----------------------------------------------------------------------------- argparse in one line
@pytest.mark.parametrize("argv", [["bench", "x.toml", "-r", "1.5"], ["bench", "x.toml", "-r", "abc"],
                                  ["solve"], ["report", "bench"]])
def test_argparse_errors_are_one_line(capsys, argv):
    assert main(argv) == 2
    one_error_line(capsys.readouterr().err, " ".join(argv[:2]) if argv[0] == "report" else argv[0])


# ----------------------------------------------------------------------------- stress: time and scene
def test_stress_estimates_before_it_starts_and_warns_when_long(capsys, monkeypatch):
    from dualfem.cli import stress as cli_stress
    from dualfem.experiments import stress, stress_estimate

    tasks = stress.build_grid(["pdas", "uzawa"], quick=True, axes=("delta", "N"))
    est = stress_estimate.estimate(tasks, 1, measured={"build_s": 0.01, "run_s": 0.1, "solver": "pdas", "n": 1})
    assert est["runs"] == len(tasks) and 0 < est["seconds"] < est["worst_s"]
    n_tasks = [t for t in tasks if t.axis == "N"]
    assert est["seconds"] < len(tasks) * 0.1 + len({stress._sid(t.scene) for t in tasks}) * 0.11 \
        + sum(t.time_limit for t in n_tasks)
    monkeypatch.setattr(stress_estimate, "probe", lambda t: {"build_s": 1.0, "run_s": 30.0, "solver": "pdas", "n": 9})
    cli_stress._say_estimate(tasks, 1, None)
    err = capsys.readouterr().err
    assert "runs on" in err and "about" in err and "warning: this grid takes about" in err
    monkeypatch.setattr(stress_estimate, "probe", lambda t: {"build_s": 0.0, "run_s": 0.01, "solver": "pdas", "n": 9})
    cli_stress._say_estimate(tasks, 1, None)
    assert "warning" not in capsys.readouterr().err


def test_stress_dry_run_prints_the_estimate(capsys):
    assert main(["stress", "--quick", "--solvers", "pdas", "--axes", "N", "--max-n", "16", "--dry-run"]) == 0
    assert "time   2 runs on 2 scenes, about" in capsys.readouterr().out


def test_the_stability_report_names_the_grid_scene():
    from dualfem.reports.stability import base_scene

    assert base_scene({"scene": "two_defects", "base": {"mesh": "gmsh", "mesh_size": 0.04, "delta": 1e-5}}) == \
        "`two_defects` (gmsh, mesh_size = 0.04, delta = 1e-05)"
    assert "paper's f2" in base_scene({"scene": "f2 (paper)", "quick": True})


# ----------------------------------------------------------------------------- the committed report
def test_corpus_records_name_no_path_of_this_machine():
    from dualfem.experiments.robustness import load_cases, run_case

    case = next(c for c in load_cases(CORPUS) if c["name"] == "TOML boolean for a number (delta = true)")
    rec = run_case(case, CORPUS.resolve(), main)
    assert rec["outcome"] == "refused" and "{corpus}/scenes/bool_delta.toml" in rec["why"], rec["why"]
    text = json.dumps(rec)
    assert str(CORPUS.resolve()) not in text and "/tmp/dualfem-bad-" not in text
