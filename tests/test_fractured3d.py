"""The 3D fractured problem (``problem = "fractured"``, ``dim = 3``; problems/three_d/fractured.py and
problems/three_d/disks.py): the random disk generator, its refusals and its scenes.

Distances between disks are measured here by brute force on densely sampled filled disks (not the
generator's rim test), so a generator that lets two disks touch or cross fails these tests.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.errors import InputError
from dualfem.problems.three_d.disks import random_disks
from dualfem.runner import run
from dualfem.scene import load_scene
from dualfem.solution import Status

pytest.importorskip("gmsh")

#: a 3D scene that meshes and solves in well under a second
TINY = {"dim": 3, "cracks": 5, "crack_radius": 0.1, "mesh_size": 0.15, "tip_size": 0.06}


def _filled(c, n, r, step):
    """Points of the filled disk (centre c, unit normal n, radius r), at most ``step`` apart, rim included."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = a - (a @ n) * n
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    pts = [c]
    for rho in np.linspace(step, r, max(2, int(np.ceil(r / step)))):
        k = max(8, int(np.ceil(2 * np.pi * rho / step)))
        t = np.linspace(0, 2 * np.pi, k, endpoint=False)
        pts += list(c + rho * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2))
    return np.array(pts)


def _min_distance(disks, step):
    """The least distance between two of the disks, sampled (>= the true one); pairs whose centres are farther
    apart than their radii + 0.2 are skipped (they are farther apart than 0.2)."""
    from scipy.spatial import cKDTree

    clouds = [_filled(np.array(d["center"]), np.array(d["normal"]), d["radius"], step) for d in disks]
    trees = [cKDTree(c) for c in clouds]
    best = 0.2
    for i, a in enumerate(disks):
        for j in range(i + 1, len(disks)):
            b = disks[j]
            if np.linalg.norm(np.subtract(a["center"], b["center"])) < a["radius"] + b["radius"] + 0.2:
                best = min(best, float(trees[i].query(clouds[j])[0].min()))
    return best


def test_same_seed_same_disks_other_seed_other_disks():
    a = random_disks(30, [0.05, 0.1], [0, 0, 1], 45, 0.04, seed=3)
    assert a == random_disks(30, [0.05, 0.1], [0, 0, 1], 45, 0.04, seed=3)
    assert a != random_disks(30, [0.05, 0.1], [0, 0, 1], 45, 0.04, seed=4)
    assert len(a) == 30 and all(d["shape"] == "disk" and 0.05 <= d["radius"] <= 0.1 for d in a)


def test_disks_keep_the_gap_between_them_and_from_the_boundary_and_stay_in_the_region():
    region = [[0.1, 0.2, 0.0], [0.9, 1.0, 0.7]]
    gap = 0.05
    disks = random_disks(25, [0.06, 0.12], [1, 1, 0], 90, gap, seed=7, region=region, box=(1.0, 1.2, 0.8))
    assert _min_distance(disks, 0.004) >= gap
    lo = np.maximum(np.array(region[0]), gap)
    hi = np.minimum(np.array(region[1]), np.array([1.0, 1.2, 0.8]) - gap)
    for d in disks:                     # the exact extent of a disk along axis k: r sqrt(1 - n_k^2)
        c, n = np.array(d["center"]), np.array(d["normal"])
        half = d["radius"] * np.sqrt(1 - n ** 2)
        assert np.all(c - half >= lo - 1e-12) and np.all(c + half <= hi + 1e-12)


def test_a_tight_gap_is_still_kept():
    """Many disks packed close to the gap: the closest pair found by brute force is still >= min_gap."""
    disks = random_disks(40, 0.1, [0, 0, 1], 90, 0.03, seed=1)
    d = _min_distance(disks, 0.006)
    assert 0.03 <= d < 0.06, d             # close pairs exist (the test is not vacuous) and keep the gap


@pytest.mark.parametrize("spread", [0.0, 20.0, 90.0])
def test_normals_lie_in_the_cone(spread):
    axis = np.array([1.0, 2.0, 2.0]) / 3
    disks = random_disks(40, 0.04, axis * 3, spread, 0.03, seed=2)
    n = np.array([d["normal"] for d in disks])
    assert np.allclose(np.linalg.norm(n, axis=1), 1)
    ang = np.degrees(np.arccos(np.clip(n @ axis, -1, 1)))
    assert ang.max() <= spread + 1e-6
    if spread:
        assert ang.max() > 0.7 * spread          # the cone is filled, not only its axis


def test_same_keys_same_qp():
    a, b = load_scene("fractured", TINY).build(), load_scene("fractured", TINY).build()
    assert a.n == b.n and a.m == b.m and a.m > 0
    for x, y in ((a.K, b.K), (a.B, b.B)):
        assert (x != y).nnz == 0
    assert np.array_equal(a.F, b.F)
    c = load_scene("fractured", {**TINY, "seed": 1}).build()
    assert c.m != a.m or c.n != a.n or not np.array_equal(c.F, a.F)


def test_an_impossible_set_is_refused_saying_how_many_fit():
    with pytest.raises(InputError, match=r"cracks = 2000: at most [\d,]+ disks of radius >= 0.1 fit 0.05 apart"):
        random_disks(2000, 0.1, [0, 0, 1], 90, 0.05)
    with pytest.raises(InputError, match=r"cracks = 30: only 9 disks could be placed in 6,000 attempts.*ask "
                                         r"for at most 9 cracks"):
        random_disks(30, 0.25, [0, 0, 1], 90, 0.05)


@pytest.mark.parametrize("key,value,needles", [
    ("cracks", 0, [r"cracks", r"\[1, 20000\]"]),
    ("crack_radius", -0.1, [r"crack_radius", r"> 0"]),
    ("crack_radius", [0.2, 0.1], [r"crack_radius", r"min <= max"]),
    ("crack_radius", 0.45, [r"crack_radius", r"no disk fits"]),
    ("crack_normal", [0, 0, 0], [r"crack_normal", r"not all zero"]),
    ("crack_normal", "up", [r"crack_normal", r"\[nx, ny, nz\]"]),
    ("crack_normal_spread", 120, [r"crack_normal_spread", r"\[0, 90\]"]),
    ("min_gap", 0.01, [r"min_gap", r">= the element size near the cracks .* = 0\.06"]),
    ("seed", -3, [r"seed", r"integer in \[0, "]),
    ("region", [[0.5, 0, 0], [0.2, 1, 1]], [r"region", r"x0 < x1"]),
    ("region", [[0, 0, 0], [1, 1, 1.5]], [r"region", r"width, depth, height = 1, 1, 1"]),
    ("dim", 4, [r"dim", r"2 or 3"]),
    ("defects", [], [r"unknown scene key 'defects' for problem 'fractured'"]),
    ("tip_size", 1e-4, [r"tip_size", r"tetrahedra"]),
])
def test_bad_keys_are_refused_naming_the_key(key, value, needles):
    with pytest.raises(InputError) as exc:     # parallel disks: one of radius 0.45 needs 0.9 + 2 x 0.12
        load_scene("fractured", {**TINY, "crack_normal_spread": 0, key: value})
    for n in needles:
        assert re.search(n, str(exc.value)), (n, str(exc.value))


def test_cli_refuses_a_bad_key_on_one_line(capsys):
    rc = main(["solve", "fractured", "--set", "dim=3", "--set", "crack_normal_spread=100"])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("dualfem solve: error: ") and "crack_normal_spread" in lines[0]


@pytest.mark.parametrize("solver", ["pdas", "uzawa_auto"])
def test_a_tiny_scene_solves_certified(solver):
    pr = load_scene("fractured", TINY)
    assert pr.params["min_gap"] == pytest.approx(2 * 0.06)               # the documented default
    qp = pr.build()
    sol = run(solver, qp)
    assert sol.status == Status.SOLVED, sol.message
    assert qp.params["cracks"] == 5 and "defects" not in qp.params and qp.name == "fractured[f2]"


def test_each_disk_is_cut_with_its_own_normal():
    """Every constrained node lies strictly inside its disk (on its plane, inside its rim) and its row of B
    carries that disk's normal; every disk has constrained nodes."""
    pr = load_scene("fractured", {**TINY, "crack_radius": 0.15, "tip_size": 0.04})
    qp = pr.build()
    C, N, R = pr.disks
    it, P = qp.interface, qp.geometry.nodes
    for k in range(len(R)):
        rows = np.flatnonzero(it.defect_id == k)
        assert rows.size > 0
        X = P[:, it.lower[rows]].T - C[k]
        assert np.abs(X @ N[k]).max() < 1e-9
        assert np.linalg.norm(X, axis=1).max() < R[k]
        assert np.allclose(it.normals[rows], N[k], atol=1e-9)


def test_a_scene_file_with_dim_3(tmp_path, capsys):
    f = tmp_path / "rock.toml"
    f.write_text('problem = "fractured"\ndim = 3\ncracks = 4\ncrack_radius = [0.08, 0.12]\n'
                 'crack_normal = [0, 0, 1]\ncrack_normal_spread = 30\nmesh_size = 0.15\ntip_size = 0.06\n')
    rc = main(["solve", str(f), "--solver", "pdas", "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0 and "solved" in out, out


def test_the_2d_fractured_scene_is_unchanged():
    pr = load_scene("fractured", {"cracks": 5, "crack_length": 0.15, "mesh_size": 0.05, "tip_size": 0.05})
    assert type(pr).__name__ == "Fractured" and pr.dim == 2
    qp = pr.build()
    assert "dim" not in qp.params and qp.name == "fractured[f1]" and qp.geometry.dim == 2
    assert load_scene("fractured", {"dim": 2, "cracks": 5, "crack_length": 0.15, "mesh_size": 0.05,
                                    "tip_size": 0.05}).build().n == qp.n


def test_a_sweep_over_delta_reuses_the_mesh():
    pr = load_scene("fractured", TINY)
    pr.build()
    other = pr.with_params(delta=1e-3)
    assert other.shared is pr.shared
    other.build()
    assert pr.shared.assemblies == 1


def test_the_3d_report_states_the_target_from_the_runs(tmp_path, monkeypatch):
    """benchmarks/fractured_report.py with name fractured3d: the target line counts the certified dual
    solvers of the 200-disk scene, names the ones that failed, and gives the fastest's ratio to the floor."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("fractured_report", Path(__file__).resolve().parents[1]
                                                  / "benchmarks" / "fractured_report.py")
    fr = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fr)
    monkeypatch.setattr("matplotlib.figure.Figure.savefig", lambda fig, path, **kw: None)
    floor = {"floor": 10.0, "n": 300000, "m": 9000, "n_local": 54000, "assembly": 4.0, "peak_rss_mb": 2048}

    def run(entry, status, t, peak):
        return {"label": "200 disks", "entry": entry, "wall": 2 * t,
                "result": {"status": status, "time_s": {"setup": t / 2, "solve": t / 2}, "peak_rss_mb": peak,
                           "certificate": {"value": 1e-12}, "energy": -1.0}}

    runs = [{"label": "200 disks", "entry": "floor", "wall": 12.0, "result": floor},
            run("pdas", "solved", 40.0, 3072), run("mprgp", "solved", 25.0, 4096), run("uzawa", "failed", 99.0, 1024)]
    fr.render(runs, {}, tmp_path, name="fractured3d")
    text = (tmp_path / "fractured3d.md").read_text()
    assert "2 of 3 dual solvers solved and certified (not: uzawa (failed)); not run on it: uzawa_auto, penalty, "\
           "newton_amg, dual_gradient (see the smaller scenes)" in text
    assert "the fastest, mprgp, 25.00 s setup + solve = 2.5 x the floor (10.00 s)" in text
    assert "the largest process peak 4.00 GB" in text and "# 3D fractured bodies" in text
    assert not (tmp_path / "fractured.md").exists()


@pytest.mark.parametrize("sigma", [-1.0, 1.0])
def test_parallel_disks_close_under_compression_and_open_under_tension(sigma):
    """Horizontal disks (crack_normal_spread = 0) under a remote stress sigma_zz: compression closes every
    constrained node and each carries the remote pressure (contact force / nodal area = 1: the uncracked
    body's stress, transmitted by the closed disks); tension opens every node, no contact force remains."""
    pr = load_scene("fractured", {"dim": 3, "cracks": 4, "crack_radius": 0.12, "crack_normal_spread": 0,
                                  "mesh_size": 0.12, "tip_size": 0.04, "seed": 2, "delta": 1e-9,
                                  "remote_stress": [[0, 0, 0], [0, 0, 0], [0, 0, sigma]]})
    qp = pr.build()
    assert np.allclose(qp.interface.normals, [0, 0, 1])
    sol = run("pdas", qp)
    assert sol.status == Status.SOLVED, sol.message
    jump, mu = qp.B @ sol.x, sol.multipliers
    scale = np.abs(sol.x).max()
    if sigma < 0:
        assert np.all(jump <= 1e-9 * scale) and np.all(mu > 0)
        assert np.allclose(mu / qp.weights, -sigma, rtol=1e-3)
    else:
        assert np.all(jump > 1e-9 * scale) and np.all(mu == 0)


def test_friction_keys_act_on_every_disk():
    """friction = "tresca" at the top level of a 3D fractured scene: one friction node per constrained disk node
    (two tangential rows each), the same QP otherwise; a disk under compression and shear slips."""
    from dualfem.core.laws import Tresca
    from dualfem.problems.fractured import Fractured

    load = {"remote_stress": [[0, 0, 0.3], [0, 0, 0], [0.3, 0, -1.0]], "crack_normal_spread": 0.0}
    plain = Fractured(**TINY, **load).build()
    qp = Fractured(**TINY, **load, friction="tresca", friction_bound=0.1).build()
    (block,) = qp.blocks
    assert isinstance(block.law, Tresca) and block.m == 2 * qp.m and qp.m == plain.m
    assert abs(qp.K - plain.K).max() == 0 and np.array_equal(qp.F, plain.F) and not plain.blocks
