"""Issue 26, item 3: the runner trusts nothing a plugin says about itself.

Small hostile plugins, one per class of attack: a declared tolerance that certifies anything, NaN/inf
answers, a plugin writing into the QP it is given, a problem preset taking a built-in scene name,
SystemExit and other BaseExceptions, prints (Python and file descriptor 1) corrupting ``--json``,
malformed return values, and ``--json`` with a closed stdout. Each test fails without its fix.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core import registry
from dualfem.core.errors import InputError
from dualfem.core.problem import Problem
from dualfem.core.scene import PresetConflictWarning, load_scene, preset_conflicts, presets
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.experiments.compare import compare_solvers
from dualfem.experiments.runner import fingerprint, make_solver, run

SMALL = ["--set", "N=8"]


@pytest.fixture(scope="module")
def qp():
    return load_scene("f1", {"N": 8}).build()



def exact_answer(qp):
    return run("pdas", qp)


class Zero(Solver):
    """Claims 'solved' with x = 0: right only if the certification is fooled."""

    name = "hostile_zero"
    defaults = {"tol": 1e-8}

    def solve(self):
        return Solution(solver=self.name, status=Status.SOLVED, x=np.zeros(self.qp.n),
                        multipliers=np.zeros(self.qp.m))


# --------------------------------------------------------------------- declared tolerance
BAD_TOLERANCES = [float("nan"), float("inf"), 10.0, 1.0, 0.0, -1e-6, "1e-6", True, None]


@pytest.mark.parametrize("bad", BAD_TOLERANCES, ids=repr)
def test_bad_declared_tolerance_refused_at_registration(bad, register):
    cls = type("BadTol", (Zero,), {"name": "hostile_badtol", "tolerance": bad})
    with pytest.raises(InputError, match=r"hostile_badtol.*tolerance.*finite number in \(0, 1\)"):
        register(cls)
    assert "hostile_badtol" not in registry.solvers()


@pytest.mark.parametrize("bad", BAD_TOLERANCES, ids=repr)
def test_bad_tolerance_set_in_init_refused_at_instantiation(bad):
    class SetsIt(Zero):
        def validate(self):
            self.tolerance = bad

    with pytest.raises(InputError, match="tolerance"):
        SetsIt()


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 10.0])
def test_bad_tolerance_set_after_init_refused_by_the_runner(bad, qp):
    s = Zero()
    s.tolerance = bad
    with pytest.raises(InputError, match="tolerance"):
        run(s, qp)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 10.0])
def test_tolerance_changed_during_the_run_is_an_error(bad, qp):
    class Changes(Zero):
        def solve(self):
            self.tolerance = bad
            return super().solve()

    sol = run(Changes(), qp)
    assert sol.status == Status.ERROR and "tolerance" in sol.message


def test_exact_changed_during_the_run_is_an_error(qp):
    class Changes(Zero):
        def solve(self):
            type(self).exact = False          # skip the certificate?
            return super().solve()

    sol = run(Changes(), qp)
    assert sol.status == Status.ERROR and "exact" in sol.message


def test_zero_answer_is_never_solved(qp):
    assert run(Zero(), qp).status == Status.INACCURATE


# -------------------------------------------------------------------- NaN / inf anywhere
@pytest.mark.parametrize("where, value", [("x", np.nan), ("x", np.inf), ("multipliers", np.nan),
                                          ("multipliers", -np.inf)])
def test_nan_or_inf_is_never_solved(where, value, qp):
    good = exact_answer(qp)

    class Poisoned(Solver):
        name = "hostile_nan"

        def solve(self):
            x, mu = good.x.copy(), good.multipliers.copy()
            (x if where == "x" else mu)[0] = value
            return Solution(solver=self.name, status=Status.SOLVED, x=x, multipliers=mu)

    sol = run(Poisoned(), qp)
    assert sol.status != Status.SOLVED and "NaN/inf" in sol.message


@pytest.mark.parametrize("exact", [True, False])
def test_nan_residuals_are_never_solved(exact, qp):
    """Finite but huge x, mu: K x overflows, the stationarity residual is NaN (and NaN > tol is False)."""
    class Huge(Solver):
        name = "hostile_huge"

        def solve(self):
            q = self.qp
            return Solution(self.name, Status.SOLVED, x=np.full(q.n, 1e308), multipliers=np.full(q.m, 1e308))

    cls = type("H", (Huge,), {"exact": exact})
    with np.errstate(all="ignore"):
        sol = run(cls(), qp)
    assert sol.status == Status.NUMERICAL_ERROR and "not finite" in sol.message, (sol.status, sol.message)


def test_plugin_cannot_supply_residuals_or_certificate(qp):
    """Runner-owned fields of the Solution are the runner's: a plugin's residuals/certificate are dropped."""
    class Liar(Solver):
        name = "hostile_liar"
        exact = False

        def solve(self):
            s = Solution(solver=self.name, status=Status.SOLVED, x=None, multipliers=None)
            s.residuals = {"stationarity": 0.0, "primal": 0.0, "dual": 0.0, "complementarity": 0.0,
                           "energy": -1.0, "finite": True}
            s.info.update(certificate={"bound": 0.0, "active_set": 0.0, "value": 0.0}, claimed_status="solved")
            return s

    sol = run(Liar(), qp)
    assert sol.status == Status.ERROR and "without returning x" in sol.message

    class Liar2(Zero):
        exact = False

        def solve(self):
            s = super().solve()
            s.info["certificate"] = {"bound": 0.0, "active_set": 0.0, "value": 0.0}
            return s

    sol = run(Liar2(), qp)
    assert sol.status == Status.INACCURATE and "certificate" not in sol.info


# -------------------------------------------------------------- the QP handed out is read-only
class DoublesF(Solver):
    name = "hostile_doubles_f"

    def setup(self, qp):
        qp.F *= 2
        self.qp = qp

    def solve(self):
        return Solution(solver=self.name, status=Status.SOLVED, x=np.zeros(self.qp.n))


@pytest.mark.parametrize("attack", ["F *= 2", "K.data *= 2", "B.data[:] = 0", "weights[:] = 1", "K_fixed",
                                    "local.dofs", "maps"])
def test_in_place_writes_to_the_qp_fail_and_leave_it_unchanged(attack, qp):
    before = fingerprint(qp)
    maps_before = {k: np.array(v, copy=True) for k, v in qp.maps.items()}

    class Writer(Zero):
        def setup(self, q):
            super().setup(q)
            if attack == "F *= 2":
                q.F *= 2
            elif attack == "K.data *= 2":
                q.K.data *= 2
            elif attack == "B.data[:] = 0":
                q.B.data[:] = 0
            elif attack == "weights[:] = 1":
                q.weights[:] = 1
            elif attack == "K_fixed":
                q.local.K_fixed.data[0] = 1.0
            elif attack == "local.dofs":
                q.local.dofs[0] = 0
            else:
                next(iter(q.maps.values()))[...] = 0

    sol = run(Writer(), qp)
    assert sol.status == Status.ERROR and "read-only" in sol.message, sol.message
    assert fingerprint(qp) == before
    assert all(np.array_equal(np.asarray(qp.maps[k]), v) for k, v in maps_before.items())


def test_replacing_an_attribute_changes_only_the_plugins_view(qp):
    F = qp.F.copy()

    class Replaces(Solver):
        name = "hostile_replaces"

        def setup(self, q):
            q.F = 2 * q.F                     # the plugin now solves another QP: certified against ours
            self.qp = q

        def solve(self):
            from dualfem.experiments.runner import run as inner
            ref = inner("pdas", self.qp)
            return Solution(solver=self.name, status=Status.SOLVED, x=ref.x, multipliers=ref.multipliers)

    sol = run(Replaces(), qp)
    assert np.array_equal(qp.F, F)
    assert sol.status == Status.INACCURATE


class Unlocks(Zero):
    """Makes the view writeable again and doubles F: the fingerprint catches it."""

    name = "hostile_unlocks"

    def setup(self, q):
        super().setup(q)
        q.F.flags.writeable = True
        q.F *= 2


def test_deliberate_change_is_caught_by_the_fingerprint(register):
    qp = load_scene("f1", {"N": 8}).build()
    sol = run(Unlocks(), qp)
    assert sol.status == Status.ERROR and "changed the QP" in sol.message and sol.info["qp_changed"] == ["F"]


def test_a_change_is_caught_even_when_the_plugin_then_raises():
    class UnlocksAndRaises(Unlocks):
        def solve(self):
            raise RuntimeError("and now I fail")

    qp = load_scene("f1", {"N": 8}).build()
    sol = run(UnlocksAndRaises(), qp)
    assert sol.status == Status.ERROR and sol.info["qp_changed"] == ["F"] and "changed the QP" in sol.message


def test_compare_stops_when_a_plugin_changes_the_qp(register):
    register(Unlocks)
    qp = load_scene("f1", {"N": 8}).build()
    with pytest.raises(InputError, match="hostile_unlocks.*changed the QP.*F"):
        compare_solvers(qp, ["hostile_unlocks", "pdas"])


def test_compare_later_solvers_see_the_original_qp(register):
    register(DoublesF)
    qp = load_scene("f1", {"N": 8}).build()
    F = qp.F.copy()
    out = compare_solvers(qp, ["hostile_doubles_f", "pdas", "clarabel"])
    runs = {r["solver"]: r for r in out["runs"]}
    assert runs["hostile_doubles_f"]["status"] == "error"
    assert runs["pdas"]["grade"] == "correct" and np.array_equal(qp.F, F)


def test_the_view_shares_the_factorizations(qp):
    """No copy and no second factorization: the certification reuses what the solver factorized."""
    from dualfem.numerics.linalg import store_of

    q = load_scene("f1", {"N": 8}).build()
    sol = run("pdas", q)
    assert sol.ok and store_of(q).factorizations == 1


# --------------------------------------------------------- problem presets: built-in names win
class Taker(Problem):
    name = "hostile_taker"
    description = "a problem plugin whose presets take built-in scene names"
    defaults = {"N": 8}
    presets = {"f2": {"N": 8}, "curved": {"N": 8}, "hostile_own": {"N": 8}}

    def build(self):  # pragma: no cover - never reached for f2
        raise AssertionError("the built-in f2 was taken over")


def test_problem_preset_cannot_take_a_builtin_scene_name(register):
    register(Taker, "problem")
    pre = presets()
    assert pre["f2"][0] == "thin_defect" and pre["hostile_own"][0] == "hostile_taker"
    assert "curved" not in pre                       # the library's curved.toml stays reachable
    msgs = preset_conflicts()
    assert any("'f2'" in m and "hostile_taker" in m and "thin_defect" in m for m in msgs), msgs
    assert any("'curved'" in m and "library" in m for m in msgs), msgs
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        prob = load_scene("f2", {"N": 8})
    assert prob.name == "thin_defect"
    assert any(issubclass(x.category, PresetConflictWarning) and "hostile_taker" in str(x.message) for x in w)
    with pytest.warns(PresetConflictWarning, match="curved"):
        assert load_scene("curved").name == "thin_defect"


def test_list_names_the_refused_preset(register, capsys):
    register(Taker, "problem")
    assert main(["list", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["scenes"]["f2"]["problem"] == "thin_defect"
    assert any("hostile_taker" in e and "'f2'" in e for e in d["plugin_errors"])


class LoudProblem(Problem):
    name = "hostile_loud_problem"
    description = "a problem plugin that prints, exits or returns garbage"
    defaults = {"N": 8, "mode": "print"}
    presets = {"hostile_loud_scene": {"N": 8}, "hostile_bad_preset": "not a dict"}

    def build(self):
        print("problem build prints")
        if self.params["mode"] == "exit":
            raise SystemExit(0)
        if self.params["mode"] == "none":
            return None
        return load_scene("f1", {"N": self.params["N"]}).build()


@pytest.mark.parametrize("mode, rc, words", [("print", 0, None), ("exit", 2, "SystemExit"),
                                             ("none", 2, "NoneType, not a dualfem QP")])
def test_problem_plugin_build_is_contained(mode, rc, words, register, capsys):
    register(LoudProblem, "problem")
    got = main(["solve", "hostile_loud_scene", "--set", f"mode={mode}", "--solver", "pdas", "--json"])
    out, err = capsys.readouterr()
    assert got == rc and "Traceback" not in err and "problem build prints" in err
    if words is None:
        assert json.loads(out)["status"] == "solved"
    else:
        assert out == "" and words in err and "hostile_loud_problem" in err
    assert any("hostile_bad_preset" in m for m in preset_conflicts())


# ------------------------------------------------------- SystemExit and other BaseExceptions
class Exits(Zero):
    name = "hostile_exits"
    where = "solve"
    exc: BaseException = SystemExit(0)

    def setup(self, q):
        super().setup(q)
        if self.where == "setup":
            raise self.exc

    def solve(self):
        raise self.exc


class Custom(BaseException):
    pass


@pytest.mark.parametrize("exc", [SystemExit(0), SystemExit(3), GeneratorExit(), Custom("boom")], ids=repr)
@pytest.mark.parametrize("where", ["setup", "solve"])
def test_base_exceptions_become_errors(exc, where, qp):
    cls = type("E", (Exits,), {"exc": exc, "where": where})
    sol = run(cls(), qp)
    assert sol.status == Status.ERROR and type(exc).__name__ in sol.message


def test_a_raising_check_params_is_an_error(qp):
    class BadCheck(Zero):
        def check_params(self):
            if getattr(self, "armed", False):
                raise SystemExit("check_params exits")

    s = BadCheck()
    s.armed = True
    sol = run(s, qp)
    assert sol.status == Status.ERROR and "SystemExit" in sol.message


def test_keyboard_interrupt_still_stops(qp):
    cls = type("E", (Exits,), {"exc": KeyboardInterrupt()})
    with pytest.raises(KeyboardInterrupt):
        run(cls(), qp)


def test_cli_solve_with_systemexit_plugin_reports_error(register, capsys):
    register(Exits)
    rc = main(["solve", "f1", *SMALL, "--solver", "hostile_exits", "--json"])
    out, err = capsys.readouterr()
    rec = json.loads(out)
    assert rc == 1 and rec["status"] == "error" and "SystemExit" in rec["message"]


def test_plugin_init_raising_is_refused_cleanly(register, capsys):
    class BadInit(Zero):
        name = "hostile_bad_init"

        def validate(self):
            raise SystemExit("bye")

    register(BadInit)
    rc = main(["solve", "f1", *SMALL, "--solver", "hostile_bad_init"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and "hostile_bad_init" in err and "SystemExit" in err


# -------------------------------------------------------------------- prints and --json
class Chatty(Solver):
    name = "hostile_chatty"

    def __init__(self, **p):
        print("hello from __init__")
        super().__init__(**p)

    def setup(self, q):
        print("hello from setup")
        sys.__stdout__.write("")              # nothing: a write to the real stdout object
        super().setup(q)

    def solve(self):
        print("hello from solve")
        return exact_answer(self.qp)


def test_prints_do_not_corrupt_json(register, capsys):
    register(Chatty)
    rc = main(["solve", "f1", *SMALL, "--solver", "hostile_chatty", "--json"])
    out, err = capsys.readouterr()
    rec = json.loads(out)                     # exactly one JSON object
    assert rc == 0 and rec["status"] == "solved"
    assert "hello from setup" in err and "hello from solve" in err and "hello from __init__" in err


class BrokenMissing(Zero):
    name = "hostile_broken_missing"

    @classmethod
    def missing(cls):
        print("missing() prints")
        raise SystemExit("missing() exits")


def test_a_raising_missing_is_contained(register, capsys):
    register(BrokenMissing)
    assert main(["list", "--json"]) == 0
    out, err = capsys.readouterr()
    d = json.loads(out)
    assert "SystemExit" in d["solvers"]["hostile_broken_missing"]["missing"] and "missing() prints" in err
    assert main(["list"]) == 0
    rc = main(["solve", "f1", *SMALL, "--solver", "hostile_broken_missing"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and "hostile_broken_missing" in err
    qp = load_scene("f1", {"N": 8}).build()
    sol = run(BrokenMissing(), qp)
    assert sol.status == Status.ERROR and "SystemExit" in sol.message


PLUGIN_SRC = '''
import os, sys
import numpy as np
print("import-time print")
os.write(1, b"import-time fd 1 write\\n")
from dualfem.core.registry import register_solver
from dualfem.core.solver import Solver
from dualfem.experiments.runner import run


@register_solver
class Loud(Solver):
    name = "hostile_loud"

    def setup(self, qp):
        print("setup print")
        os.write(1, b"setup fd 1 write\\n")
        self.qp = qp

    def solve(self):
        os.write(1, b"solve fd 1 write\\n")
        print("solve print", flush=False)
        return run("pdas", self.qp)
'''


def installed(tmp_path: Path, modules: dict[str, str]) -> dict:
    """A subprocess environment in which the plugin ``modules`` (name -> source; each one entry point
    of the group dualfem.solvers) are 'installed': a dist-info on PYTHONPATH, as pip writes it."""
    src = tmp_path / "src"
    src.mkdir()
    for name, code in modules.items():
        (src / f"{name}.py").write_text(code)
    dist = tmp_path / "site" / "hostile_plugins-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: hostile-plugins\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[dualfem.solvers]\n" + "".join(f"{n} = {n}\n" for n in modules))
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "site"), str(src), env.get("PYTHONPATH", "")])
    return env


@pytest.fixture
def loud_env(tmp_path):
    """A subprocess environment in which a plugin printing at import time is 'installed'."""
    return installed(tmp_path, {"hostile_loud": PLUGIN_SRC})


def test_plugin_exiting_at_import_is_listed_not_fatal(tmp_path):
    env = installed(tmp_path, {"hostile_exit_import": "raise SystemExit(0)\n"})
    r = subprocess.run([sys.executable, "-m", "dualfem", "list", "--json"], env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    errors = json.loads(r.stdout)["plugin_errors"]
    assert any("hostile_exit_import" in e and "SystemExit" in e for e in errors), errors
    r = subprocess.run([sys.executable, "-m", "dualfem", "solve", "f1", *SMALL, "--json"], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and json.loads(r.stdout)["status"] == "solved", r.stderr


SLEEPY_SRC = '''
import sys, time
from dualfem.core.registry import register_solver
from dualfem.core.solver import Solver


@register_solver
class Sleepy(Solver):
    name = "hostile_sleepy"

    def solve(self):
        print("ready", file=sys.stderr, flush=True)
        time.sleep(60)
'''


def test_a_real_ctrl_c_still_interrupts(tmp_path):
    import signal

    env = installed(tmp_path, {"hostile_sleepy": SLEEPY_SRC})
    # a terminal's Ctrl-C reaches a process whose SIGINT is at its default; a suite started in the background
    # of a non-interactive shell (nohup sh -c ... &) inherits SIGINT ignored, and Python then keeps it ignored
    p = subprocess.Popen([sys.executable, "-m", "dualfem", "solve", "f1", *SMALL, "--solver", "hostile_sleepy",
                          "--json"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for line in p.stderr:
            if "ready" in line:
                break
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    finally:
        p.kill()
    assert p.returncode == 130 and "interrupted" in err and out == "", (p.returncode, err)


def test_keyboard_interrupt_subclass_is_contained(qp):
    class Fake(KeyboardInterrupt):
        pass

    cls = type("E", (Exits,), {"exc": Fake("not a Ctrl-C")})
    sol = run(cls(), qp)
    assert sol.status == Status.ERROR and "Fake" in sol.message


def test_bench_flags_a_run_that_changed_the_qp(register):
    from dualfem.experiments.curves import timed_runs

    register(Unlocks)
    qp = load_scene("f1", {"N": 8}).build()
    task = {"hard_limit": 60, "cold_setup": True, "tol": None}
    sol, setups, solves, done, note, _ = timed_runs(task, qp, "hostile_unlocks", {}, lambda *a: None, False, 3)
    assert sol.status == Status.ERROR and "changed the QP" in sol.message and done == 1


def test_fd_level_and_import_time_prints_do_not_corrupt_json(loud_env):
    r = subprocess.run([sys.executable, "-m", "dualfem", "solve", "f1", *SMALL, "--solver", "hostile_loud",
                        "--json"], env=loud_env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rec = json.loads(r.stdout)
    assert rec["status"] == "solved"
    for words in ("import-time print", "import-time fd 1 write", "setup print", "setup fd 1 write",
                  "solve fd 1 write", "solve print"):
        assert words in r.stderr, words
    r = subprocess.run([sys.executable, "-m", "dualfem", "list", "--json"], env=loud_env,
                       capture_output=True, text=True, timeout=300)
    assert "hostile_loud" in json.loads(r.stdout)["solvers"]


# ------------------------------------------------------------------- malformed return values
def _returns(value_fn):
    class Returns(Solver):
        name = "hostile_returns"

        def solve(self):
            return value_fn(self.qp)

    return Returns


MALFORMED = {
    "None": (lambda q: None, "NoneType, not a Solution"),
    "a dict": (lambda q: {"x": np.zeros(q.n)}, "dict, not a Solution"),
    "x too short": (lambda q: Solution("s", Status.SOLVED, x=np.zeros(q.n - 1)), "x of shape"),
    "x 2-D": (lambda q: Solution("s", Status.SOLVED, x=np.zeros((q.n, 1))), "x of shape"),
    "mu too long": (lambda q: Solution("s", Status.SOLVED, x=np.zeros(q.n), multipliers=np.zeros(q.m + 1)),
                    "multipliers of shape"),
    "x strings": (lambda q: Solution("s", Status.SOLVED, x=np.array(["a"] * q.n)), "real numbers"),
    "x objects": (lambda q: Solution("s", Status.SOLVED, x=[object()] * q.n), "real numbers"),
    "x complex": (lambda q: Solution("s", Status.SOLVED, x=np.zeros(q.n, complex)), "real numbers"),
    "unknown status": (lambda q: Solution("s", "great", x=np.zeros(q.n)), "unknown status"),
    "solved without x": (lambda q: Solution("s", Status.SOLVED), "without returning x"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_solution_is_an_error_not_a_traceback(case, qp):
    fn, words = MALFORMED[case]
    sol = run(_returns(fn)(), qp)
    assert sol.status == Status.ERROR and words in sol.message, sol.message


def test_malformed_solution_through_the_cli(register, capsys):
    register(_returns(lambda q: Solution("s", Status.SOLVED, x=np.zeros(q.n - 1))))
    rc = main(["solve", "f1", *SMALL, "--solver", "hostile_returns", "--json"])
    out, err = capsys.readouterr()
    assert rc == 1 and json.loads(out)["status"] == "error" and "Traceback" not in err


def test_make_solver_of_a_builtin_is_unchanged():
    assert make_solver("pdas").name == "pdas"


# ------------------------------------------------------------------------- closed stdout
def test_json_with_closed_stdout_is_one_clear_line():
    code = ("import os, sys; os.close(1); sys.stdout = None; from dualfem.cli.main import main; "
            "sys.exit(main(['solve', 'f1', '--set', 'N=8', '--json']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       env=dict(os.environ, MPLBACKEND="Agg"))
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1 and "standard output is closed" in lines[0], r.stderr


def test_closed_stdout_in_a_real_shell(tmp_path):
    exe = Path(sys.executable).with_name("dualfem")
    if not exe.exists():
        pytest.skip("the dualfem console script is not installed next to this Python")
    r = subprocess.run(["sh", "-c", f"{exe} solve f1 --set N=8 --json >&-"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    r = subprocess.run(["sh", "-c", f"{exe} solve f1 --set N=8 >&-"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


def test_doc_lists_the_guards():
    text = (Path(__file__).parents[1] / "docs" / "plugins.md").read_text()
    assert "read-only" in text and "(0, 1)" in text and "SystemExit" in text
