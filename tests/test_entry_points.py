"""Third-party plugins through the entry-point groups ``dualfem.solvers`` / ``dualfem.problems``.

The example package ``tests/plugin_pkg`` (``dualfem-example-plugin``) is made visible exactly as
an installed distribution is: a ``*.dist-info`` directory with ``METADATA`` and
``entry_points.txt`` on ``sys.path`` (what ``pip install`` writes), generated from the package's
own ``pyproject.toml``. So the real ``importlib.metadata`` machinery finds it, and the test
environment is not modified. ``dualfem`` then runs in subprocesses with that path, unchanged.
"""
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

PKG = Path(__file__).parent / "plugin_pkg"


def make_dist(root: Path, pyproject: Path, extra_eps: dict | None = None) -> Path:
    """Write ``<name>-<version>.dist-info`` for ``pyproject`` under ``root`` (like an installer)."""
    meta = tomllib.loads(pyproject.read_text())["project"]
    eps = {g: dict(v) for g, v in meta.get("entry-points", {}).items()}
    for g, v in (extra_eps or {}).items():
        eps.setdefault(g, {}).update(v)
    dist = root / f"{meta['name'].replace('-', '_')}-{meta['version']}.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {meta['name']}\nVersion: {meta['version']}\n")
    lines = []
    for group, items in eps.items():
        lines.append(f"[{group}]")
        lines += [f"{k} = {v}" for k, v in items.items()]
        lines.append("")
    (dist / "entry_points.txt").write_text("\n".join(lines))
    return dist


@pytest.fixture
def plugin_env(tmp_path):
    """Environment for a subprocess in which dualfem-example-plugin is 'installed'."""
    site = tmp_path / "site"
    make_dist(site, PKG / "pyproject.toml")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(PKG / "src"), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["MPLBACKEND"] = "Agg"
    return env


def dualfem(env, *args, cwd=None, check=True):
    r = subprocess.run([sys.executable, "-m", "dualfem", *args], env=env, cwd=cwd,
                       capture_output=True, text=True, timeout=600)
    if check and r.returncode != 0:
        raise AssertionError(f"dualfem {' '.join(args)} -> {r.returncode}\n{r.stdout}\n{r.stderr}")
    return r


def test_metadata_sees_the_entry_points(plugin_env):
    code = ("from importlib.metadata import entry_points;"
            "print(sorted(e.name for e in entry_points(group='dualfem.solvers')),"
            "sorted(e.name for e in entry_points(group='dualfem.problems')))")
    out = subprocess.run([sys.executable, "-c", code], env=plugin_env, capture_output=True, text=True).stdout
    assert "example_nnls" in out and "example_string" in out


def test_list_shows_third_party_plugins(plugin_env):
    d = json.loads(dualfem(plugin_env, "list", "--json").stdout)
    assert d["plugin_errors"] == []
    assert d["solvers"]["example_nnls"]["installed"] is True
    assert d["solvers"]["example_nnls"]["family"] == "other" and d["solvers"]["example_nnls"]["reference"] is False
    assert d["solvers"]["pdas"]["family"] == "dual" and d["solvers"]["pdas"]["reference"] is True
    assert "example_string" in d["problems"]
    assert d["scenes"]["string"]["problem"] == "example_string"
    text = dualfem(plugin_env, "list").stdout
    assert "example_nnls" in text and "example_string" in text


def test_without_the_package_nothing_appears():
    d = json.loads(dualfem(dict(os.environ), "list", "--json").stdout)
    assert "example_nnls" not in d["solvers"] and "example_string" not in d["problems"]


def test_third_party_solver_on_builtin_scene_and_vice_versa(plugin_env):
    for args in (["f2", "--set", "N=8", "--solver", "example_nnls"],
                 ["string", "--set", "N=32", "--solver", "clarabel"],
                 ["string", "--set", "N=32", "--solver", "dual_gradient"],
                 ["string", "--set", "N=32", "--solver", "example_nnls"]):
        rec = json.loads(dualfem(plugin_env, "solve", *args, "--json").stdout)
        assert rec["status"] == "solved", rec
        assert max(rec["residuals"].values()) < 1e-8, rec


def test_third_party_answers_are_right(plugin_env):
    """In-process: the same entry points, loaded by a fresh registry, give correct answers."""
    code = r"""
import numpy as np
from dualfem.core import evaluator
from dualfem.experiments.runner import run
from dualfem.core.scene import load_scene
qp = load_scene("string", {"N": 64, "q": 1.0, "tension": 1.0, "lift": 0.05}).build()
s = run("example_nnls", qp)
ref = run("clarabel", qp)
d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
assert s.ok and d["x_energy"] < 1e-7 and d["contact_mismatch"] == 0, d
# physics: sag q/(8T) = 0.125 > lift, so the middle touches the floor; the free span near each
# end is where the cable's parabola y = lift - q x^2/2 + ... meets the floor tangentially:
# a = sqrt(2 T lift / q) = sqrt(0.1)
x = qp.maps["x"]; c = evaluator.contact_set(qp, s.x)
a = np.sqrt(2 * 0.05)
assert np.all(c[(x > a + 2/64) & (x < 1 - a - 2/64)]) and not np.any(c[(x < a - 2/64) | (x > 1 - a + 2/64)])
# equilibrium: floor reactions + end reactions = load on the 63 interior nodes, q * 63 h
h = 1/64; T = 1.0
end = T * (0.05 - s.x[0]) / h + T * (0.05 - s.x[-1]) / h
assert abs(s.multipliers.sum() + end - 63 * h) < 1e-8, (s.multipliers.sum(), end)
# figures: the plugin (no declared family) is drawn as "other", with a colour-and-marker pair of its own
from dualfem.core.registry import solvers
from dualfem.post import style
st = style.styles(solvers())
assert style.family("example_nnls") == "other" and len({(v.color, v.marker) for v in st.values()}) == len(st)
print("OK")
"""
    r = subprocess.run([sys.executable, "-c", code], env=plugin_env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "OK" in r.stdout, r.stderr


def test_broken_plugin_is_reported_not_fatal(tmp_path):
    site = tmp_path / "site"
    make_dist(site, PKG / "pyproject.toml",
              extra_eps={"dualfem.solvers": {"broken": "dualfem_example_plugin.nonexistent:Nope"}})
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(PKG / "src"), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    d = json.loads(dualfem(env, "list", "--json").stdout)
    assert "example_nnls" in d["solvers"]
    assert any(e.startswith("dualfem.solvers:broken:") for e in d["plugin_errors"]), d["plugin_errors"]
    r = dualfem(env, "list")
    assert "plugin failed to load: dualfem.solvers:broken" in r.stdout


def _has_command(env, name):
    r = dualfem(env, "--help", check=False)
    return name in r.stdout


def test_third_party_plugins_run_in_bench(plugin_env, tmp_path):
    if not _has_command(plugin_env, "bench"):
        pytest.skip("the bench command is not available in this checkout")
    spec = tmp_path / "tp.toml"
    spec.write_text("""
name = "third_party"
repeats = 1
warmup = false
time_limit = 60.0
[tiers]
default = 1e-6
[reference]
solvers = ["clarabel"]
[[scenes]]
scene = ["string"]
N = [32]
[[solvers]]
name = "example_nnls"
[[solvers]]
name = "dual_gradient"
""")
    out = tmp_path / "res"
    dualfem(plugin_env, "bench", str(spec), "--out", str(out), "--no-progress-bar")
    import csv

    rows = list(csv.DictReader((out / "results.csv").open()))
    runs = {r["solver"]: r for r in rows if r.get("kind", "run") == "run"}
    assert {"example_nnls", "dual_gradient"} <= set(runs), rows
    assert all(runs[n]["status"] == "solved" for n in ("example_nnls", "dual_gradient")), runs


def test_third_party_plugins_run_in_compare(plugin_env, tmp_path):
    if not _has_command(plugin_env, "compare"):
        pytest.skip("the compare command is not available in this checkout")
    r = dualfem(plugin_env, "compare", "string", "--set", "N=32", "--json", cwd=tmp_path, check=False)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout.strip().splitlines()[-1])
    runs = {x["solver"]: x for x in d["runs"]}
    assert runs["example_nnls"]["grade"] == "correct", runs["example_nnls"]
    # docs/plugins.md 1.5: an exact plugin that does not declare ``reference`` is never the reference
    assert d["reference"]["solver"] in ("pdas", "clarabel"), d["reference"]

