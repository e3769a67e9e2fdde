"""Issue 26 item 4: inputs are validated before allocating (sizes, declared shapes, memory limits),
never silently misread, never a traceback. The corpus cases are in tests/bad_inputs/cases_inputs.toml."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from dualfem.core import limits
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene


# ------------------------------------------------------------------ the memory guard
def _fake_tree(tmp_path: Path, cgroup_line: str, files: dict[str, str]) -> tuple[Path, Path]:
    proc = tmp_path / "proc"
    (proc / "self").mkdir(parents=True)
    (proc / "meminfo").write_text("MemTotal: 67108864 kB\nMemAvailable: 33554432 kB\n")   # 32 GiB available
    (proc / "self" / "cgroup").write_text(cgroup_line)
    (proc / "self" / "status").write_text("VmSize: 1024 kB\n")
    root = tmp_path / "cg"
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return proc, root


def test_available_memory_honours_cgroup_v2(tmp_path, monkeypatch):
    proc, root = _fake_tree(tmp_path, "0::/user/job\n", {
        "cgroup.controllers": "memory", "user/memory.max": "max",
        "user/job/memory.max": str(2 * 2**30), "user/job/memory.current": str(2**29)})
    monkeypatch.setattr(limits, "PROC", proc)
    monkeypatch.setattr(limits, "CGROUP_ROOT", root)
    monkeypatch.setattr(limits, "rlimit_bytes", lambda: None)
    assert limits.available_bytes() == 2 * 2**30 - 2**29
    # a tighter parent limit wins
    (root / "user" / "memory.max").write_text(str(2**30))
    assert limits.available_bytes() == 2**30


def test_available_memory_honours_cgroup_v1(tmp_path, monkeypatch):
    proc, root = _fake_tree(tmp_path, "4:memory:/box\n0::/\n", {
        "memory/memory.limit_in_bytes": "9223372036854771712",       # v1's "no limit" at the root
        "memory/box/memory.limit_in_bytes": str(3 * 2**30),
        "memory/box/memory.usage_in_bytes": str(2**30)})
    monkeypatch.setattr(limits, "PROC", proc)
    monkeypatch.setattr(limits, "CGROUP_ROOT", root)
    monkeypatch.setattr(limits, "rlimit_bytes", lambda: None)
    assert limits.available_bytes() == 2 * 2**30
    (root / "memory" / "box" / "memory.limit_in_bytes").write_text("9223372036854771712")
    assert limits.available_bytes() == 32 * 2**30          # no limit: MemAvailable


def test_available_memory_honours_ulimit_v():
    """Under ``ulimit -v 2 GB`` the guard sees at most 2 GB, and refuses N = 1024 (about 4 GB) before assembly."""
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, resource.RLIM_INFINITY));"
            "from dualfem.numerics.memory import available_bytes; print(available_bytes())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert 0 < int(out.stdout) <= 2 * 2**30
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, resource.RLIM_INFINITY));"
            "from dualfem.cli.main import main; sys.exit(main(['export', 'f2', '--set', 'N=1024', '-o', "
            f"{str(Path('/nonexistent-dir') / 'x.npz')!r}]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "N=1024" in out.stderr and "memory" in out.stderr and "Traceback" not in out.stderr


# ------------------------------------------------------------------ scene keys
@pytest.mark.parametrize("points, needle", [
    ([[0.25, 0.5, 0.0], [0.75, 0.5, 0.0]], r"defects\[0\]\.points: point 0 must have exactly 2 coordinates"),
    ([[0.25, 0.5], [0.5, 0.5, 0.1], [0.75, 0.5]], r"defects\[0\]\.points: point 1 must have exactly 2"),
    ([[0.25, True], [0.75, 0.5]], r"defects\[0\]\.points: point 0 coordinates must be numbers"),
])
def test_defect_points_with_other_than_two_coordinates_are_refused(points, needle):
    with pytest.raises(InputError, match=needle):
        load_scene("f2", {"N": 8, "defects": [{"points": points}]})


def test_single_defect_with_3d_points_is_refused():
    with pytest.raises(InputError, match=r"defect: point 0 must have exactly 2 coordinates"):
        load_scene("f2", {"N": 8, "defect": [[0.25, 0.5, 0.0], [0.75, 0.5, 0.0]]})
    assert load_scene("f2", {"N": 8, "defect": "0.25,0.5,0.75,0.5"}).params["defect"].shape == (2, 2)


@pytest.mark.parametrize("delta", [True, False, "1e-3"])
def test_per_defect_delta_must_be_a_number(delta):
    with pytest.raises(InputError, match=r"defects\[0\]\.delta must be a number"):
        load_scene("f2", {"N": 8, "defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "delta": delta}]})


@pytest.mark.parametrize("over, needle", [
    ({"mesh_size": 1e-9}, r"mesh_size=1e-09 gives about .* mesh_size must be in \[0.00068, 1\]"),
    ({"mesh_size": 1e-200}, r"mesh_size=1e-200 gives about"),
    ({"tip_size": 1e-300}, r"tip_size must be in \["),
    ({"height": 1e9}, r"height=1e\+09.*aspect ratio"),
    ({"height": 1e4}, r"min\(width, height\)/N.*mesh_size must be in \[0.068, 1\]"),
])
def test_gmsh_sizes_are_bounded_when_the_scene_is_validated(over, needle):
    """Before any meshing (the problem is only constructed: no gmsh call, no memory check needed)."""
    with pytest.raises(InputError, match=needle):
        load_scene("f2", {"mesh": "gmsh", **over})


def test_size_estimate_never_overflows():
    p = load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.01})
    p.params["mesh_size"] = 1e-200            # past validation: the estimate stays a number
    n, label = p.size_estimate()
    assert n >= 10**30 and "mesh_size=1e-200" in label
