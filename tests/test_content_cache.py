"""Issue 37, item 5: caches keyed by content. A bench row or reference of a scene that reads a file
(a QP file, a scene file) is reused only for the same content: a changed file is run again (the
rows of the old content stay in rows/), the same content under another name is not. Before the fix
a bench folder re-run after its QP file changed reused the old rows (keyed by the file's name).
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from dualfem.core.scene import load_scene
from dualfem.experiments import bench, harness, store
from dualfem.experiments.spec import load_spec
from dualfem.experiments.tasks import expand_scenes, expand_tasks

SPEC = """
name = "content"
repeats = 1
warmup = false
time_limit = 30
[tiers]
high = 1e-8
[floor]
enabled = false
[[scenes]]
scene = ["{path}"]
[[solvers]]
name = "pdas"
"""


def export(path: Path, N: int) -> Path:
    load_scene("f1", {"N": N}).build().save(str(path))
    return path


def spec_for(tmp_path: Path, qpfile: Path, name: str = "spec.toml"):
    p = tmp_path / name
    p.write_text(SPEC.replace("{path}", str(qpfile)), encoding="utf-8")
    return load_spec(p)


def test_scene_key_follows_the_file_content_not_its_name(tmp_path):
    a = export(tmp_path / "a.npz", 8)
    (key,) = [s.key for s in expand_scenes(spec_for(tmp_path, a))]
    b = tmp_path / "b.npz"
    shutil.copy(a, b)
    assert [s.key for s in expand_scenes(spec_for(tmp_path, b))] == [key]        # same content, another name
    export(a, 12)
    assert [s.key for s in expand_scenes(spec_for(tmp_path, a))] != [key]        # same name, new content
    (run,) = expand_tasks(spec_for(tmp_path, a))
    assert run["scene_key"] != key


def test_builtin_scene_keys_are_unchanged(tmp_path):
    """Scenes that read no file keep their former key (the folders of earlier sweeps resume as before)."""
    from dualfem.experiments.tasks import _canon, _hash

    p = tmp_path / "spec.toml"
    p.write_text(SPEC.replace('"{path}"', '"f1", "f2"]\nN = [8'), encoding="utf-8")
    for sc in expand_scenes(load_spec(p)):
        assert store.content_ident(sc.scene, sc.resolved) is None
        assert sc.key == _hash({"scene": sc.scene, "params": _canon(sc.resolved)})


@pytest.fixture
def in_process(monkeypatch):
    """Tasks run in this process (what is cached is the point here, not the worker)."""
    monkeypatch.setattr(harness, "run_guarded", lambda task: harness._handler(task["kind"])(task, lambda *a: None))


def test_bench_reruns_a_changed_qp_file_and_keeps_the_rest(tmp_path, in_process):
    qpfile = export(tmp_path / "scene.npz", 8)
    out = tmp_path / "out"
    bench.run_sweep(spec_for(tmp_path, qpfile), out, progress=False)
    first = [r for r in store.read_results(out / "results.csv") if r["kind"] == "run"]
    assert len(first) == 1 and first[0]["status"] == "solved" and first[0]["n_unknowns"] == 150
    export(qpfile, 12)                                   # the same file name, another QP
    bench.run_sweep(spec_for(tmp_path, qpfile), out, progress=False)
    rows = [r for r in store.read_results(out / "results.csv") if r["kind"] == "run"]
    assert len(rows) == 1 and rows[0]["n_unknowns"] != 150 and rows[0]["status"] == "solved", rows
    assert rows[0]["run_id"] != first[0]["run_id"]
    kept = {json.loads(p.read_text())["run_id"] for p in (out / "rows").glob("*.json")}
    assert first[0]["run_id"] in kept                    # the old content's row is not lost
    refs = {r["scene_key"] for r in store.read_results(out / "results.csv") if r["kind"] == "reference"}
    assert refs == {rows[0]["scene_key"]}                # a reference of the new content
