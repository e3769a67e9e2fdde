"""The bad-input corpus (issue 6): every bad input gives exit status 2, ONE line on stderr naming the
parameter and the allowed range, no traceback, and writes nothing.

Most cases run ``dualfem.cli.main`` in-process (fast); a few run ``python -m dualfem`` as a real
subprocess, which also catches stray warnings and tracebacks printed outside Python's control.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.registry import solvers

SMALL = ["--set", "N=8"]


def run_cli(argv, capsys):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc, err, needles, cmd="solve"):
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, f"exit {rc}, stderr: {err!r}"
    assert len(lines) == 1, f"expected one stderr line, got {lines!r}"
    assert lines[0].startswith(f"dualfem {cmd}: error: "), lines[0]
    for n in needles:
        assert re.search(n, lines[0], flags=re.I), f"{n!r} not in {lines[0]!r}"


# ------------------------------------------------------------------- scene parameters
# (argv after 'solve f2', regexes the message must contain: the parameter and its allowed range)
SCENE_CASES = {
    "delta=0": (["--set", "delta=0"], [r"\bdelta\b", r"> 0"]),
    "delta<0": (["--set", "delta=-1e-5"], [r"\bdelta\b", r"> 0"]),
    "delta=nan": (["--set", "delta=nan"], [r"\bdelta\b", r"finite", r"> 0"]),
    "delta=inf": (["--set", "delta=inf"], [r"\bdelta\b", r"finite", r"> 0"]),
    "delta=-inf": (["--set", "delta=-inf"], [r"\bdelta\b", r"> 0"]),
    "delta=text": (["--set", "delta=small"], [r"'delta'", r"number"]),
    "E=0": (["--set", "E=0"], [r"\bE\b", r"> 0"]),
    "E<0": (["--set", "E=-69000"], [r"\bE\b", r"> 0"]),
    "E=nan": (["--set", "E=nan"], [r"\bE\b", r"finite"]),
    "E=inf": (["--set", "E=inf"], [r"\bE\b", r"finite"]),
    "nu=0.5": (["--set", "nu=0.5"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "nu=-1": (["--set", "nu=-1"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "nu=0.7": (["--set", "nu=0.7"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "nu=-3": (["--set", "nu=-3"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "nu=nan": (["--set", "nu=nan"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "nu=inf": (["--set", "nu=inf"], [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    "N=0": (["--set", "N=0"], [r"\bN\b", r"\[2, 4096\]"]),
    "N=1": (["--set", "N=1"], [r"\bN\b", r"\[2, 4096\]"]),
    "N<0": (["--set", "N=-8"], [r"\bN\b", r"\[2, 4096\]"]),
    "N=huge": (["--set", "N=100000"], [r"\bN\b", r"\[2, 4096\]"]),
    "N=2.5": (["--set", "N=2.5"], [r"'N'", r"integer"]),
    "N=text": (["--set", "N=many"], [r"'N'", r"integer"]),
    "N cannot carry the defect (N=2)": (["--set", "N=2"], [r"N=2", r"cannot carry the defect", r"multiples"]),
    "N cannot carry the defect (N=6)": (["--set", "N=6"], [r"N=6", r"cannot carry the defect"]),
    "defect on one edge": (["--set", "N=4", "--set", "defect=0.25,0.5,0.5,0.5"],
                           [r"N=4", r"too coarse|single mesh edge"]),
    "defect off the mesh directions": (SMALL + ["--set", "defect=0.25,0.5,0.75,0.25"],
                                       [r"N=8", r"mesh edges", r"horizontal"]),
    "defect outside": (["--set", "defect=0.25,0.5,1.5,0.5"], [r"defect", r"strictly inside", r"\(0, 1\) x \(0, 1\)"]),
    "defect outside (negative)": (["--set", "defect=-0.25,0.5,0.5,0.5"], [r"defect", r"strictly inside"]),
    "defect touching boundary": (["--set", "defect=0,0.5,0.75,0.5"], [r"defect", r"strictly inside", r"touches"]),
    "defect touching top": (["--set", "defect=0.5,0.5,0.5,1"], [r"defect", r"strictly inside"]),
    "defect zero length": (["--set", "defect=0.5,0.5,0.5,0.5"], [r"defect", r"zero length"]),
    "defect malformed": (["--set", "defect=1,2,3"], [r"defect", r"two points"]),
    "defect nan": (["--set", "defect=nan,0.5,0.75,0.5"], [r"defect", r"finite"]),
    "width=0": (["--set", "width=0"], [r"\bwidth\b", r"> 0"]),
    "height=-1": (["--set", "height=-1"], [r"\bheight\b", r"> 0"]),
    "height=nan": (["--set", "height=nan"], [r"\bheight\b", r"finite"]),
    "load unknown": (["--set", "load=f9"], [r"unknown load 'f9'", r"f1, f2, f3"]),
    "load code injection": (["--set", "load=__import__('os').system('true')"],
                            [r"load", r"not allowed|only arithmetic"]),
    "load attribute": (["--set", "load=x.real"], [r"load", r"only arithmetic"]),
    "load syntax": (["--set", "load=10*(x"], [r"load", r"f1, f2, f3"]),
    "load empty": (["--set", "load="], [r"\bload\b", r"f1, f2, f3"]),
    "load NaN": (["--set", "load=log(x-2)"], [r"load", r"NaN or infinite"]),
    "load inf": (["--set", "load=1/(x-x)"], [r"load", r"NaN or infinite"]),
    "load NaN on part of the side": (SMALL + ["--set", "load=sqrt(x-0.6)"], [r"load", r"NaN or infinite"]),
    "load NaN between the sample points": (SMALL + ["--set", "load=sqrt((x-0.55)*(x-0.7))"],
                                           [r"load", r"NaN or infinite", r"top side"]),
    "load_scale nan": (["--set", "load_scale=nan"], [r"load_scale", r"finite"]),
    "load_scale inf": (["--set", "load_scale=inf"], [r"load_scale", r"finite"]),
    "plane": (["--set", "plane=3d"], [r"\bplane\b", r"strain, stress"]),
    "unknown scene key": (["--set", "youngs=1"], [r"unknown scene key 'youngs'", r"allowed: .*delta"]),
    "set without =": (["--set", "delta"], [r"KEY=VALUE"]),
    "unknown solver": (["--solver", "nosuch"], [r"unknown solver 'nosuch'", r"known solvers: .*clarabel"]),
    "unknown solver parameter": (["--solver", "clarabel", "-p", "rr=1"],
                                 [r"unknown parameter 'rr'", r"allowed: .*tol_ktratio"]),
    "param without =": (["--solver", "clarabel", "-p", "tol_ktratio"], [r"KEY=VALUE"]),
}


@pytest.mark.parametrize("case", list(SCENE_CASES))
def test_scene_and_cli_inputs(case, capsys):
    extra, needles = SCENE_CASES[case]
    rc, out, err = run_cli(["solve", "f2", *extra], capsys)
    assert_one_line_error(rc, err, needles)
    assert out == ""


def test_python_load_function_that_breaks():
    from dualfem.core.errors import InputError
    from dualfem.core.scene import load_scene

    def bad(x, y):
        raise ZeroDivisionError("boom")

    with pytest.raises(InputError, match="load bad cannot be evaluated"):
        load_scene("f2", {"N": 8, "load": bad}).build()
    with pytest.raises(InputError, match="NaN or infinite"):
        load_scene("f2", {"N": 8, "load": lambda x, y: np.where(x > 0.6, np.nan, -1.0)}).build()


def test_unknown_scene(capsys):
    rc, out, err = run_cli(["solve", "f9"], capsys)
    assert_one_line_error(rc, err, [r"unknown scene 'f9'", r"f1, f2, f3", r"\.toml"])


# ------------------------------------------------------------ solver parameters
def _solver_positive_params():
    """(solver, parameter) for every positive tolerance-like parameter and every 'r' of the registry."""
    out = []
    for name, cls in sorted(solvers().items()):
        for k, v in cls.defaults.items():
            tol_like = (isinstance(v, float) and v > 0 and re.search(r"tol|eps|^r$|^rho", k))
            if tol_like or k == "r":
                out.append((name, k))
    return out


SOLVER_PARAMS = _solver_positive_params()


def test_corpus_covers_tolerances_of_the_reference_solvers():
    names = {s for s, _ in SOLVER_PARAMS}
    assert {"clarabel", "osqp"} <= names
    if "uzawa" in solvers():
        assert ("uzawa", "r") in SOLVER_PARAMS


@pytest.mark.parametrize("bad", ["0", "-1", "nan", "inf", "-inf"])
def test_solver_tolerances_and_r(bad, capsys):
    """Every (solver, tolerance-like parameter or r) of :data:`SOLVER_PARAMS` given ``bad`` on the command
    line: exit 2, one stderr line naming the parameter, the solver and the range; all failures listed."""
    failures = []
    for solver, param in SOLVER_PARAMS:
        rc, out, err = run_cli(["solve", "f2", *SMALL, "--solver", solver, "-p", f"{param}={bad}"], capsys)
        try:
            assert_one_line_error(rc, err, [rf"'{param}'", rf"'{solver}'", r"finite|> 0|positive|\("])
        except AssertionError as exc:
            failures.append(f"{solver} -p {param}={bad}: {exc}")
    assert not failures, f"{len(failures)} of {len(SOLVER_PARAMS)}:\n" + "\n".join(failures)


@pytest.mark.parametrize("solver,param", SOLVER_PARAMS[:4])
def test_solver_parameter_not_a_number(solver, param, capsys):
    rc, out, err = run_cli(["solve", "f2", *SMALL, "--solver", solver, "-p", f"{param}=tiny"], capsys)
    assert_one_line_error(rc, err, [rf"'{param}'", r"number"])


# -------------------------------------------------------------------------- TOML
def test_malformed_toml(tmp_path, capsys):
    f = tmp_path / "bad.toml"
    f.write_text('scene = "f2"\nN = = 8\n')
    rc, out, err = run_cli(["solve", str(f)], capsys)
    assert_one_line_error(rc, err, [r"malformed TOML", re.escape(str(f))])


@pytest.mark.parametrize("body,needles", [
    ('scene = "f2"\nN = 8\nyoungs = 1\n', [r"unknown scene key 'youngs'"]),
    ('scene = "f2"\nN = 8\ndelta = -1e-5\n', [r"\bdelta\b", r"> 0"]),
    ('scene = "f2"\nN = 8\nnu = 0.5\n', [r"\bnu\b", r"\(-1(\.0)?, 0\.5\)"]),
    ('scene = "f2"\nN = 8\ndelta = nan\n', [r"\bdelta\b", r"finite"]),
    ('scene = "f2"\nN = 8\ndelta = inf\n', [r"\bdelta\b", r"finite"]),
    ('scene = "f7"\n', [r"unknown base scene 'f7'"]),
    ('scene = "f2"\nN = 8\nload = "f0"\n', [r"unknown load 'f0'"]),
    ('scene = "f2"\nN = 8\ndefect = [[0.25, 0.5], [0.25, 0.5]]\n', [r"defect", r"zero length"]),
    ('scene = "f2"\nN = 8\ndefect = [[0.25, 0.5], [1.25, 0.5]]\n', [r"defect", r"strictly inside"]),
    ('scene = "f2"\nN = 8\nproblem = "nosuch"\n', [r"unknown problem 'nosuch'"]),
])
def test_bad_toml_values(tmp_path, capsys, body, needles):
    f = tmp_path / "s.toml"
    f.write_text(body)
    rc, out, err = run_cli(["solve", str(f)], capsys)
    assert_one_line_error(rc, err, needles)


def test_toml_not_utf8_and_missing(tmp_path, capsys):
    f = tmp_path / "latin.toml"
    f.write_bytes('load = "f2"\n# caf\xe9\n'.encode("latin-1"))
    rc, out, err = run_cli(["solve", str(f)], capsys)
    assert_one_line_error(rc, err, [r"UTF-8|malformed"])
    rc, out, err = run_cli(["solve", str(tmp_path / "none.toml")], capsys)
    assert_one_line_error(rc, err, [r"does not exist"])


# -------------------------------------------------- user QP files (.npz, via the CLI)
@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A valid QP written by ``dualfem export`` and its arrays."""
    d = tmp_path_factory.mktemp("qp")
    f = d / "good.npz"
    assert main(["export", "f2", *SMALL, "-o", str(f)]) == 0
    with np.load(f, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _tamper(arrays, case):
    a = {k: v.copy() for k, v in arrays.items()}
    n = int(a["K_shape"][0])
    if case == "F too short":
        a["F"] = a["F"][:-1]
    elif case == "B columns":
        a["B_shape"] = np.array([a["B_shape"][0], n + 3])
    elif case == "K not square":
        a["K_shape"] = np.array([n, n + 1])
    elif case == "weights length":
        a["weights"] = a["weights"][:-1]
    elif case == "K nan":
        a["K_data"][5] = np.nan
    elif case == "F inf":
        a["F"][0] = np.inf
    elif case == "K non-symmetric":
        off = np.flatnonzero(a["K_row"] != a["K_col"])[0]
        a["K_data"][off] += 1e3 * np.abs(a["K_data"]).max()
    elif case == "K indefinite":
        # flip the smallest eigenvalue: K - 2 w0 v v' has eigenvalue -w0 < 0, but its diagonal
        # stays positive, so the cheap diagonal test alone would not see it
        import scipy.sparse as sp

        K = sp.coo_matrix((a["K_data"], (a["K_row"], a["K_col"])), shape=(n, n)).toarray()
        w, V = np.linalg.eigh(K)
        K = K - 2.0 * w[0] * np.outer(V[:, 0], V[:, 0])
        K = 0.5 * (K + K.T)
        assert np.all(np.diag(K) > 0) and np.linalg.eigvalsh(K)[0] < 0
        c = sp.coo_matrix(K)
        a.update(K_data=c.data, K_row=c.row, K_col=c.col)
    elif case == "no F":
        del a["F"]
    elif case == "weights <= 0":
        a["weights"][0] = 0.0
    return a


QP_CASES = {
    "F too short": [r"\bF\b", r"length"],
    "B columns": [r"\bB\b", r"columns"],
    "K not square": [r"\bK\b", r"square"],
    "weights length": [r"weights", r"length"],
    "K nan": [r"\bK\b", r"NaN"],
    "F inf": [r"\bF\b", r"NaN or infinite"],
    "K non-symmetric": [r"symmetric"],
    "K indefinite": [r"positive definite"],
    "no F": [r"lacks|missing|\bF\b"],
    "weights <= 0": [r"weights", r"> 0"],
}


@pytest.mark.parametrize("case", list(QP_CASES))
def test_bad_user_qp_file(case, exported, tmp_path, capsys):
    f = tmp_path / "user.npz"
    np.savez(f, **_tamper(exported, case))
    rc, out, err = run_cli(["solve", str(f), "--solver", "clarabel"], capsys)
    assert_one_line_error(rc, err, QP_CASES[case])


def test_corrupt_and_missing_qp_files(tmp_path, capsys):
    f = tmp_path / "junk.npz"
    f.write_bytes(b"PK\x03\x04 this is not a zip archive")
    rc, out, err = run_cli(["solve", str(f)], capsys)
    assert_one_line_error(rc, err, [r"cannot read|not|corrupt"])
    rc, out, err = run_cli(["solve", str(tmp_path / "absent.npz")], capsys)
    assert_one_line_error(rc, err, [r"does not exist"])


# ---------------------------------------------------------- missing optional dependency
@pytest.fixture
def fake_missing_solver():
    from dualfem.core import registry
    from dualfem.core.solver import Solver

    registry.solvers()

    class _Missing(Solver):
        name = "fake_missing_dep"
        description = "test double whose backend is not installed"
        requires = ("dualfem_no_such_module_xyz",)
        extra = "fake"

    registry._SOLVERS[_Missing.name] = _Missing
    yield _Missing.name
    registry._SOLVERS.pop(_Missing.name, None)


@pytest.mark.parametrize("extra", [[], ["--json"]])
def test_missing_dependency_one_stderr_line(fake_missing_solver, extra, capsys):
    rc, out, err = run_cli(["solve", "f2", *SMALL, "--solver", fake_missing_solver, *extra], capsys)
    assert_one_line_error(rc, err, [r"fake_missing_dep", r"dualfem_no_such_module_xyz", r"pip install"])
    assert out == ""


def test_missing_dependency_in_the_grid_is_a_skip_with_the_reason(fake_missing_solver):
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    sol = run(fake_missing_solver, load_scene("f2", {"N": 8}).build())
    assert str(sol.status) == "skipped" and "pip install 'dualfem[fake]'" in sol.message


# ------------------------------------------------------------------ nothing written
def _files(d: Path) -> list[str]:
    return sorted(p.name for p in d.rglob("*"))


@pytest.mark.parametrize("extra", [["--set", "delta=0"], ["--set", "nu=0.5"], ["--set", "N=3"],
                                   ["--set", "load=log(x-2)"], ["--set", "defect=0.5,0.5,0.5,0.5"]])
def test_export_writes_nothing_on_bad_input(extra, tmp_path, capsys):
    out = tmp_path / "sub" / "qp.npz"
    rc, _, err = run_cli(["export", "f2", *extra, "-o", str(out)], capsys)
    assert_one_line_error(rc, err, [r"."], cmd="export")
    assert not out.exists()
    assert _files(tmp_path) in ([], ["sub"])  # no temporary or partial file left behind


def test_export_refuses_unknown_suffix(tmp_path, capsys):
    out = tmp_path / "qp.txt"
    rc, _, err = run_cli(["export", "f2", *SMALL, "-o", str(out)], capsys)
    assert_one_line_error(rc, err, [r"\.npz or \.mat"], cmd="export")
    assert _files(tmp_path) == []


def test_export_does_not_clobber_on_bad_input(tmp_path, capsys):
    out = tmp_path / "qp.npz"
    out.write_bytes(b"previous content")
    rc, _, err = run_cli(["export", "f2", "--set", "delta=-1", "-o", str(out)], capsys)
    assert rc == 2 and out.read_bytes() == b"previous content"


@pytest.mark.parametrize("flags,needles", [
    (["--solvers", "nosuch"], [r"--solvers", r"unknown solver 'nosuch'"]),
    (["--axes", "delta,temperature"], [r"--axes", r"'temperature'", r"delta, r, units"]),
    (["--time-limit", "0"], [r"--time-limit", r"> 0"]),
    (["--time-limit", "nan"], [r"--time-limit", r"finite"]),
    (["--jobs", "0"], [r"--jobs", r"\[1, \d+\]"]),
    (["--max-n", "5"], [r"--max-n", r"\[8, 4096\]"]),
])
def test_stress_rejects_bad_flags_before_writing(flags, needles, tmp_path, capsys):
    out = tmp_path / "res"
    rc, _, err = run_cli(["stress", "--out", str(out), *flags], capsys)
    assert_one_line_error(rc, err, needles, cmd="stress")
    assert not out.exists()


def test_stress_out_is_a_file(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    rc, _, err = run_cli(["stress", "--out", str(f), "--axes", "nu"], capsys)
    assert_one_line_error(rc, err, [r"--out", r"directory"], cmd="stress")
    assert f.read_text() == "x"


def test_report_stability_bad_results(tmp_path, capsys):
    md = tmp_path / "rep" / "stability.md"
    rc, _, err = run_cli(["report", "stability", str(tmp_path / "none"), str(md)], capsys)
    assert_one_line_error(rc, err, [r"RESULTS", r"runs\.jsonl"], cmd="report")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "runs.jsonl").write_text('{"axis": "delta", "outcome": "correct"}\n{"axis": "del')
    rc, _, err = run_cli(["report", "stability", str(bad), str(md)], capsys)
    assert_one_line_error(rc, err, [r"line 2", r"not valid JSON"], cmd="report")
    rc, _, err = run_cli(["report", "stability", str(bad), str(tmp_path / "x.html")], capsys)
    assert_one_line_error(rc, err, [r"\.md"], cmd="report")
    assert not (tmp_path / "rep").exists()


# ------------------------------------------------------- real processes (no warnings, no traceback)
@pytest.mark.parametrize("argv,needle", [
    (["solve", "f2", "--set", "delta=nan"], "delta"),
    (["solve", "f2", "--set", "load=log(x-2)"], "load"),
    (["solve", "f2", "--set", "N=8", "--set", "load=sqrt(x-0.6)"], "load"),
    (["solve", "f2", "--solver", "nosuch"], "nosuch"),
    (["export", "f2", "--set", "nu=0.5", "-o", "OUT"], "nu"),
])
def test_subprocess_one_line_no_traceback(argv, needle, tmp_path):
    argv = [str(tmp_path / "q.npz") if a == "OUT" else a for a in argv]
    env = {**os.environ, "PYTHONWARNINGS": "default"}
    p = subprocess.run([sys.executable, "-m", "dualfem", *argv], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=120)
    assert p.returncode == 2, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert needle in lines[0]
    assert p.stdout == ""
    assert _files(tmp_path) == []
