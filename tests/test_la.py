"""The linear-algebra context (dualfem.numerics.la): chosen once per run, owned by the Workspace, shared by
the solver and the certificate; the CLI and the environment variable only choose it."""
import argparse
import os

import pytest

from dualfem.core.errors import InputError
from dualfem.numerics import factor as fb
from dualfem.numerics import la, operator_choice
from dualfem.numerics.la import LinearAlgebra


@pytest.fixture(autouse=True)
def _fresh(monkeypatch):
    monkeypatch.delenv(fb.ENV, raising=False)
    la.use(None)
    yield
    la.use(None)


def test_default_reads_the_environment_and_use_sets_the_process_context(monkeypatch):
    assert la.current() == LinearAlgebra(fb.available()[0])
    monkeypatch.setenv(fb.ENV, "superlu")
    assert la.current().factor == "superlu" == fb.get_default()
    mine = LinearAlgebra("superlu", operator="matrix_free", max_memory=2e9)
    with mine.active():
        assert la.current() is mine and fb.choose().name == "superlu"
    assert la.current() == LinearAlgebra.default()
    fb.set_default("superlu")                      # the old spelling sets the context's backend
    assert la.current().factor == "superlu" and la._CURRENT is not None
    fb.set_default(None)
    assert la._CURRENT is None
    with pytest.raises(InputError, match="operator must be one of"):
        LinearAlgebra("superlu", operator="fast")
    with pytest.raises(InputError, match="must be one of cudss, pardiso, cholmod, superlu"):
        LinearAlgebra("amg")                       # not a direct factorization
    with pytest.raises(InputError, match="max_memory"):
        LinearAlgebra("superlu", max_memory=-1)


def test_the_cli_chooses_the_context_and_writes_no_environment_variable():
    from dualfem.cli.main import apply_factor

    args = argparse.Namespace(factor="superlu", threads=2, max_memory=3.0)
    assert apply_factor(args) == "superlu"
    assert fb.ENV not in os.environ
    assert la.current() == LinearAlgebra("superlu", threads=2, max_memory=3_000_000_000)
    assert la.current().child_env() == {fb.ENV: "superlu"}          # what the bench harness hands its children
    assert la.current().memory_limit() <= 3_000_000_000
    with pytest.raises(InputError, match="factor"):
        apply_factor(argparse.Namespace(factor="mumps"))


def _f2():
    from dualfem.workspace import Workspace

    return Workspace("f2", {"N": 12})


def test_the_workspace_owns_the_context_shared_by_solver_and_certificate(monkeypatch):
    from dualfem.numerics import ksolver
    from dualfem.workspace import Workspace

    seen = []
    real = ksolver.KSolver.__init__

    def spy(self, qp, *a, **k):
        real(self, qp, *a, **k)
        seen.append(self.la)

    monkeypatch.setattr(ksolver.KSolver, "__init__", spy)
    ws = Workspace("f2", {"N": 12}, factor="superlu")
    assert ws.la.factor == "superlu" and la._CURRENT is None
    sol = ws.solve("pdas")
    assert str(sol.status) == "solved"
    assert seen and all(c is ws.la for c in seen)          # the certificate's K-solver took the workspace's
    assert la._CURRENT is None                             # active only while the workspace works


def test_the_operator_is_chosen_once_per_run(monkeypatch):
    from dualfem.experiments.runner import run

    calls = []
    real = operator_choice.choose_operator

    def counting(*a, **k):
        calls.append(a[1] if len(a) > 1 else k.get("asked"))
        return real(*a, **k)

    monkeypatch.setattr(operator_choice, "choose_operator", counting)
    ws = _f2()
    sol = run("pdas", ws.qp, {})
    assert str(sol.status) == "solved"
    # skip and setup share the solver's choice; the certificate reuses the solver's reduction
    assert calls == ["auto"], calls


def test_the_memory_budget_enters_the_operator_choice():
    ws = _f2()
    tiny = LinearAlgebra(fb.available()[0], max_memory=1000)
    with pytest.raises(InputError, match="available 0.0 GB"):
        tiny.choose_operator(ws.qp)
    assert LinearAlgebra(fb.available()[0]).choose_operator(ws.qp)[0] == "dense"


def test_a_command_run_in_process_leaves_no_context_behind(capsys):
    from dualfem.cli.main import main

    assert main(["solve", "f2", "--set", "N=8", "--factor", "superlu", "--max-memory", "4", "--json"]) == 0
    assert '"factor": "superlu"' in capsys.readouterr().out
    assert la.chosen() is None and fb.ENV not in os.environ
