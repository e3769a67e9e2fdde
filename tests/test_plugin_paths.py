"""The built-in plugins import the plugin API from the stable paths docs/plugins.md promises third-party
authors (:data:`_imports.PLUGIN_PATHS`), never from the module behind one: a name that a stable path
re-exports is imported from that path; names with no stable path (``dualfem.numerics.*``,
``dualfem.core.expressions``, ...) keep their own module."""
from __future__ import annotations

import ast
import importlib

from _imports import PLUGIN_PATHS, module_files


def _stable_names() -> dict[int, str]:
    """id(object) -> the stable path that exports it (``__all__``)."""
    out: dict[int, str] = {}
    for path in sorted(PLUGIN_PATHS):
        mod = importlib.import_module(path)
        for name in mod.__all__:
            out.setdefault(id(getattr(mod, name)), path)
    return out


def _plugin_imports() -> list[tuple[str, int, str, str]]:
    """(plugin module, line, imported module, name) of every ``from dualfem.<room>... import name`` in
    solvers/ and problems/ (function-local imports included)."""
    out = []
    for mod, f in module_files().items():
        if not mod.startswith(("dualfem.solvers", "dualfem.problems")):
            continue
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").startswith(
                    ("dualfem.core.", "dualfem.numerics.")):
                out += [(mod, node.lineno, node.module, a.name) for a in node.names]
    return out


def test_builtin_plugins_import_from_the_stable_paths():
    stable = _stable_names()
    seen = _plugin_imports()
    assert any(m == "dualfem.core.expressions" for _, _, m, _ in seen)     # guard the guard: the scan sees them
    bad = []
    for src, line, module, name in seen:
        obj = getattr(importlib.import_module(module), name, None)
        if obj is not None and not isinstance(obj, type(importlib)) and id(obj) in stable:
            bad.append(f"{src}:{line} imports {name} from {module}: use {stable[id(obj)]}")
    assert not bad, "\n".join(bad)
