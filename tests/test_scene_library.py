"""The scene library (scenes/*.toml) in the experiments: unit conversion of gmsh scenes with
several, curved defects (``stress_grid.scene_in_units``) and a bench sweep over a library scene."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.experiments.stress_grid import scene_in_units

pytest.importorskip("gmsh")

#: coarse enough for a test (a few hundred unknowns), fine enough to double nodes on every defect
COARSE = {"mesh_size": 0.1, "tip_size": 0.05}
#: from MPa / mm to Pa / m: stresses x 1e6, lengths x 1e-3
PA_M = (1e6, 1e-3)


def _library_params(name: str) -> dict:
    """Every parameter of a library scene (its TOML keys over the thin_defect defaults), coarsened."""
    return dict(load_scene(name, COARSE).params)


def test_scene_in_units_scales_defect_tables_and_mesh_lengths():
    base = _library_params("two_defects")
    fs, fl = PA_M
    s = scene_in_units(base, fs, fl)
    assert s["mesh_size"] == pytest.approx(0.1 * fl) and s["tip_size"] == pytest.approx(0.05 * fl)
    assert np.allclose(s["defects"][0]["points"], np.asarray(base["defects"][0]["points"]) * fl)
    assert np.allclose(s["defects"][1]["points"], np.asarray(base["defects"][1]["points"]) * fl)
    assert "delta" not in s["defects"][0]          # the scene's delta, converted once
    assert s["defects"][1]["delta"] == pytest.approx(1e-4 * fl / fs)
    assert s["defects"][1]["curve"] == "spline"
    assert base["defects"][1]["delta"] == 1e-4     # the input is not modified


def _node_order(qp, length: float) -> np.ndarray:
    """Node ids sorted by (position / length, face): gmsh numbers the nodes of a scaled copy of a
    geometry differently, so two QPs are compared node by node through this order."""
    X = np.round(qp.geometry.nodes / length, 9)
    face = np.isin(np.arange(X.shape[1]), qp.interface.upper)
    return np.lexsort((face, X[1], X[0]))


@pytest.mark.parametrize("name", ["two_defects", "symmetric"])
def test_gmsh_scene_in_other_units_gives_the_same_relative_answer(name):
    """Same mesh, displacements x length, contact forces x stress x length, same status and contact
    set; ``symmetric`` has a load expression in x, which must be evaluated at the unscaled x."""
    from dualfem.post.fields import nodal_displacement

    fs, fl = PA_M
    base = _library_params(name)
    a = load_scene("f2", scene_in_units(base, 1.0, 1.0)).build()
    b = load_scene("f2", scene_in_units(base, fs, fl)).build()
    assert (a.n, a.m) == (b.n, b.m)
    ia, ib = _node_order(a, 1.0), _node_order(b, fl)
    np.testing.assert_allclose(b.geometry.nodes[:, ib], fl * a.geometry.nodes[:, ia], rtol=0, atol=1e-9 * fl)
    sa, sb = run("pdas", a), run("pdas", b)
    assert sa.status == sb.status == "solved"
    ua, ub = nodal_displacement(a, sa.x)[ia], nodal_displacement(b, sb.x)[ib]
    assert np.abs(ub / fl - ua).max() <= 1e-8 * np.abs(ua).max()
    # constraint rows matched through their lower node; forces are stress x length
    rank_a, rank_b = np.argsort(ia), np.argsort(ib)      # node id -> position in the common order
    ra, rb = np.argsort(rank_a[a.interface.lower]), np.argsort(rank_b[b.interface.lower])
    np.testing.assert_array_equal(a.interface.defect_id[ra], b.interface.defect_id[rb])
    mu_a, mu_b = sa.multipliers[ra], sb.multipliers[rb] / (fs * fl)
    assert np.abs(mu_b - mu_a).max() <= 1e-8 * np.abs(mu_a).max()
    ca, cb = evaluator.contact_set(a, sa.x)[ra], evaluator.contact_set(b, sb.x)[rb]
    assert np.array_equal(ca, cb) and 0 < ca.sum() < ca.size
    assert b.energy(sb.x) / (fs * fl * fl) == pytest.approx(a.energy(sa.x), rel=1e-9)


TINY = """
name = "tiny_library"
repeats = 1
warmup = false
time_limit = 30
[tiers]
high = 1e-8
[[scenes]]
scene = "two_defects"
mesh_size = 0.1
tip_size = 0.05
[[solvers]]
name = "pdas"
[[solvers]]
name = "uzawa_auto"
optional = true
"""


def test_bench_sweep_on_a_library_scene(tmp_path, capsys):
    """`dualfem bench` end to end on a spec naming a library scene: references, runs graded against
    them, rows carrying the gmsh scene's own keys; a scene name that is not in the library is refused
    before anything is written."""
    from dualfem.cli.main import main
    from dualfem.experiments import store

    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["bench", str(spec), "--out", str(out)]) == 0
    rows = store.read_results(out / "results.csv")
    qp = load_scene("two_defects", COARSE).build()
    refs = [r for r in rows if r["kind"] == "reference"]
    assert len(refs) == 1 and refs[0]["status"] == "solved" and refs[0]["kkt_error"] <= 1e-8
    runs = [r for r in rows if r["kind"] == "run"]
    assert {r["solver"] for r in runs} <= {"pdas", "uzawa_auto"} and any(r["solver"] == "pdas" for r in runs)
    for r in runs:
        assert r["scene"] == "two_defects" and r["n_unknowns"] == qp.n and r["n_constraints"] == qp.m
        assert r["status"] == "solved" and r["grade"] == "correct", (r["solver"], r["message"])
        assert r["err_x_energy"] <= 1e-6 and r["scene_mesh_size"] == 0.1
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.replace('scene = "two_defects"', 'scene = "no_such_library_scene"'), encoding="utf-8")
    assert main(["bench", str(bad), "--out", str(tmp_path / "bad_out")]) == 2
    assert "no_such_library_scene" in capsys.readouterr().err and not (tmp_path / "bad_out").exists()


def test_stress_grid_on_a_library_scene(tmp_path):
    """``dualfem stress --scene two_defects``: the units and load axes on the gmsh scene (own mesh,
    coarsened here), graded against the base scene's reference mapped exactly; the N axis varies
    the gmsh mesh size as 1/N."""
    from dualfem.cli.main import main
    from dualfem.experiments import stress
    from dualfem.experiments.stress_grid import scene_base

    base = {**scene_base("two_defects"), **COARSE}
    grid = stress.build_grid(["pdas"], quick=True, axes=("units", "load", "N"), max_n=32, scene=base)
    assert {t.axis for t in grid} == {"units", "load", "N"}
    n_axis = [t for t in grid if t.axis == "N"]
    assert [t.scene["mesh_size"] for t in n_axis] == [1 / 8, 1 / 16, 1 / 32]
    assert all(t.scene["defects"] == base["defects"] for t in n_axis)
    tasks = [t for t in grid if t.axis == "units" or (t.axis == "load" and t.coords["load_scale"] in (1e-6, 1e6))]
    recs = stress.run_grid(tasks, tmp_path / "res", jobs=1)
    assert len(recs) == 7
    for r in recs:
        assert r.status == "solved" and r.grade == "correct", (r.run_id, r.grade, r.message)
        assert "mapped exactly" in r.ref_solver and r.err_x_energy < 1e-8
    assert main(["stress", "--scene", "two_defects", "--solvers", "pdas", "--quick", "--dry-run",
                 "--out", str(tmp_path / "dry")]) == 0
    assert main(["stress", "--scene", "no_such_scene", "--solvers", "pdas", "--dry-run"]) == 2
