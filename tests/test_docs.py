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
* every ``dualfem COMMAND`` of the guide must be a command of this checkout and every
  ``tests/...`` file it names must exist (``test_guide_commands_exist``); nothing is skipped.

docs/export.md is checked against what ``dualfem export`` writes (``test_export_*``).

The file blocks that carry a template must be identical to ``docs/templates/*.py``.
"""
from __future__ import annotations

import json
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


def missing(cmd: str) -> str | None:
    """None if the command's dualfem subcommand and repository files exist here, else what is missing."""
    argv = shlex.split(cmd)
    if argv[0] == "dualfem" and len(argv) > 1:
        from dualfem.cli.main import _COMMANDS, _import_commands

        _import_commands()
        if argv[1] not in _COMMANDS:
            return f"'dualfem {argv[1]}' is not a command of this checkout"
    for a in argv:
        path = a.split("::")[0]
        if path.startswith("tests/") and not (REPO / path).exists():
            return f"{path} does not exist in this checkout"
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


def run_console(tmp: Path) -> list[str]:
    env = shell_env(tmp)
    if not (tmp / "tests").exists():
        (tmp / "tests").symlink_to(REPO / "tests")
    ran = []
    for cmd in commands():
        m = re.match(r"pip install -e (\S+)$", cmd)
        if m:
            emulate_pip_install(tmp, env, m.group(1))
            ran.append(cmd)
            continue
        r = subprocess.run(["bash", "-c", cmd], cwd=tmp, env=env, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"$ {cmd}\nexit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
        ran.append(cmd)
    return ran


def test_guide_has_blocks_of_every_kind():
    langs = [lang for lang, _ in blocks()]
    assert langs.count("python") >= 8 and "console" in langs and "toml" in langs
    assert all(lang in ("python", "console", "toml") for lang in langs), set(langs)


def test_templates_are_the_guide_blocks():
    files = {file_target(code): code for _, code in blocks() if file_target(code)}
    for target, tmpl in (("my-plugin/src/my_plugin/solver.py", "solver_template.py"),
                         ("my-plugin/src/my_plugin/problem.py", "problem_template.py"),
                         ("my-plugin/src/my_plugin/fista.py", "dual_solver_template.py")):
        text = (REPO / "docs" / "templates" / tmpl).read_text(encoding="utf-8")
        assert files[target] == "# file: " + target + "\n" + text, f"{target} differs from docs/templates/{tmpl}"


def test_guide_runs(tmp_path, clean_registry):
    """Python blocks in order, then the console commands, in one working directory."""
    write_files(tmp_path)
    assert run_python_blocks(tmp_path) >= 8
    ran = run_console(tmp_path)
    assert any(c.startswith("dualfem list") for c in ran)
    assert any(c.startswith("pip install -e") for c in ran)


def test_guide_commands_exist():
    """Every command of the guide names an existing dualfem command and existing test files."""
    cmds = commands()
    assert any(c.startswith("dualfem compare") for c in cmds) and any(c.startswith("dualfem bench") for c in cmds)
    assert [f"{c}: {missing(c)}" for c in cmds if missing(c)] == []
    # the check itself catches what it is for
    assert "not a command" in missing("dualfem frobnicate f2")
    assert "does not exist" in missing("python -m pytest tests/test_no_such_file.py::test_x")


# ------------------------------------------------------------------ docs/export.md
EXPORT_DOC = REPO / "docs" / "export.md"


def _documented_keys() -> set[str]:
    """Keys named in backticks in docs/export.md (array names only)."""
    return set(re.findall(r"`([A-Za-z][A-Za-z0-9_]*)`", EXPORT_DOC.read_text(encoding="utf-8")))


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> dict:
    import numpy as np
    import scipy.io

    from dualfem.cli.main import main

    d = tmp_path_factory.mktemp("export")
    assert main(["export", "f2", "--set", "N=8", "-o", str(d / "f2.npz")]) == 0
    assert main(["export", "f2", "--set", "N=8", "-o", str(d / "f2.mat")]) == 0
    mat = scipy.io.loadmat(d / "f2.mat")
    return {"npz": dict(np.load(d / "f2.npz")), "mat": {k: v for k, v in mat.items() if not k.startswith("__")}}


def test_export_keys_documented(exported):
    """Every array that 'dualfem export' writes for f2 is documented, and nothing else is."""
    doc = _documented_keys()
    written = set(exported["npz"]) | set(exported["mat"])
    assert sorted(written - doc) == []
    # every documented array name (a *_ name of the tables, or a param_/map_ key) is written
    array = r"(K|B)(_row|_col|_data|_shape)?$|param_|map_|F$|weights$|local_dofs$|name$"
    named = {k for k in doc if re.match(array, k)}
    assert sorted(named - written) == []
    assert {"param_plane", "param_load", "param_defect"} <= set(exported["npz"]) - set(exported["mat"])


def test_export_conventions(exported):
    """The conventions docs/export.md states hold on the exported arrays."""
    import numpy as np
    import scipy.sparse as sp

    d = exported["npz"]
    K = sp.coo_matrix((d["K_data"], (d["K_row"], d["K_col"])), shape=tuple(d["K_shape"])).tocsr()
    B = sp.coo_matrix((d["B_data"], (d["B_row"], d["B_col"])), shape=tuple(d["B_shape"])).toarray()
    n, m = K.shape[0], B.shape[0]
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max() and np.linalg.eigvalsh(K.toarray()).min() > 0
    assert d["F"].shape == (n,) and d["weights"].shape == (m,)
    assert sp.issparse(exported["mat"]["K"]) and abs(exported["mat"]["K"] - K).max() == 0
    nodes, dofs, nu = d["map_nodes"], d["map_node_dofs"], d["map_normal"]
    # row j of B = nu . (u(upper_j) - u(lower_j)), upper on the +nu side at the same place as lower
    expected = np.zeros((m, n))
    for j, (up, lo) in enumerate(zip(d["map_defect_upper"], d["map_defect_lower"])):
        assert np.allclose(nodes[:, up], nodes[:, lo])
        for c in range(2):
            expected[j, dofs[c, up]] += nu[c]
            expected[j, dofs[c, lo]] -= nu[c]
    assert np.allclose(B, expected)
    assert np.allclose(nu, [-d["map_tangent"][1], d["map_tangent"][0]])  # tangent turned by +90 degrees
    # clamped = the nodes on x2 = 0; every other component has an index into x, each used once
    assert np.array_equal((dofs < 0).any(axis=0), np.isclose(nodes[1], 0.0))
    assert sorted(dofs[dofs >= 0]) == list(range(n))
    # arc length from the first end point, trapezoid weights, local dofs
    ends = np.array(json.loads(str(d["param_defect"])))
    a = ends[0]
    assert np.allclose(d["map_defect_s"], d["map_tangent"] @ (nodes[:, d["map_defect_lower"]] - a[:, None]))
    s = np.r_[0.0, d["map_defect_s"], np.linalg.norm(ends[1] - ends[0])]
    assert np.allclose(d["weights"], 0.5 * (np.diff(s)[:-1] + np.diff(s)[1:]))
    assert set(np.flatnonzero(np.abs(B).sum(axis=0))) <= set(d["local_dofs"])
    tri = d["map_triangles"]
    assert tri.shape[0] == 3 and tri.max() == nodes.shape[1] - 1
