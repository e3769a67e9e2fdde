"""What the framework needs from a problem is declared by the problem (issue 34, item 6): ``Problem.dim``
and ``scene_default`` choose the problem of a scene file naming none; ``Problem.unit_map`` is the stress
grid's units axis. The framework (core/scene.py, experiments/stress_grid.py) names no problem for either."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from dualfem.core import registry
from dualfem.core.errors import InputError
from dualfem.core.problem import Problem
from dualfem.core.scene import load_scene
from dualfem.core.units import UnitMap
from dualfem.experiments.stress_grid import applicable_axes, scene_in_units

ROOT = Path(__file__).resolve().parents[1]



class Slab(Problem):
    """A toy third-party 2D problem: only its declarations matter here."""

    name = "toy_slab"
    dim = 2
    scene_default = True          # claims 2D scene files: the built-in choice must win
    defaults = {"E": 2.0, "thickness": 0.5, "gap": "0.1*x", "pull": "x + y", "h": 0.0}
    unit_map = UnitMap({"E": "stress", "thickness": "length", "gap": "length_field", "pull": "stress_field",
                        "h": "length_if_set"})


def test_the_dimension_picks_the_declaring_problem(register, tmp_path):
    assert (registry.problem_for_dim(2), registry.problem_for_dim(3)) == ("thin_defect", "three_d")
    assert registry.problem_dims() == [2, 3]
    register(Slab, kind="problem")
    assert registry.problem_for_dim(2) == "thin_defect"     # a third-party plugin cannot take it over
    f = tmp_path / "s.toml"
    f.write_text("N = 8\n")
    assert load_scene(str(f)).name == "thin_defect"
    with pytest.raises(InputError, match="dim must be one of 2, 3"):
        registry.problem_for_dim(4)


def test_the_unit_map_is_the_problems_declaration(register):
    register(Slab, kind="problem")
    s = scene_in_units({"thickness": 2.0}, 1e6, 1e-3, "toy_slab")
    assert s == {"E": 2e6, "thickness": 2e-3, "gap": "0.001 * (0.1 * (x / 0.001))", "pull": "x / 0.001 + y / 0.001"}
    assert scene_in_units({"h": 0.25}, 1.0, 4.0, "toy_slab")["h"] == 1.0
    assert "units" in applicable_axes("toy_slab", {})
    assert "units" not in applicable_axes("fractured", {})     # declares no unit map (yet)
    with pytest.raises(InputError, match="no unit map for problem 'fractured'"):
        scene_in_units({}, 1.0, 2.0, "fractured")
    with pytest.raises(InputError, match="unknown kind"):
        UnitMap({"E": "pressure"})


def test_the_framework_names_no_problem_for_dimension_or_units():
    names = re.compile(r"[\"'](thin_defect|three_d|fractured|signorini|qp_file)[\"']")
    for rel in ("dualfem/core/scene.py", "dualfem/experiments/stress_grid.py", "dualfem/core/units.py"):
        code = [ln for ln in (ROOT / rel).read_text().splitlines() if not ln.lstrip().startswith("#")]
        hits = [ln for ln in code if names.search(ln) and "QP_FILE_PROBLEM =" not in ln]
        assert not hits, f"{rel} names a problem plugin: {hits}"
