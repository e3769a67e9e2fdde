"""The CLI: JSON contract of ``solve``, ``list``, ``export``; clean errors."""
from __future__ import annotations

import json

import pytest

from dualfem.cli.main import main

FIELDS = {"solver", "status", "ndof", "n_defect_nodes", "energy", "max_jump", "n_contact", "iterations",
          "time_s", "residuals"}


def test_solve_json(capsys):
    assert main(["solve", "f2", "--set", "N=16", "--set", "delta=1e-5", "--solver", "clarabel", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    rec = json.loads(out[0])
    assert FIELDS <= set(rec)
    assert rec["status"] == "solved" and rec["ndof"] > 0 and rec["n_defect_nodes"] == 7
    assert set(rec["time_s"]) >= {"setup", "solve"}
    assert set(rec["residuals"]) == {"stationarity", "primal", "dual", "complementarity"}
    assert max(rec["residuals"].values()) < 1e-6
    assert 0 < rec["n_contact"] < 7


def test_solve_human(capsys):
    assert main(["solve", "f3", "--set", "N=8", "--solver", "osqp"]) == 0
    out = capsys.readouterr().out
    assert "solved" in out and "residuals" in out


def test_toml_scene_and_export(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('scene = "f2"\nN = 8\ndelta = 1e-3\nplane = "stress"\n')
    out = tmp_path / "q.npz"
    assert main(["export", str(scene), "-o", str(out)]) == 0
    from dualfem.core.qp import QP

    qp = QP.load(out)
    assert qp.m == 3 and qp.params["plane"] == "stress"


def test_list(capsys):
    assert main(["list", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert {"osqp", "clarabel", "uzawa"} <= set(d["solvers"]) and {"f1", "f2", "f3"} <= set(d["scenes"])
    assert d["solvers"]["osqp"]["installed"] is True


@pytest.mark.parametrize("argv, words", [
    (["solve", "f2", "--set", "delta=0"], "delta"),
    (["solve", "f2", "--set", "nu=0.7"], "nu"),
    (["solve", "f2", "--set", "N=10"], "N=10"),
    (["solve", "f2", "--solver", "nope"], "unknown solver"),
    (["solve", "f2", "--set", "colour=red"], "unknown scene key"),
    (["solve", "f2", "--set", "N"], "KEY=VALUE"),
    (["solve", "f2", "--solver", "uzawa", "-p", "r=-1"], "'r'"),
    (["export", "f2", "-o", "x.csv"], ".npz or .mat"),
])
def test_bad_input_one_line(capsys, argv, words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "Traceback" not in err[0]


def test_malformed_toml(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("N = [\n")
    assert main(["solve", str(bad)]) == 2
    assert "malformed TOML" in capsys.readouterr().err


def test_solve_json_reports_stages_threads_and_memory(capsys):
    """The JSON of solve carries time_s (assembly, setup, solve, total), threads and peak_rss_mb;
    progress lines go to stderr only when the command runs longer than ~2 s (never to stdout)."""
    rc = main(["solve", "f2", "--set", "N=16", "--solver", "pdas", "--json", "--threads", "1"])
    out, err = capsys.readouterr()
    rec = json.loads(out)
    assert rc == 0 and rec["threads"] == 1 and rec["peak_rss_mb"] > 10
    t = rec["time_s"]
    assert {"assembly", "setup", "solve", "total"} <= set(t)
    assert t["total"] >= t["assembly"] + t["setup"] + t["solve"]
    assert rec["claimed_status"] == rec["status"] == "solved"
    assert "dualfem solve:" not in err         # a quick solve prints no stages


def test_stages_print_once_slow(capsys, monkeypatch):
    from dualfem.cli import stages

    monkeypatch.setattr(stages, "QUIET_FOR", 0.0)
    s = stages.Stages("solve")
    s("assembly", 0.5)
    quiet = stages.Stages("solve", quiet=True)
    quiet("assembly", 0.5)
    err = capsys.readouterr().err
    assert err.count("dualfem solve: assembly 0.50 s") == 1


def test_list_json_shows_parameters_with_defaults_and_renamed_names(capsys):
    assert main(["list", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    osqp = d["solvers"]["osqp"]
    assert {"tol", "max_iter", "time_limit", "verbose"} <= set(osqp["parameters"])
    assert osqp["renamed"]["eps_abs"] == "tol"
    assert "curved" in d["scene_library"]


# ------------------------------------------------------------- one dialect, one-line errors
SPEC = "benchmarks/small.toml"
CMDS = {"solve": ["solve", "f2", "--set", "N=8"], "compare": ["compare", "f2", "--set", "N=8"],
        "bench": ["bench", SPEC, "--out", "{tmp}/b"]}


def _argv(cmd: str, tmp_path, *extra: str) -> list[str]:
    return [a.replace("{tmp}", str(tmp_path)) for a in CMDS[cmd]] + list(extra)


def _one_line_error(capsys, cmd: str, *needles: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"dualfem {cmd}: error: "), err
    for n in needles:
        assert n in err, (n, err)
    return err


@pytest.mark.parametrize("cmd", sorted(CMDS))
@pytest.mark.parametrize("bad", ["pdas[", "pdas[tol=1", "pdas]", "pdas[tol=]", "pdas[tol=1]]", "pdas[][", ""])
def test_malformed_solver_selection_is_one_line_in_every_command(cmd, bad, tmp_path, capsys):
    assert main(_argv(cmd, tmp_path, "-s", bad)) == 2
    _one_line_error(capsys, cmd, "-s/--solver")
    assert not (tmp_path / "b").exists()


@pytest.mark.parametrize("cmd,flag,value,needles", [
    ("bench", "-r", "1.5", ["-r/--repeats", "1..1000", "'1.5'"]),
    ("bench", "-r", "abc", ["-r/--repeats", "1..1000"]),
    ("bench", "--jobs", "0", ["--jobs", "1.."]),
    ("bench", "--dask-timeout", "-1", ["--dask-timeout", "(0, "]),
    ("solve", "--threads", "1.5", ["--threads", "1.."]),
    ("solve", "--max-memory", "nan", ["--max-memory", "(0, "]),
    ("compare", "--max-memory", "0", ["--max-memory", "(0, "]),
    ("testset", "--max-memory", "-3", ["--max-memory", "(0, "]),
    ("testset", "--max-memory", "lots", ["--max-memory", "(0, "]),
    ("solve", "--max-memory", "lots", ["--max-memory", "number of GB in (0, "]),
])
def test_numeric_options_refused_in_one_line_with_range(cmd, flag, value, needles, tmp_path, capsys):
    argv = ["testset", "--out", str(tmp_path / "t")] if cmd == "testset" else _argv(cmd, tmp_path)
    assert main([*argv, flag, value]) == 2
    _one_line_error(capsys, cmd, *needles)


def test_solve_takes_the_selection_dialect(capsys):
    assert main(["solve", "f2", "--set", "N=8", "-s", "osqp[tol=1e-7,polish=true]", "--json"]) == 0
    out, err = capsys.readouterr()
    rec = json.loads(out)
    assert rec["solver"] == "osqp" and rec["params"]["tol"] == 1e-7 and rec["params"]["polish"] is True
    assert "warning" not in err


def test_solve_old_param_form_works_with_a_warning(capsys):
    assert main(["solve", "f2", "--set", "N=8", "--solver", "pdas", "-p", "tol=1e-9", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["params"]["tol"] == 1e-9
    assert "dualfem solve: warning: -p KEY=VALUE is deprecated: write -s 'pdas[tol=1e-9]'" in err


def test_solve_refuses_two_solvers_and_a_key_given_twice(capsys):
    assert main(["solve", "f2", "-s", "pdas", "-s", "osqp"]) == 2
    _one_line_error(capsys, "solve", "one solver")
    assert main(["solve", "f2", "-s", "pdas[tol=1e-9]", "-p", "tol=1e-8"]) == 2
    _one_line_error(capsys, "solve", "'tol'")
    assert main(["solve", "f2", "-s", "pdas[nope=1]"]) == 2
    _one_line_error(capsys, "solve", "'nope'", "allowed")


def test_compare_takes_the_selection_dialect_and_old_forms(capsys):
    assert main(["compare", "f2", "--set", "N=8", "-s", "pdas", "-s", "osqp[tol=1e-7]", "--json"]) == 0
    out, err = capsys.readouterr()
    runs = {r["solver"]: r for r in json.loads(out)["runs"]}
    assert set(runs) == {"pdas", "osqp"} and runs["osqp"]["params"]["tol"] == 1e-7
    assert "warning" not in err
    assert main(["compare", "f2", "--set", "N=8", "--solvers", "pdas,osqp", "-p", "osqp.tol=1e-7", "--json"]) == 0
    out, err = capsys.readouterr()
    assert {r["solver"]: r for r in json.loads(out)["runs"]}["osqp"]["params"]["tol"] == 1e-7
    assert "deprecated: write -s pdas -s 'osqp[tol=1e-7]'" in err
    assert main(["compare", "f2", "-s", "pdas", "--solvers", "osqp"]) == 2
    _one_line_error(capsys, "compare", "--solvers")
    assert main(["compare", "f2", "-s", "pdas", "-s", "pdas[tol=1e-9]"]) == 2
    _one_line_error(capsys, "compare", "twice")


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"dualfem {__import__('dualfem').__version__}"


@pytest.mark.parametrize("cmd", ["solve", "compare"])
def test_help_names_no_deprecated_parameter_or_option(cmd, capsys):
    from dualfem.core.registry import solvers

    assert main([cmd, "--help"]) == 0
    text = capsys.readouterr().out
    old = {o for c in solvers().values() for o in getattr(c, "renamed", {})}
    assert "-s SOLVER[KEY=V,...]" in text
    assert not [w for w in old if w in text], [w for w in old if w in text]
    assert "--solvers" not in text and "--param" not in text


def test_report_help_names_each_kinds_default_output(capsys):
    """``dualfem report --help`` lists every report kind's default output as that kind's own --help says it."""
    from dualfem.cli.report import DEFAULT_OUTPUT, reports

    assert set(DEFAULT_OUTPUT) == set(reports())
    assert main(["report", "--help"]) == 0
    top = " ".join(capsys.readouterr().out.split())
    for kind, where in DEFAULT_OUTPUT.items():
        assert f"{kind} {where}" in top.replace("- ", "-")
        try:
            rc = main(["report", kind, "--help"])
        except SystemExit as exc:                    # a report kind's own argparse may exit after --help
            rc = exc.code
        assert rc in (0, None)
        own = "".join(capsys.readouterr().out.split())        # argparse wraps (and may break at '-')
        assert "".join((where.split(" (")[0] if kind == "robustness" else where).split()) in own, kind


@pytest.mark.parametrize("argv,folder", [
    (["--quick"], "quick"), (["--quick", "--scene", "two_defects"], "quick-two_defects"),
    (["--scene", "scenes/curved.toml"], "full-curved")])
def test_stress_default_folder_is_unique_per_scene(argv, folder, monkeypatch, capsys):
    """The README's consecutive `stress --quick` and `stress --quick --scene two_defects` use two folders."""
    import dualfem.experiments.stress as stress

    monkeypatch.setattr(stress, "holds_results", lambda out: "a grid")   # every folder 'holds' a grid: refused
    assert main(["stress", *argv]) == 2
    assert f"--out 'dualfem-results/stress/{folder}' already holds results" in capsys.readouterr().err


def test_bench_default_folder_is_unique_per_selection():
    from dualfem.cli.bench import default_name

    assert default_name("small", ()) == "small"
    a, b = default_name("small", ("-s pdas",)), default_name("small", ("-s osqp",))
    assert a != b and a.startswith("small-") and len(a) == len("small-") + 8


def test_unrecognized_arguments_are_named_by_their_command(capsys):
    assert main(["list", "--json", "extra"]) == 2
    _one_line_error(capsys, "list", "unrecognized arguments: extra")
