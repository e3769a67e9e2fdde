"""The copy-ready templates docs/templates/*.py: the in-tree path ("copy the file into solvers/ or
problems/, nothing else") end to end, and the templates' own correctness."""
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualfem.core import evaluator, registry
from dualfem.experiments.runner import run

REPO = Path(__file__).resolve().parents[1]
TEMPLATES = REPO / "docs" / "templates"


@pytest.fixture
def templates():
    """Import the templates (they register themselves) and unregister them afterwards."""
    registry._load()
    before_s, before_p = dict(registry._SOLVERS), dict(registry._PROBLEMS)
    mods = {}
    for name in ("solver_template", "problem_template", "dual_solver_template"):
        spec = importlib.util.spec_from_file_location(f"_dualfem_tmpl_{name}", TEMPLATES / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        mods[name] = mod
    yield mods
    registry._SOLVERS.clear()
    registry._SOLVERS.update(before_s)
    registry._PROBLEMS.clear()
    registry._PROBLEMS.update(before_p)


def test_in_tree_copy_is_all_it_takes(tmp_path):
    """A template dropped into the solvers/ and problems/ folders is all it takes.

    The folders are the packages dualfem.solvers / dualfem.problems; the copies go to a scratch
    folder appended to those packages' paths (the repository's own folders stay untouched)."""
    for pkg in ("solvers", "problems"):
        (tmp_path / pkg).mkdir()
    shutil.copy(TEMPLATES / "solver_template.py", tmp_path / "solvers" / "my_pg.py")
    shutil.copy(TEMPLATES / "problem_template.py", tmp_path / "problems" / "membrane.py")
    shutil.copy(TEMPLATES / "dual_solver_template.py", tmp_path / "solvers" / "my_fista.py")
    boot = ("import sys, dualfem.solvers, dualfem.problems; "
            f"dualfem.solvers.__path__.append({str(tmp_path / 'solvers')!r}); "
            f"dualfem.problems.__path__.append({str(tmp_path / 'problems')!r}); "
            "from dualfem.cli import main; sys.exit(main(sys.argv[1:]))")
    env = dict(os.environ, MPLBACKEND="Agg")

    def dualfem(*args):
        r = subprocess.run([sys.executable, "-c", boot, *args], env=env, capture_output=True, text=True,
                           timeout=600, cwd=tmp_path)
        assert r.returncode == 0, (args, r.stdout, r.stderr)
        return r.stdout

    listing = json.loads(dualfem("list", "--json"))
    assert "my_pg" in listing["solvers"] and "membrane" in listing["problems"]
    assert listing["solvers"]["my_fista"]["family"] == "dual" and not listing["solvers"]["my_fista"]["reference"]
    assert listing["scenes"]["membrane_heavy"]["problem"] == "membrane"
    for args in (["membrane_heavy", "--set", "N=8", "--solver", "my_pg"],
                 ["membrane", "--set", "N=8", "--solver", "dual_gradient"],
                 ["f2", "--set", "N=8", "--solver", "my_pg"],
                 ["membrane_heavy", "--set", "N=8", "--solver", "my_fista", "-p", "operator=matrix_free"]):
        rec = json.loads(dualfem("solve", *args, "--json"))
        assert rec["status"] == "solved" and max(rec["residuals"].values()) < 1e-8, rec


def test_folders_named_solvers_and_problems_do_not_shadow_the_builtins(tmp_path):
    """A research project's own solvers/ and problems/ packages in the working directory (first on
    sys.path) must not hide dualfem's built-in plugins."""
    for pkg in ("solvers", "problems"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("MINE = True\n")
        (tmp_path / pkg / "mine.py").write_text("raise RuntimeError('dualfem imported my module')\n")
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "dualfem", "list", "--json"], env=env, capture_output=True,
                       text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    listing = json.loads(r.stdout)
    from dualfem.core.registry import problems, solvers

    assert set(solvers()) <= set(listing["solvers"]) and {"uzawa", "pdas", "osqp"} <= set(listing["solvers"])
    assert set(problems()) <= set(listing["problems"]) and "thin_defect" in listing["problems"]


def test_membrane_touches_the_floor_only_above_the_threshold(templates):
    M = templates["problem_template"].MembraneOverFloor
    # continuum threshold: 0.0737 q / T = lift = 0.05 -> q = 0.678
    light, heavy = M(N=16, q=0.6).build(), M(N=16, q=0.8).build()
    s_light, s_heavy = run("my_pg", light), run("my_pg", heavy)
    assert s_light.ok and s_heavy.ok
    assert not evaluator.contact_set(light, s_light.x).any() and s_light.multipliers.max() == 0
    c = evaluator.contact_set(heavy, s_heavy.x)
    assert 0 < c.sum() < heavy.m
    nodes = heavy.geometry.nodes[:, heavy.geometry.node_dofs[0] >= 0]
    centre = np.argmin(np.linalg.norm(nodes - 0.5, axis=0))
    assert c[centre]                                   # touches first in the middle


def test_membrane_point_symmetry(templates):
    """The (1,1)-diagonal mesh is symmetric under (x, y) -> (1 - x, 1 - y): so is the solution."""
    qp = templates["problem_template"].MembraneOverFloor(N=12, q=2.0).build()
    s = run("my_pg", qp)
    nd = qp.geometry.node_dofs[0]
    X = qp.geometry.nodes
    free = np.flatnonzero(nd >= 0)
    key = {tuple(np.round(X[:, i], 12)): nd[i] for i in free}
    partner = np.array([key[tuple(np.round(1.0 - X[:, i], 12))] for i in free])
    np.testing.assert_allclose(s.x[nd[free]], s.x[partner], atol=1e-8 * np.abs(s.x).max())


@pytest.mark.parametrize("scene", ["f2", "signorini"])
def test_solver_template_agrees_and_fails_honestly(templates, scene):
    from dualfem.core.scene import load_scene
    from dualfem.core.solution import Status

    qp = load_scene(scene, {"N": 8}).build()
    ref = run("pdas" if "pdas" in registry.solvers() else "clarabel", qp)
    s = run("my_pg", qp)
    d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
    assert s.ok and d["x_energy"] < templates["solver_template"].MyProjectedGradient.tolerance
    short = run("my_pg", qp, {"max_iter": 1})
    assert short.status == Status.MAX_ITER and short.residuals is not None


def test_every_exact_solver_on_a_fully_constrained_problem(templates):
    """B = I (every unknown constrained, mesh maps present): an edge case for solvers that reduce
    onto the constrained unknowns (nothing is left to eliminate)."""
    qp = templates["problem_template"].MembraneOverFloor(N=10, q=2.0).build()
    ref = run("my_pg", qp, {"tol": 1e-12})
    assert ref.ok
    for name, cls in sorted(registry.solvers().items()):
        if not cls.exact or cls.missing():
            continue
        s = run(name, qp)
        if s.status == "skipped" or (s.status != "solved" and cls.requires):
            continue          # a third-party library may fail honestly (its certified status says so)
        assert s.status == "solved", (name, s.status, s.message)
        d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
        assert d["x_energy"] < max(cls.tolerance, 1e-6), (name, d)


@pytest.mark.parametrize("scene", ["f2", "signorini", "membrane"])
def test_dual_solver_template_agrees_and_fails_honestly(templates, scene):
    """FISTA on the dual operator (docs/templates/dual_solver_template.py), with either operator."""
    from dualfem.core.scene import load_scene

    qp = (templates["problem_template"].MembraneOverFloor(N=10, q=2.0) if scene == "membrane"
          else load_scene(scene, {"N": 8})).build()
    ref = run("pdas", qp)
    tol = templates["dual_solver_template"].MyFista.tolerance
    for operator in ("dense", "matrix_free"):
        s = run("my_fista", qp, {"operator": operator})
        d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
        assert s.ok and d["x_energy"] < tol, (operator, s.message, d)
    assert run("my_fista", qp, {"max_iter": 1}).status == "max_iter"
