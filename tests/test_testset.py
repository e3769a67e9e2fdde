"""``dualfem testset``: the public qpbenchmark test set of contact QPs and its certified references.

The tiny subset is written once into a temporary folder; its files must be exactly the scenes' QPs in
qpsolvers' convention (P = K, q = -F, G = -B, h = 0), its references must satisfy the KKT conditions of
``G x <= h`` (checked here with numpy alone), and qpbenchmark, run on it with Clarabel, must agree with
them under the a-posteriori check :func:`dualfem.experiments.testset_files.agreement`, which a mutated
reference must fail.
"""
from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.errors import InputError
from dualfem.core.scene import build_qp, load_scene
from dualfem.experiments import testset
from dualfem.experiments.testset_files import MANIFEST, TESTSET_PY, Reference, agreement, read_qp, read_reference

TINY = [d for d in testset.DECLARED if d.size == "tiny"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("testset") / "tiny"
    man = testset.write_testset(out, ("tiny",))
    return out, man


def _qp(d):
    return build_qp(load_scene(d.scene, dict(d.params)))


def _files(out, name):
    return read_qp(out / "qp" / f"{name}.npz"), read_reference(out / "reference" / f"{name}.npz")


def test_files_are_exactly_the_scenes_qps_in_qpsolvers_convention(tiny):
    out, man = tiny
    assert [p["name"] for p in man["problems"]] == [d.name for d in TINY]
    for d in TINY:
        qp = _qp(d)
        (P, q, G, h), _ = _files(out, d.name)
        assert P.shape == qp.K.shape and (P != qp.K).nnz == 0
        assert np.array_equal(q, -qp.F)
        assert G.shape == qp.B.shape and (G != -qp.B).nnz == 0 and G.nnz == qp.B.nnz
        assert h.shape == (qp.m,) and not np.any(h)


def test_references_satisfy_kkt_of_g_x_le_h(tiny):
    out, man = tiny
    active = 0
    for p in man["problems"]:
        (P, q, G, h), ref = _files(out, p["name"])
        x, z = ref.x, ref.z
        Gx = G @ x
        force = np.max(np.abs(P) @ np.abs(x) + np.abs(q) + np.abs(G.T) @ np.abs(z))   # the size of each term
        assert np.max(np.abs(P @ x + q + G.T @ z)) <= 1e-10 * force          # stationarity
        assert np.max(Gx - h) <= 1e-12 * np.max(np.abs(x))                   # G x <= h (G: unit normals)
        assert np.min(z) >= 0                                                # z >= 0
        assert np.max(np.abs(z * (Gx - h))) <= 1e-12 * np.max(z, initial=0) * np.max(np.abs(x))
        f = 0.5 * x @ (P @ x) + q @ x
        assert ref.objective == pytest.approx(f, rel=1e-14) and p["objective"] == pytest.approx(f, rel=1e-14)
        assert f == pytest.approx(_qp(next(d for d in TINY if d.name == p["name"])).energy(x), rel=1e-13)
        assert 0 <= ref.certified_error <= testset.REF_BOUND_MAX
        assert p["n"] == x.size and p["m"] == z.size and p["nnz_P"] == P.nnz and p["nnz_G"] == G.nnz
        active += int(np.sum(z > 0))
    assert active > 0          # some contact is closed: the multipliers are checked, not only zeros


def test_manifest_readme_and_size_table(tiny):
    out, man = tiny
    on_disk = json.loads((out / MANIFEST).read_text())
    assert on_disk["format"] == "dualfem-testset/1" and on_disk["sizes"] == ["tiny"]
    (row,) = on_disk["size_table"]
    assert row["size"] == "tiny" and row["problems"] == len(TINY) and row["unknowns"] == [150, 150]
    assert row["bytes"] == sum((out / p["files"][k]).stat().st_size for p in on_disk["problems"]
                               for k in ("qp", "reference"))
    readme = (out / "README.md").read_text()
    assert "G x <= h" in readme and "| tiny | 4 | 150 | 3 |" in readme and "B x >= h" in readme


def test_agreement_check_rejects_mutated_references(tiny):
    out, _ = tiny
    rng = np.random.default_rng(0)
    for d in TINY:
        (P, q, G, h), ref = _files(out, d.name)
        assert agreement(P, q, G, h, ref, ref.x, ref.z).ok                       # the reference agrees with itself
        bad_obj = Reference(ref.x, ref.z, ref.objective * (1 + 1e-9), ref.certified_error)
        a = agreement(P, q, G, h, bad_obj, ref.x, ref.z)
        assert not a.ok and not a.reference_consistent
        dx = rng.standard_normal(ref.x.size)
        dx *= 1e-2 * np.sqrt(ref.x @ (P @ ref.x)) / np.sqrt(dx @ (P @ dx))   # 1 % of |x_ref|_P
        x_bad = ref.x + dx
        moved = Reference(x_bad, ref.z, float(0.5 * x_bad @ (P @ x_bad) + q @ x_bad), ref.certified_error)
        a = agreement(P, q, G, h, moved, ref.x, ref.z)                          # consistent, but wrong
        assert a.reference_consistent and not a.ok, a
        assert not agreement(P, q, G, h, ref, ref.x, None).ok                     # no multipliers: no bound


def _load_testset_module(out):
    spec = importlib.util.spec_from_file_location(f"dualfem_contact_{id(out)}", out / TESTSET_PY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_qpbenchmark_solutions_agree_with_the_references(tiny, tmp_path):
    """qpbenchmark's Python API runs the tiny subset with Clarabel at its high_accuracy settings; every
    solution it records agrees with our reference within its own a-posteriori bound (see
    :func:`agreement`: no tolerance is chosen), the bound is tight enough to matter (< 1 % of |x|_P), and
    a reference moved by 1 % fails against the same solutions."""
    qpbenchmark = pytest.importorskip("qpbenchmark", reason="qpbenchmark is not installed (pip install "
                                                            "'dualfem[testset]')")
    out, man = tiny
    ts = _load_testset_module(out).DualfemContact()
    if "clarabel" not in ts.solvers:
        pytest.skip(f"qpsolvers does not offer clarabel here (solvers: {sorted(ts.solvers)})")
    assert [p.name for p in ts] == [p["name"] for p in man["problems"]]
    for prob in ts:                                            # what qpbenchmark reads is the file's QP
        P, q, G, h = read_qp(out / "qp" / f"{prob.name}.npz")
        assert (prob.P != P).nnz == 0 and np.array_equal(prob.q, q) and (prob.G != G).nnz == 0
        assert np.array_equal(prob.h, h) and prob.lb is None and prob.A is None
    seen = {}

    class Capture(qpbenchmark.Results):
        def update(self, problem, solver, settings, solution, runtime):
            seen[problem.name] = solution
            super().update(problem, solver, settings, solution, runtime)

    results = Capture(tmp_path / "results.csv", ts)
    qpbenchmark.run(ts, results, only_solver="clarabel", only_settings="high_accuracy")
    assert sorted(seen) == sorted(p["name"] for p in man["problems"])
    assert results.df["found"].all()
    for name, sol in seen.items():
        (P, q, G, h), ref = _files(out, name)
        a = agreement(P, q, G, h, ref, sol.x, sol.z)
        assert a.ok, (name, a)
        assert a.x_bound < 1e-2 * np.sqrt(ref.x @ (P @ ref.x)), (name, a)
        x_bad = 1.01 * ref.x
        moved = Reference(x_bad, ref.z, float(0.5 * x_bad @ (P @ x_bad) + q @ x_bad), ref.certified_error)
        assert not agreement(P, q, G, h, moved, sol.x, sol.z).ok, name


@pytest.mark.slow
def test_qpbenchmark_command_line_runs_the_test_set(tiny):
    pytest.importorskip("qpbenchmark", reason="qpbenchmark is not installed (pip install 'dualfem[testset]')")
    out, man = tiny
    proc = subprocess.run([sys.executable, str(out / TESTSET_PY), "run", "--solver", "clarabel", "--author",
                           "dualfem-test"], capture_output=True, text=True, timeout=300, cwd=out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    with open(out / "results" / "dualfem_contact.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    names = [p["name"] for p in man["problems"]]
    assert len(rows) == 4 * len(names) and {r["problem"] for r in rows} == set(names)
    assert {r["settings"] for r in rows} == {"default", "low_accuracy", "mid_accuracy", "high_accuracy"}
    assert all(r["solver"] == "clarabel" and r["found"] == "True" for r in rows)
    assert (out / "results" / "dualfem_contact.md").is_file()


def test_every_declared_scene_fits_its_size_class():
    chosen = testset.select(tuple(testset.SIZES))
    assert chosen == list(testset.DECLARED) and len({d.name for d in chosen}) == len(chosen)
    assert {d.size for d in chosen} == set(testset.SIZES)
    assert len(testset.check_sizes(chosen)) == len(chosen)      # every scene validates, nothing assembled


def test_a_scene_too_big_for_its_class_is_refused_before_writing(tmp_path):
    bad = (testset.Declared("tiny", "f2_N64", "f2", {"N": 64}),)
    with pytest.raises(InputError, match=r"'f2_N64'.*size class 'tiny' allows at most 1000"):
        testset.write_testset(tmp_path / "out", ("tiny",), declared=bad)
    assert not (tmp_path / "out").exists()
    twice = (testset.Declared("tiny", "a", "f2", {"N": 4}), testset.Declared("tiny", "a", "f1", {"N": 4}))
    with pytest.raises(InputError, match="'a' appears twice"):
        testset.select(("tiny",), twice)


@pytest.mark.parametrize("argv, words", [
    (["--sizes", "huge"], "unknown size class 'huge'; allowed: tiny, small, medium, large"),
    (["--sizes", ","], "--sizes needs at least one of"),
    (["--max-memory", "-1"], "--max-memory must be a number of GB"),
])
def test_cli_refuses_bad_options_in_one_line(tmp_path, capsys, argv, words):
    assert main(["testset", "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dualfem testset: error:") and words in err[0], err
    assert not (tmp_path / "o").exists()


def test_cli_refuses_a_non_empty_folder_unless_forced(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    assert main(["testset", "--out", str(out), "--sizes", "tiny"]) == 2
    assert "is not empty (it holds other files)" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]
    (tmp_path / "f").write_text("")
    assert main(["testset", "--out", str(tmp_path / "f"), "--sizes", "tiny"]) == 2
    assert "is a file" in capsys.readouterr().err
    assert main(["testset", "--out", str(out), "--sizes", "tiny", "--force"]) == 0
    cap = capsys.readouterr()
    assert "| tiny | 4 | 150 |" in cap.out and "wrote 4 problems" in cap.err
    assert (out / "mine.txt").read_text() == "keep me" and (out / MANIFEST).is_file()
    assert main(["testset", "--out", str(out), "--sizes", "tiny"]) == 2       # a test set is not replaced either
    assert "it holds a dualfem test set" in capsys.readouterr().err


def test_force_replaces_the_previous_set_and_nothing_else(tmp_path):
    out = tmp_path / "o"
    testset.write_testset(out, ("tiny",))
    (out / "qp" / "notes.npz").write_bytes(b"mine")                   # not listed by the manifest: kept
    man = testset.write_testset(out, ("tiny",), force=True, declared=tuple(TINY[:1]))
    assert [p["name"] for p in man["problems"]] == [TINY[0].name]
    assert sorted(p.name for p in (out / "qp").iterdir()) == sorted([f"{TINY[0].name}.npz", "notes.npz"])
    assert sorted(p.name for p in (out / "reference").iterdir()) == [f"{TINY[0].name}.npz"]
    with pytest.raises(InputError, match="unknown size class 'huge'"):
        testset.write_testset(out, ("huge",), force=True)


def test_a_failed_forced_rewrite_leaves_no_manifest(tmp_path, monkeypatch):
    out = tmp_path / "o"
    testset.write_testset(out, ("tiny",))

    def fail(qp, name):
        raise InputError(f"no certified reference for {name!r}")

    monkeypatch.setattr(testset, "certified_reference", fail)
    with pytest.raises(InputError, match="no certified reference"):
        testset.write_testset(out, ("tiny",), force=True)
    assert not (out / MANIFEST).exists()                  # an unfinished set says so: no manifest
