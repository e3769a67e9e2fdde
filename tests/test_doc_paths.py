"""Every module path the documentation names resolves, and the README's Python example runs.

Checked texts (:func:`texts`): README.md, docs/ (with docs/templates), benchmarks/*.toml and
benchmarks/*.py, the reports (reports/**/*.md), and the sources of dualfem/, problems/ and
solvers/ (docstrings and the text they render into reports). In each:

* a dotted path ``dualfem.xxx[.yyy]`` must import, or be an attribute (a dataclass field counts)
  of an importable module;
* a Sphinx reference ``:mod:/:func:/:class:/:meth:/:data:/:attr:/:exc:`X.Y``` in the Python
  sources must resolve: absolutely, relative to its package (``.base``), or as an attribute path of
  the module it is written in; ``problems.x`` / ``solvers.x`` are refused (they import only from
  the root of a checkout: the installed names are ``dualfem.problems.x`` / ``dualfem.solvers.x``);
* ``from dualfem.x import a, b`` must import ``a`` and ``b``;
* a repository file path (``dualfem/numerics/linalg.py``, ``tests/test_docs.py``, ...) must
  exist, except the files the plugin guide tells the reader to create (:data:`TO_CREATE`).

A committed report is regenerated only by its own command (README), so a report written before a
module moved may name the old path until then: :data:`STALE_UNTIL_REGENERATED` lists those, and
the report's generator (checked above like every source) must already write the new path.
"""
from __future__ import annotations

import dataclasses
import importlib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

DOTTED = re.compile(r"(?<![\w./-])dualfem(?:\.[A-Za-z_]\w*)+")
ROLE = re.compile(r":(?:mod|func|class|meth|data|attr|exc|obj):`~?(\.?[\w.]+)`")
FROM_IMPORT = re.compile(r"\bfrom\s+(dualfem(?:\.\w+)*)\s+import\s+\(?\s*([\w\s,]+?)\s*\)?\s*(?:$|[;`#\n])", re.M)
FILE = re.compile(r"(?<![\w/.-])((?:dualfem|problems|solvers|benchmarks|tests|scripts|docs|scenes|reports|examples)"
                  r"/[\w/.-]*\w\.(?:py|toml|md|sh|json|csv|npz))\b")

#: files the plugin guide and its templates tell the reader to create (they do not exist here)
TO_CREATE = {"problems/membrane.py", "solvers/my_pg.py", "solvers/my_fista.py"}

#: (report, old path): written before the module moved; the report's generator writes the new path
STALE_UNTIL_REGENERATED = {
    ("reports/benchmark.md", "dualfem.linalg.clear_cache"): "dualfem.numerics.linalg.store_of",
    ("reports/breadth.md", "dualfem.linalg.clear_cache"): "dualfem.numerics.linalg.store_of",
    ("reports/stress_breadth/stability.md", "dualfem.scaling"): "dualfem.numerics.scaling",
}


def texts() -> list[Path]:
    files = [REPO / "README.md", *sorted(REPO.glob("docs/**/*.md")), *sorted(REPO.glob("docs/templates/*.py")),
             *sorted(REPO.glob("benchmarks/*.toml")), *sorted(REPO.glob("benchmarks/*.py")),
             *sorted(REPO.glob("reports/**/*.md"))]
    for room in ("dualfem", "problems", "solvers"):
        files += sorted(REPO.glob(f"{room}/**/*.py"))
    return files


def _module_of(path: Path) -> str | None:
    """The import name of a source file (``problems/`` and ``solvers/`` install as dualfem.*)."""
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[0] in ("problems", "solvers"):
        parts = ["dualfem", *parts]
    if parts[0] != "dualfem":
        return None
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _has(obj, name: str):
    if hasattr(obj, name):
        return True, getattr(obj, name)
    if isinstance(obj, type) and (name in getattr(obj, "__annotations__", {})
                                  or (dataclasses.is_dataclass(obj)
                                      and name in {f.name for f in dataclasses.fields(obj)})):
        return True, None            # an instance attribute declared on the class
    return False, None


def _chain(obj, names: list[str]) -> bool:
    for n in names:
        ok, obj = _has(obj, n)
        if not ok:
            return False
        if obj is None:
            return n == names[-1]
    return True


def resolves(ref: str, here: str | None = None) -> bool:
    """True if ``ref`` imports, or is an attribute path of an importable module (or of ``here``)."""
    if ref.startswith("."):
        if here is None:
            return False
        is_pkg = Path(importlib.import_module(here).__file__).name == "__init__.py"
        base = here if is_pkg else here.rpartition(".")[0]
        for _ in range(len(ref) - len(ref.lstrip(".")) - 1):
            base = base.rpartition(".")[0]
        ref = f"{base}.{ref.lstrip('.')}"
    parts = ref.split(".")
    if parts[0] in ("problems", "solvers"):
        return False                 # importable only from a checkout's root; installed as dualfem.*
    for i in range(len(parts), 0, -1):
        try:
            mod = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        if _chain(mod, parts[i:]):
            return True
        break
    return here is not None and _chain(importlib.import_module(here), parts)


def references(path: Path) -> list[str]:
    """The unresolved references of one text, as ``'file: ref'`` lines."""
    text = path.read_text(encoding="utf-8")
    rel = path.relative_to(REPO).as_posix()
    here = _module_of(path) if path.suffix == ".py" else None
    refs = {r.rstrip(".") for r in DOTTED.findall(text)}
    if path.suffix == ".py":
        refs |= {r for r in ROLE.findall(text) if "." in r}
    bad = [r for r in sorted(refs) if not resolves(r, here)
           and (rel, r) not in STALE_UNTIL_REGENERATED]
    for mod, names in FROM_IMPORT.findall(text):
        for name in filter(None, (n.strip() for n in names.replace("\n", " ").split(","))):
            name = name.split()[0]
            if not resolves(f"{mod}.{name}"):
                bad.append(f"from {mod} import {name}")
    bad += [f for f in sorted(set(FILE.findall(text))) if not (REPO / f).exists() and f not in TO_CREATE]
    return [f"{rel}: {r}" for r in bad]


@pytest.mark.parametrize("path", texts(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_named_path_resolves(path):
    bad = references(path)
    assert not bad, "\n".join(bad)


def test_the_checker_finds_rot():
    """The checker itself: the paths a review found rotten are refused, their new homes accepted."""
    for old in ("dualfem.linalg.clear_cache", "dualfem.figures", "dualfem.scaling", "dualfem.core.certify",
                "dualfem.core.runner", "dualfem.io.atomic_write", "dualfem.polish.active_set_polish",
                "problems.loads", "solvers.uzawa"):
        assert not resolves(old), old
    for new in ("dualfem.numerics.linalg.store_of", "dualfem.post.figures", "dualfem.numerics.scaling",
                "dualfem.numerics.certify", "dualfem.experiments.runner.run", "dualfem.core.io.atomic_write",
                "dualfem.numerics.linalg.LocalReduction.k_solve", "dualfem.experiments.row.Row.extra",
                "dualfem.runner.run", "dualfem.scene.load_scene", "dualfem.evaluator.certify", "dualfem.qp.QP",
                "dualfem.problems.loads", "dualfem.solvers.uzawa"):
        assert resolves(new), new
    assert resolves(".base", "dualfem.numerics.factor.ordering")
    assert not resolves(".nosuch", "dualfem.numerics.factor.ordering")
    assert resolves("Signorini.punch_force", "dualfem.problems.signorini")
    assert FILE.findall("see `dualfem/linalg.py` and tests/test_docs.py.") == ["dualfem/linalg.py",
                                                                              "tests/test_docs.py"]
    assert not (REPO / "dualfem/linalg.py").exists()
    assert FROM_IMPORT.findall("`from dualfem.post import figures; figures.plot(qp)`") == [("dualfem.post",
                                                                                           "figures")]


def test_stale_reports_are_only_waiting_for_regeneration():
    """A stale report path is listed only while the report still has it, and its generator is fixed."""
    generators = "\n".join(p.read_text(encoding="utf-8") for p in REPO.glob("dualfem/reports/*.py"))
    for (report, old), new in STALE_UNTIL_REGENERATED.items():
        assert not resolves(old) and resolves(new), (old, new)
        assert f"`{new}" in generators, f"the generator of {report} does not write {new}"
        assert not re.search(rf"`{re.escape(old)}[`.(]", generators), f"a generator still writes {old}"


# ------------------------------------------------------------------ the README's Python example
FENCE = re.compile(r"^```([a-z]*)[^\n]*\n(.*?)^```\s*$", re.S | re.M)


def readme_python() -> list[str]:
    return [code for lang, code in FENCE.findall((REPO / "README.md").read_text(encoding="utf-8"))
            if lang == "python"]


def test_readme_python_uses_the_stable_paths():
    blocks = readme_python()
    assert blocks, "README.md has no python block"
    for code in blocks:
        modules = re.findall(r"^\s*(?:from|import)\s+(dualfem[\w.]*)", code, re.M)
        assert modules, code
        for mod in modules:
            assert not mod.startswith(("dualfem.core", "dualfem.experiments", "dualfem.numerics")), \
                f"README imports {mod}: use the stable paths of docs/plugins.md (dualfem.scene, dualfem.runner, ...)"


def test_readme_python_runs(tmp_path, monkeypatch):
    """The README's Python blocks run, in order, in one namespace, from an empty directory."""
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for i, code in enumerate(readme_python()):
        exec(compile(code, f"README.md python block {i + 1}", "exec"), namespace)  # noqa: S102
    assert namespace["sol"].status.value == "solved"


def test_readme_scene_file_is_the_example_and_solves():
    """The scene file the README shows in full is examples/plate.toml, byte for byte, and it solves with
    its crack closed (the contact constraints active)."""
    from dualfem.runner import run
    from dualfem.scene import load_scene

    shown = [code for lang, code in FENCE.findall((REPO / "README.md").read_text(encoding="utf-8")) if lang == "toml"]
    path = REPO / "examples" / "plate.toml"
    assert shown == [path.read_text(encoding="utf-8")]
    qp = load_scene(str(path)).build()
    sol = run("pdas", qp)
    assert sol.status.value == "solved" and (sol.multipliers > 0).sum() > 0
