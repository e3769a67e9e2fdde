"""The stable facade dualfem/*.py (docs/plugins.md): each module names its API in ``__all__`` (no
``import *``), every name there resolves, and what a module re-exported by accident before it had
``__all__`` still resolves for one release with a DeprecationWarning."""
from __future__ import annotations

import importlib
from pathlib import Path

import pytest

FACADE = ["errors", "evaluator", "problem", "qp", "registry", "runner", "scene", "solution", "solver",
          "workspace", "dual_solver"]
ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", FACADE)
def test_facade_module_declares_all_and_every_name_resolves(name):
    mod = importlib.import_module(f"dualfem.{name}")
    assert isinstance(getattr(mod, "__all__", None), list) and mod.__all__, f"dualfem.{name} has no __all__"
    assert "import *" not in (ROOT / "dualfem" / f"{name}.py").read_text()
    for n in mod.__all__:
        assert hasattr(mod, n), f"dualfem.{name}.__all__ names {n!r}, which it does not define"


def test_star_import_gives_exactly_all():
    ns: dict = {}
    exec("from dualfem.qp import *", ns)
    assert sorted(k for k in ns if k != "__builtins__") == sorted(importlib.import_module("dualfem.qp").__all__)


def test_accidental_reexport_is_deprecated_not_removed():
    import dualfem.problem
    from dualfem.qp import QP

    with pytest.deprecated_call(match="import it from dualfem.qp"):
        assert dualfem.problem.QP is QP
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        dualfem.problem.nope  # noqa: B018
