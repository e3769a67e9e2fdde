"""``dualfem testset``: the frictional problems (dualfem.experiments.testset_friction). A subset (2D and 3D,
Tresca and Coulomb, the small ones that build fastest) is written once: its files read back as the scenes' QPs,
blocks and laws included; each reference is certified and scored ``correct`` by the judge; an answer that ignores
friction, or a moved one, is not; the Coulomb problems' FCLIB files hold the global problem and the reference in
``/solution`` (M v = H r + f, r in the Coulomb cones); ``--no-friction`` and ``--force`` behave."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.scene import build_qp, load_scene
from dualfem.experiments import testset
from dualfem.experiments import testset_friction as fr
from dualfem.experiments.runner import run

pytest.importorskip("h5py")

TINY = tuple(d for d in testset.DECLARED if d.size == "tiny")[:1]
FAST = tuple(d for d in fr.declared() if d.scene in ("f2", "three_d") and d.size == "small")


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("testset_friction") / "set"
    man = testset.write_testset(out, ("tiny", "small"), declared=TINY, declared_friction=FAST)
    return out, man


def _qp(d):
    return build_qp(load_scene(d.scene, dict(d.params)))


def _paths(out, name):
    return out / "friction" / "qp" / f"{name}.npz", out / "friction" / "reference" / f"{name}.npz"


def test_the_declared_frictional_problems_cover_2d_3d_tresca_coulomb_small_medium():
    ds = fr.declared()
    kinds = {(d.size, "3d" if d.scene in ("three_d", "penny") else "2d", d.params["friction"]) for d in ds}
    laws = ("tresca", "coulomb")
    assert kinds == {(s, dim, law) for s in ("small", "medium") for dim in ("2d", "3d") for law in laws}
    assert len({d.name for d in ds}) == len(ds)
    testset.select(("small", "medium"), ds)                     # names are file stems, classes known
    assert {d.name for d in ds}.isdisjoint({d.name for d in testset.DECLARED})


def test_files_read_back_as_the_scenes_frictional_qps(written):
    out, man = written
    assert [p["name"] for p in man["friction"]["problems"]] == [d.name for d in FAST]
    for d in FAST:
        qp, back = _qp(d), fr.read_problem(_paths(out, d.name)[0])
        assert (qp.K - back.K).nnz == 0 and np.array_equal(qp.F, back.F) and (qp.B - back.B).nnz == 0
        assert np.array_equal(qp.weights, back.weights) and len(qp.blocks) == len(back.blocks) == 1
        a, b = qp.blocks[0], back.blocks[0]
        assert (a.G - b.G).nnz == 0 and np.array_equal(a.weights, b.weights)
        assert type(a.law) is type(b.law) and a.law.components == b.law.components
        ref = fr.read_reference(_paths(out, d.name)[1])
        mus = (ref.mu[:qp.m], ref.mu[qp.m:])
        assert np.allclose(a.law.radius(a.weights, mus), b.law.radius(b.weights, mus), rtol=0, atol=0)


def test_references_are_certified_and_scored_correct_by_the_judge(written):
    out, man = written
    for p in man["friction"]["problems"]:
        qp_path, ref_path = _paths(out, p["name"])
        ref = fr.read_reference(ref_path)
        assert ref.solver == p["reference"]["solver"] and ref.certified_error <= testset.REF_BOUND_MAX
        s = fr.score(qp_path, ref_path, ref.x, ref.mu, tol=1e-9)
        assert s.status == "solved" and s.outcome == "correct" and s.cert_x <= 1e-9, (p["name"], s)
        assert p["slipping_nodes"] >= 1 and p["friction_nodes"] >= p["slipping_nodes"]   # friction acts


def test_another_solver_agrees_and_a_frictionless_or_moved_answer_does_not(written):
    out, _ = written
    for d in FAST[1:3]:                 # 2D Coulomb, 3D Tresca
        qp_path, ref_path = _paths(out, d.name)
        qp, ref = fr.read_problem(qp_path), fr.read_reference(ref_path)
        good = run("clarabel", qp)
        s = fr.score(qp, ref, good.x, good.multipliers, tol=1e-6)
        assert s.status == "solved" and s.outcome == "correct", (d.name, s)
        free = run("pdas", dataclasses.replace(qp, blocks=(), store=None))       # ignores friction
        mu = np.concatenate([free.multipliers, np.zeros(qp.m_total - qp.m)])
        s = fr.score(qp, ref, free.x, mu, tol=1e-6)
        assert s.status != "solved" and s.outcome != "correct", (d.name, s)
        s = fr.score(qp, ref, ref.x * (1 + 1e-3), ref.mu, tol=1e-6)
        assert s.outcome != "correct"


def test_coulomb_problems_are_fclib_global_problems_with_the_reference_as_solution(written):
    import h5py

    from dualfem.core.fclib import read_fclib

    out, man = written
    coulomb = [p for p in man["friction"]["problems"] if p["law"] == "coulomb"]
    assert {p["dim"] for p in coulomb} == {2, 3}
    for p in coulomb:
        path = out / p["files"]["fclib"]
        prob, qp = read_fclib(str(path)), fr.read_problem(out / p["files"]["qp"])
        ref = fr.read_reference(out / p["files"]["reference"])
        assert prob.spacedim == p["dim"] and (prob.M - qp.K).nnz == 0 and np.array_equal(prob.f, qp.F)
        with h5py.File(path, "r") as fh:
            v, u, r = (fh["solution"][k][()] for k in ("v", "u", "r"))
        assert np.array_equal(v, ref.x) and np.allclose(u, prob.H.T @ v + prob.w, rtol=0, atol=0)
        scale = np.abs(prob.f).max() + np.abs(prob.H @ r).max()
        assert np.abs(prob.M @ v - prob.H @ r - prob.f).max() < 1e-12 * scale
        R = r.reshape(-1, prob.spacedim)
        assert R[:, 0].min() >= 0 and np.all(np.linalg.norm(R[:, 1:], axis=1) <= prob.mu * R[:, 0] * (1 + 1e-12))
        assert np.abs(R[:, 0] * u.reshape(-1, prob.spacedim)[:, 0]).max() <= 1e-12 * np.abs(R).max() * np.abs(u).max()


def test_manifest_and_readme_list_the_frictional_problems(written):
    out, man = written
    on_disk = json.loads((out / "manifest.json").read_text())
    assert on_disk["friction"]["format"] == "dualfem-friction-testset/1"
    assert [p["name"] for p in on_disk["problems"]] == [d.name for d in TINY]     # qpbenchmark's list unchanged
    readme = (out / "README.md").read_text()
    assert "## Frictional problems" in readme and all(f"| {d.name} |" in readme for d in FAST)


def test_no_friction_and_force_leave_no_stale_frictional_files(tmp_path, monkeypatch):
    out = tmp_path / "set"
    monkeypatch.setattr(testset, "DECLARED", TINY)
    monkeypatch.setattr(fr, "declared", lambda: FAST[:1])
    assert main(["testset", "--out", str(out), "--sizes", "tiny,small", "--quiet"]) == 0
    assert (out / "friction" / "qp" / f"{FAST[0].name}.npz").is_file()
    assert main(["testset", "--out", str(out), "--sizes", "tiny,small", "--quiet", "--force", "--no-friction"]) == 0
    assert not (out / "friction" / "qp" / f"{FAST[0].name}.npz").exists()
    assert "friction" not in json.loads((out / "manifest.json").read_text())
