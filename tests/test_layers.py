"""The rooms import in one direction only, function-local imports included (see tests/_imports.py and
docs/layout.md), the core imports no plugin, solver plugins do not import each other, and the
built-in plugins are found through entry points like third-party ones (their names reserved)."""
from __future__ import annotations

import pytest
from _imports import PLUGIN_PATHS, Edge, cycles, edges, plugin_cross_imports, plugin_path, room, upward

from dualfem.core import registry
from dualfem.core.errors import InputError
from dualfem.core.solver import Solver


@pytest.fixture(scope="module")
def graph() -> list[Edge]:
    return edges()


def _show(es: list[Edge]) -> str:
    return "\n".join(f"{e.src}:{e.line} -> {e.dst}{' (function-local)' if e.local else ''}" for e in es)


def test_the_scanner_sees_every_kind_of_import(graph):
    """Guard the guard: module-level, function-local and relative imports are all found."""
    kinds = {(e.src, e.local) for e in graph}
    assert ("dualfem.experiments.runner", False) in kinds
    assert any(e.local for e in graph)
    assert any(e.src.startswith("dualfem.problems.thin_defect") and e.dst == "dualfem.problems.loads" for e in graph)
    fake = upward([Edge("dualfem.core.qp", "dualfem.numerics.linalg", True, 1),
                   Edge("dualfem.solvers.pdas", "dualfem.post.fields", False, 1),
                   Edge("dualfem.cli.main", "dualfem.core.qp", False, 1)])
    assert [e.src for e in fake] == ["dualfem.core.qp", "dualfem.solvers.pdas"]


def test_imports_point_one_way(graph):
    bad = upward(graph)
    assert not bad, "imports against the room order core <- numerics <- {solvers, problems, post} <- " \
                    "experiments <- reports <- cli:\n" + _show(bad)


def test_no_room_imports_the_facade(graph):
    bad = [e for e in graph if room(e.src) != "facade" and room(e.dst) == "facade" and e.dst != "dualfem"
           and not plugin_path(e)]
    assert not bad, _show(bad)


def test_the_plugins_stable_paths_reexport_core_and_numerics_only(graph):
    """What makes a plugin's import of a stable path safe: those facade modules import nothing upstairs."""
    bad = [e for e in graph if e.src in PLUGIN_PATHS and room(e.dst) not in ("core", "numerics", "facade")]
    assert not bad, _show(bad)
    assert plugin_path(Edge("dualfem.solvers.pdas", "dualfem.solver", False, 1))
    assert not plugin_path(Edge("dualfem.solvers.pdas", "dualfem.runner", False, 1))
    assert upward([Edge("dualfem.solvers.pdas", "dualfem.runner", False, 1)])


def test_no_import_cycles(graph):
    assert cycles(graph) == []


def test_solver_plugins_do_not_import_each_other(graph):
    bad = plugin_cross_imports(graph)
    assert not bad, "shared algorithm pieces belong in dualfem.numerics:\n" + _show(bad)


def test_builtin_plugins_come_from_entry_points_and_keep_their_names():
    reg = registry.solvers()
    assert {"uzawa", "uzawa_auto", "pdas"} <= set(reg) and "thin_defect" in registry.problems()

    class Impostor(Solver):
        name = "pdas"

    with pytest.raises(InputError, match="built-in"):
        registry.register_solver(Impostor)
    assert registry.solvers()["pdas"] is reg["pdas"]


def test_every_package_is_installed():
    """A non-editable install ships exactly the packages pyproject.toml lists: every package of the tree."""
    import tomllib

    from _imports import ROOT

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.relative_to(ROOT).parent.parts) for p in (ROOT / "dualfem").rglob("__init__.py")}
    found |= {"dualfem.solvers", "dualfem.problems", "dualfem.scenes"}
    found |= {"dualfem.problems." + ".".join(p.relative_to(ROOT / "problems").parent.parts)
              for p in (ROOT / "problems").rglob("*/__init__.py")}
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"
