"""The import graph of dualfem (module-level and function-local imports), from the source text.

Rooms, in the one direction imports may point (a module may import its own room and the rooms to
its left; the three plugin-side rooms in the middle do not import each other):

    core  <-  numerics  <-  {solvers, problems, post}  <-  verify  <-  experiments  <-  reports  <-  cli

The top-level modules ``dualfem/*.py`` are the stable facade of docs/plugins.md: they may import
any room, and no room imports them, except that the plugins import the stable paths that re-export
core and numerics only (:data:`PLUGIN_PATHS`), as third-party plugins do. So are the deprecated shims
of :data:`SHIMS` (an old path kept for one release after its module moved up a room: it imports the new
path, and no module imports it). Run as a script for a summary (upward edges, cycles, function-local
imports): ``python tests/_imports.py``.
"""
from __future__ import annotations

import ast
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LEVEL = {"core": 0, "numerics": 1, "solvers": 2, "problems": 2, "post": 2, "verify": 2.5, "experiments": 3,
         "reports": 4, "cli": 5, "facade": 6, "scenes": 0}
#: deprecated old paths of moved modules: facade-like (they import the new path; no room imports them)
SHIMS = frozenset({"dualfem.core.grade"})
#: where the package dualfem.<room> lives in the source tree (pyproject's package-dir)
SOURCE = {"solvers": ROOT / "solvers", "problems": ROOT / "problems"}


@dataclass(frozen=True)
class Edge:
    src: str            # importing module (dotted)
    dst: str            # imported module or package (dotted)
    local: bool         # inside a function body
    line: int


def module_files() -> dict[str, Path]:
    """Dotted module name -> file, for every module of dualfem (plugins included)."""
    out = {}
    for base, prefix in ((ROOT / "dualfem", "dualfem"), (SOURCE["solvers"], "dualfem.solvers"),
                         (SOURCE["problems"], "dualfem.problems")):
        for f in sorted(base.rglob("*.py")):
            parts = list(f.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([prefix, *parts])] = f
    return out


def room(mod: str) -> str | None:
    """The room of a dualfem module (None outside dualfem)."""
    p = mod.split(".")
    if mod in SHIMS:
        return "facade"
    if p[0] != "dualfem":
        return None
    if len(p) == 1 or p[1] not in LEVEL:
        return "facade"
    return p[1]


def _resolve(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def edges(files: dict[str, Path] | None = None) -> list[Edge]:
    """Every import of a dualfem module by a dualfem module (``from a import b`` counts as a.b when b
    is a module)."""
    files = module_files() if files is None else files
    out: list[Edge] = []
    for mod, f in files.items():
        tree = ast.parse(f.read_text(), str(f))
        local = {id(n) for fn in ast.walk(tree) if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, f.name == "__init__.py", node)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            for t in targets:
                if t.startswith("dualfem"):
                    out.append(Edge(mod, t, id(node) in local, node.lineno))
    return out


#: the stable paths of docs/plugins.md that re-export only core and numerics: the built-in plugins import
#: them as third-party plugins do (:func:`plugin_path`); the other facade modules (runner, workspace,
#: results) re-export experiments and stay out of a plugin's reach
PLUGIN_PATHS = frozenset({"dualfem.errors", "dualfem.evaluator", "dualfem.laws", "dualfem.problem", "dualfem.qp",
                          "dualfem.registry", "dualfem.scene", "dualfem.solution", "dualfem.solver",
                          "dualfem.dual_solver"})


def plugin_path(e: Edge) -> bool:
    """A plugin (solvers, problems) importing a stable path of :data:`PLUGIN_PATHS`: allowed."""
    return room(e.src) in ("solvers", "problems") and e.dst in PLUGIN_PATHS


def upward(es: list[Edge]) -> list[Edge]:
    """Edges that point against the room order (or between two different middle rooms, or into the facade
    other than a plugin's stable path, :func:`plugin_path`)."""
    bad = []
    for e in es:
        a, b = room(e.src), room(e.dst)
        if a is None or b is None or a == b or a == "facade" or plugin_path(e) or e.dst == "dualfem":
            continue            # the package itself (its __init__: the version, core names) as in the facade test
        if LEVEL[b] > LEVEL[a] or (LEVEL[b] == LEVEL[a]) or b == "facade":
            bad.append(e)
    return bad


def plugin_cross_imports(es: list[Edge]) -> list[Edge]:
    """Solver plugins that import another solver plugin module (shared pieces belong in numerics)."""
    return [e for e in es if e.src.startswith("dualfem.solvers.") and e.dst.startswith("dualfem.solvers.")]


def cycles(es: list[Edge]) -> list[list[str]]:
    """Strongly connected components (size > 1) of the module-level import graph."""
    graph: dict[str, set[str]] = {}
    for e in es:
        if not e.local and e.src != e.dst:
            graph.setdefault(e.src, set()).add(e.dst)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:             # Tarjan, iterative enough for this graph's depth
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def summary() -> str:
    es = edges()
    up = upward(es)
    rooms = Counter((room(e.src), room(e.dst)) for e in up)
    lines = [f"imports between dualfem modules: {len(es)} ({sum(e.local for e in es)} function-local)",
             f"upward or sideways edges: {len(up)} "
             + ", ".join(f"{a}->{b} {c}" for (a, b), c in sorted(rooms.items())),
             f"solver plugins importing each other: {len(plugin_cross_imports(es))}",
             f"module-level cycles: {len(cycles(es))}"]
    lines += [f"  cycle: {' -> '.join(c)}" for c in cycles(es)]
    lines += [f"  {e.src}:{e.line} -> {e.dst}{' (local)' if e.local else ''}" for e in up]
    return "\n".join(lines)


if __name__ == "__main__":
    print(summary())
