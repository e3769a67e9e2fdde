"""docs/plugins.md is executable: every code block in it runs here, so the guide cannot rot.

Rules (stated at the top of the guide too):

* a block whose first line is ``# file: PATH`` is written to PATH (relative to a fresh temp dir
  that stands for the reader's working directory); a Python file block is also compiled;
* every other ``python`` block is executed, in order, in one namespace, with that temp dir as
  the working directory (the blocks assert their own results);
* every line ``$ COMMAND`` of a ``console`` block is run by bash in the same directory, in order,
  after all Python blocks, and must exit with status 0. ``dualfem`` and ``python`` are this
  interpreter. ``tests`` in the temp dir links to this checkout's tests (the guide's commands
  are run "from a dualfem checkout"). ``pip install -e DIR`` is the one command not run
  literally: it is emulated by what pip writes for an installed distribution, a
  ``*.dist-info`` with ``entry_points.txt`` generated from ``DIR/pyproject.toml`` on PYTHONPATH
  plus ``DIR/src`` (see tests/test_entry_points.py), so the test environment is not modified
  while the real importlib.metadata entry-point machinery is used;
* a command needing a part of dualfem written in parallel with the guide (``OPTIONAL_COMMANDS``,
  ``OPTIONAL_FILES``) that this checkout does not have yet is not run by the main test;
  ``test_optional_commands`` reports it as skipped with its name. Any other failure fails.

The file blocks that carry a template must be identical to ``docs/templates/*.py``.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dualfem.core import registry

REPO = Path(__file__).resolve().parents[1]
GUIDE = REPO / "docs" / "plugins.md"
FENCE = re.compile(r"^```([a-z]*)[^\n]*\n(.*?)^```\s*$", re.S | re.M)


def blocks() -> list[tuple[str, str]]:
    """(language, code) of every fenced block, in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(GUIDE.read_text(encoding="utf-8"))]


def file_target(code: str) -> str | None:
    first = code.splitlines()[0] if code.strip() else ""
    m = re.match(r"#\s*file:\s*(\S+)\s*$", first)
    return m.group(1) if m else None


def commands() -> list[str]:
    out = []
    for lang, code in blocks():
        if lang == "console":
            out += [ln[2:].strip() for ln in code.splitlines() if ln.startswith("$ ")]
    return out


#: parts of dualfem developed in parallel with the guide: a command using them is reported as
#: skipped while they are absent (any other unknown command or file fails the test)
OPTIONAL_COMMANDS = {"compare", "bench"}
OPTIONAL_FILES = {"tests/test_contract.py"}


def available(cmd: str) -> str | None:
    """None if the command can run in this checkout, else why not."""
    argv = shlex.split(cmd)
    if argv[0] == "dualfem" and len(argv) > 1 and argv[1] in OPTIONAL_COMMANDS:
        from dualfem.cli.main import _COMMANDS, _import_commands

        _import_commands()
        if argv[1] not in _COMMANDS:
            return f"'dualfem {argv[1]}' is not a command of this checkout"
    for a in argv:
        if a.split("::")[0] in OPTIONAL_FILES and not (REPO / a.split("::")[0]).exists():
            return f"{a} does not exist in this checkout"
    return None


@pytest.fixture
def clean_registry():
    """The guide registers its plugins in this process: remove them afterwards."""
    registry._load()
    before_s, before_p = dict(registry._SOLVERS), dict(registry._PROBLEMS)
    saved_path = list(sys.path)
    saved_mods = set(sys.modules)
    yield
    registry._SOLVERS.clear()
    registry._SOLVERS.update(before_s)
    registry._PROBLEMS.clear()
    registry._PROBLEMS.update(before_p)
    sys.path[:] = saved_path
    for m in set(sys.modules) - saved_mods:
        if m.startswith(("my_plugin", "my_pg", "membrane")):
            del sys.modules[m]


def write_files(tmp: Path) -> list[str]:
    written = []
    for lang, code in blocks():
        target = file_target(code)
        if target:
            path = tmp / target
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(code, encoding="utf-8")
            if lang == "python":
                compile(code, str(path), "exec")
            written.append(target)
    return written


def run_python_blocks(tmp: Path) -> int:
    ns: dict = {"__name__": "__guide__"}
    n = 0
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        for i, (lang, code) in enumerate(blocks()):
            if lang != "python" or file_target(code):
                continue
            try:
                exec(compile(code, f"{GUIDE.name}[block {i}]", "exec"), ns)
            except Exception as exc:
                raise AssertionError(f"python block {i} of {GUIDE.name} failed: {type(exc).__name__}: {exc}\n"
                                     f"{textwrap.indent(code, '    ')}") from exc
            n += 1
    finally:
        os.chdir(cwd)
    return n


def shell_env(tmp: Path) -> dict:
    bin_ = tmp / "bin"
    bin_.mkdir(exist_ok=True)
    (bin_ / "dualfem").write_text(f'#!/bin/sh\nexec "{sys.executable}" -m dualfem "$@"\n')
    (bin_ / "python").write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    for f in ("dualfem", "python"):
        (bin_ / f).chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    return env


def emulate_pip_install(tmp: Path, env: dict, target: str) -> None:
    from test_entry_points import make_dist

    proj = tmp / target
    site = tmp / "site"
    make_dist(site, proj / "pyproject.toml")
    paths = [str(site), str(proj / "src")]
    env["PYTHONPATH"] = os.pathsep.join(paths + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])


def run_console(tmp: Path, only_available: bool = True) -> tuple[list[str], list[str]]:
    env = shell_env(tmp)
    if not (tmp / "tests").exists():
        (tmp / "tests").symlink_to(REPO / "tests")
    ran, skipped = [], []
    for cmd in commands():
        m = re.match(r"pip install -e (\S+)$", cmd)
        if m:
            emulate_pip_install(tmp, env, m.group(1))
            ran.append(cmd)
            continue
        why = available(cmd)
        if why and only_available:
            skipped.append(f"{cmd}: {why}")
            continue
        r = subprocess.run(["bash", "-c", cmd], cwd=tmp, env=env, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"$ {cmd}\nexit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
        ran.append(cmd)
    return ran, skipped


def test_guide_has_blocks_of_every_kind():
    langs = [lang for lang, _ in blocks()]
    assert langs.count("python") >= 8 and "console" in langs and "toml" in langs
    assert all(lang in ("python", "console", "toml") for lang in langs), set(langs)


def test_templates_are_the_guide_blocks():
    files = {file_target(code): code for _, code in blocks() if file_target(code)}
    for target, tmpl in (("my-plugin/src/my_plugin/solver.py", "solver_template.py"),
                         ("my-plugin/src/my_plugin/problem.py", "problem_template.py")):
        text = (REPO / "docs" / "templates" / tmpl).read_text(encoding="utf-8")
        assert files[target] == "# file: " + target + "\n" + text, f"{target} differs from docs/templates/{tmpl}"


def test_guide_runs(tmp_path, clean_registry):
    """Python blocks in order, then the console commands, in one working directory."""
    write_files(tmp_path)
    assert run_python_blocks(tmp_path) >= 8
    ran, _ = run_console(tmp_path)
    assert any(c.startswith("dualfem list") for c in ran)
    assert any(c.startswith("pip install -e") for c in ran)


def test_optional_commands(tmp_path):
    """Commands that need parts of dualfem this checkout may not have yet (reported, not hidden)."""
    skipped = [c for c in commands() if available(c)]
    if skipped:
        pytest.skip("not run here: " + "; ".join(f"{c} ({available(c)})" for c in skipped))
