"""The friction comparison's specs and report code (issue 36, item 5): benchmarks/friction_curves.toml (work-precision
by `dualfem bench`), benchmarks/friction_fractured.toml (fractured bodies with Coulomb, benchmarks/fractured.py),
benchmarks/friction_fixed_point.py (fixed-point counts against mu_f, stick/slip maps)."""
from __future__ import annotations

import importlib.util
import json
import sys
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _module(name: str):
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_curves_spec_expands_to_frictional_scenes_of_both_laws_and_dims():
    """Every scene of friction_curves.toml is validated (constructing the problem, no meshing) and carries a friction
    law; every solver block is registered or optional; both laws in 2D and 3D."""
    from dualfem.experiments.spec import load_spec
    from dualfem.experiments.tasks import expand_scenes, expand_tasks

    spec = load_spec(BENCH / "friction_curves.toml")
    scenes = expand_scenes(spec)
    laws = {(int(sc.resolved.get("dim", 2)), sc.resolved["friction"]) for sc in scenes}
    assert laws == {(2, "tresca"), (2, "coulomb"), (3, "tresca"), (3, "coulomb")}
    tasks = expand_tasks(spec, scenes)
    names = {t["solver"]["name"] if isinstance(t.get("solver"), dict) else t.get("solver") for t in tasks}
    assert {"pdas", "mprgp", "uzawa", "uzawa_auto", "penalty", "dual_gradient", "clarabel", "osqp"} <= names
    assert spec.curves and set(spec.tiers) == {"low", "mid", "high"}


def test_the_fractured_friction_spec_names_valid_coulomb_scenes():
    """friction_fractured.toml: each scene's keys are accepted by the problem (validated before meshing) and put
    Coulomb friction on the defects, 2D and 3D."""
    from dualfem.core.scene import load_scene

    spec = tomllib.loads((BENCH / "friction_fractured.toml").read_text())
    dims = set()
    for sc in spec["scenes"]:
        prob = load_scene(sc["scene"], dict(sc["set"]))
        assert prob.params["friction"] == "coulomb" and prob.params["friction_coefficient"] == 0.3
        dims.add(int(sc["set"].get("dim", 2)))
    assert dims == {2, 3} and "pdas" in spec["solvers"]


def test_the_fractured_report_shows_the_slipping_nodes_of_each_answer(tmp_path, monkeypatch):
    fr = _module("fractured_report")
    monkeypatch.setattr("matplotlib.figure.Figure.savefig", lambda fig, path, **kw: None)
    lab = "400 cracks, Coulomb mu_f = 0.3"
    floor = {"floor": 1.0, "n": 283983, "m": 3600, "n_local": 14400, "assembly": 9.0, "peak_rss_mb": 700}

    def run(entry, status, slipping):
        return {"label": lab, "entry": entry, "wall": 20.0,
                "result": {"status": status, "time_s": {"setup": 2.0, "solve": 10.0}, "peak_rss_mb": 700,
                           "certificate": {"value": 1e-13}, "energy": -1.0,
                           "friction": [{"law": "coulomb", "nodes": 3600, "slipping": slipping, "max_slip": 1e-6}]}}

    runs = [{"label": lab, "entry": "floor", "wall": 2.0, "result": floor}, run("pdas", "solved", 1764),
            run("mprgp", "inaccurate", 1760)]
    fr.render(runs, {}, tmp_path, name="friction_fractured")
    text = (tmp_path / "friction_fractured.md").read_text()
    assert "Friction nodes slipping in each answer: pdas 1,764 of 3,600 (coulomb); mprgp 1,760 of 3,600 " \
           "(coulomb)." in text
    assert "# Fractured bodies under compression plus shear with Coulomb friction" in text
    assert "--spec benchmarks/friction_fractured.toml" in text


def test_the_fixed_point_facts_are_read_from_either_form_of_a_solvers_info():
    fp = _module("friction_fixed_point")
    flat = SimpleNamespace(info={"coulomb_changes": [1.0, 0.05, 0.001, 1e-5]},
                           iterations={"coulomb_iterations": 4})
    nested = SimpleNamespace(info={"coulomb": {"changes": [1.0, 0.04, 0.002]}}, iterations={"ipm": 40, "coulomb": 3})
    monolithic = SimpleNamespace(info={"friction": "semismooth newton"}, iterations={"newton": 3})
    a, b = fp.fixed_point_facts(flat), fp.fixed_point_facts(nested)
    assert a["steps"] == 4 and a["contraction"] == pytest.approx(0.02)          # max(0.001/0.05, 1e-5/0.001)
    assert b["steps"] == 3 and b["contraction"] == pytest.approx(0.05)
    assert fp.fixed_point_facts(monolithic) == {}


def test_the_sweeps_remote_stress_puts_the_asked_traction_on_the_crack_plane():
    from dualfem.experiments.friction import resolved

    fp = _module("friction_fixed_point")
    sigma_n, tau = resolved(fp.ANGLE, fp.stress_2d(1.0, 1.2))
    assert sigma_n == pytest.approx(1.0) and abs(tau) == pytest.approx(1.2)


def test_a_tiny_coulomb_scene_runs_through_the_sweep_code_and_the_report(tmp_path):
    """A structured f2 crack with Coulomb through ``one`` (certified run) for a fixed-point solver and the monolithic
    pdas, then the renderer: the steps table, the findings and both figures."""
    from dualfem.core.scene import load_scene

    fp = _module("friction_fixed_point")
    rep = _module("friction_fixed_point_report")
    qp = load_scene("f2", {"N": 8, "E": 1000.0, "nu": 0.3, "delta": 1e3, "remote_stress": [[-1.0, 0.6], [0.6, -1.0]],
                           "friction": "coulomb", "friction_coefficient": 0.2}).build()
    rows = []
    for name, params in (("mprgp", {}), ("pdas", {})):
        rows.append({"dim": 2, "mu_f": 0.2, "n": qp.n, "nodes": int(qp.interface.lower.size),
                     **fp.one(name, params, qp)})
    assert rows[0]["status"] == "solved" and rows[0]["steps"] >= 2 and "steps" not in rows[1]
    s = np.asarray(qp.interface.s)
    maps = [{"dim": 2, "expr": "0.2 + x", "tau": 0.5, "sigma_n": 1.0, "status": "solved", "certified": 1e-14,
             "n": qp.n, "s": s.tolist(), "slip": [0.0] * 3 + [1e-6] * (s.size - 3), "g": [0.5] * s.size,
             "stick": [True] * 3 + [False] * (s.size - 3), "tol": 1e-12},
            {"dim": 3, "expr": "0.5", "status": "failed", "certified": None, "n": 10, "tau": 0.5, "sigma_n": 1.0}]
    data = json.loads(json.dumps({"sweep": rows, "maps": maps, "machine": {"cpu": "x", "cores": 2}}))
    path = rep.render(data, tmp_path)
    text = path.read_text()
    assert "| mu_f | mprgp | pdas |" in text and "every run solved and certified" in text
    assert f"3 of {s.size} nodes stick along the crack" in text and "3D: failed (no answer to map)" in text
    assert (tmp_path / "friction_fixed_point" / "steps.png").exists()
    assert (tmp_path / "friction_fixed_point" / "stick_slip.png").exists()


def test_the_friction_page_links_the_companion_reports_that_exist_beside_it(tmp_path):
    from dualfem.reports.friction import _companions

    assert _companions(tmp_path) == []                   # rendered elsewhere: no dangling links
    (tmp_path / "friction_curves.md").write_text("x")
    (tmp_path / "friction_fractured.md").write_text("x")
    lines = _companions(tmp_path)
    assert lines[0] == "## The solver comparison at larger scale"
    assert [ln.split("]")[0] for ln in lines if ln.startswith("- [")] == ["- [friction_curves.md",
                                                                          "- [friction_fractured.md"]


@pytest.mark.parametrize("law", [{"friction": "tresca", "friction_bound": 0.1},
                                 {"friction": "coulomb", "friction_coefficient": 0.2}])
def test_a_bench_curve_of_a_frictional_qp_samples_every_iterate(law):
    """The bench's monitor takes the multipliers of every block (m_total), as the solvers report them: a frictional
    QP's curve is not stopped at its first iterate by a shape check against the Signorini block's m."""
    from dualfem.core.scene import load_scene
    from dualfem.experiments.curves import timed_runs

    qp = load_scene("f2", {"N": 8, "E": 1000.0, "nu": 0.3, "delta": 1e3, "remote_stress": [[-1.0, 0.6], [0.6, -1.0]],
                           **law}).build()
    assert qp.m_total > qp.m
    task = {"curves": True, "hard_limit": 60.0, "cold_setup": True, "tol": None}
    sol, *_, monitor = timed_runs(task, qp, "uzawa", {}, lambda *a: None, False, 1)
    assert str(sol.status) == "solved"
    assert monitor.note == "" and len(monitor.samples) > 2


def test_a_cached_reference_of_a_frictional_qp_passes_its_check():
    """The bench's check of a cached reference takes every block's multipliers (m_total): a certified frictional
    reference is trusted, not rejected for its shape and recomputed on every resume; a Signorini-sized mu is refused."""
    from dualfem.core.scene import load_scene
    from dualfem.experiments.bench_execute import check_reference
    from dualfem.experiments.runner import run

    qp = load_scene("f2", {"N": 8, "E": 1000.0, "nu": 0.3, "delta": 1e3, "remote_stress": [[-1.0, 0.6], [0.6, -1.0]],
                           "friction": "tresca", "friction_bound": 0.1}).build()
    sol = run("pdas", qp)
    ref = {"qp_key": qp.key(), "x": sol.x, "multipliers": sol.multipliers}
    why, kkt, _ = check_reference(qp, ref, 1e-8)
    assert why is None and kkt < 1e-10
    why, _, _ = check_reference(qp, {**ref, "multipliers": sol.multipliers[:qp.m]}, 1e-8)
    assert "are not the QP's" in why


def test_a_run_killed_by_the_guard_keeps_its_scene_keys():
    """A row without a result (time limit, crash) carries the scene's grid keys like a finished run's row, so the
    bench report draws it in its scene's panel (a frictional scene: friction, friction_coefficient), not apart."""
    from dualfem.experiments.harness import error_row

    task = {"run_id": "r1", "kind": "run", "scene": "penny.toml", "solver": "clarabel", "tier": "low",
            "scene_params": {"friction": "coulomb", "friction_coefficient": 0.2}}
    row = error_row(task, "killed by the wall-clock guard", "time_limit")
    assert row["scene_friction"] == "coulomb" and row["scene_friction_coefficient"] == 0.2
