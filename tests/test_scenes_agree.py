"""Every scene of the library ``scenes/*.toml`` (repository root): the exact active-set solver
(pdas) and the interior-point solver (Clarabel, raw: no polish) agree to 1e-8 relative in energy
and displacements; the multipliers (nodal contact forces) to 1e-7 of the largest nodal force, the
limit of Clarabel's own accuracy at its default tolerances (measured 1.1e-8 on a kinked gmsh
defect with a weakly active node, 1e-9 or less elsewhere).
Meshes are coarsened for test time (N = 16, gmsh mesh_size >= 0.04)."""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run

SCENES = sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.toml"))
MIN_SIZE = 0.04


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_pdas_and_clarabel_agree(path):
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    over = {"N": 16}
    if data.get("mesh") == "gmsh" and 0 < float(data.get("mesh_size", 0)) < MIN_SIZE:
        over["mesh_size"] = MIN_SIZE
        if 0 < float(data.get("tip_size", 0)) < MIN_SIZE / 4:
            over["tip_size"] = MIN_SIZE / 4
    qp = load_scene(str(path), over).build()
    a, b = run("pdas", qp), run("clarabel", qp)
    assert a.ok and b.ok, (a.status, b.status)
    assert abs(qp.energy(b.x) - qp.energy(a.x)) <= 1e-8 * abs(qp.energy(a.x))
    assert np.abs(a.x - b.x).max() <= 1e-8 * np.abs(a.x).max()
    f_s = max(np.abs(a.multipliers).max(), np.abs(qp.F).max())
    assert np.abs(a.multipliers - b.multipliers).max() <= 1e-7 * f_s
