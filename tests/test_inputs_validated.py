"""Issue 26 item 4: inputs are validated before allocating (sizes, declared shapes, memory limits),
never silently misread, never a traceback. The corpus cases are in tests/bad_inputs/cases_inputs.toml."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp

from dualfem.cli.main import main
from dualfem.core import limits
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.scene import load_scene
from dualfem.experiments import spec as spec_mod
from dualfem.experiments.compare import compare_solvers
from dualfem.experiments.tasks import expand_scenes, expand_tasks, floor_tasks


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


# ------------------------------------------------------------------ QP files: declared sizes


def _solve(path, capsys, *extra) -> tuple[int, str]:
    rc = main(["solve", str(path), "--solver", "pdas", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    return rc, err[-1] if err else ""


def _fake_npy_member(path: Path, name: str, shape: tuple, payload: bytes = b"") -> None:
    """Add to an .npz a member whose header declares ``shape`` (float64) but holds only ``payload``."""
    import io
    import zipfile

    from numpy.lib import format as npf

    buf = io.BytesIO()
    npf.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "a") as z:
        z.writestr(name + ".npy", buf.getvalue() + payload)


@pytest.mark.parametrize("arrays, needle", [
    # qpsolvers letters: P as COO triplets whose shape disagrees with q, or G with 1e10 declared rows
    ({"P_data": [1.0], "P_row": [0], "P_col": [0], "P_shape": [10**10, 10**10], "q": [0.0], "G": np.zeros((0, 1))},
     r"P must have 1 rows \(the length of q\), but P_shape"),
    ({"P": np.eye(2), "q": np.zeros(2), "G_data": [1.0], "G_row": [0], "G_col": [0], "G_shape": [10**10, 2]},
     r"G_shape in QP file .* declares shape \(10000000000, 2\).*memory"),
    # an exported file (K_*, B_*, F) whose B declares 1e10 rows
    ({"K_data": [1.0], "K_row": [0], "K_col": [0], "K_shape": [1, 1], "B_data": [1.0], "B_row": [0], "B_col": [0],
      "B_shape": [10**10, 1], "F": [0.0]}, r"B_shape in QP file .* declares shape \(10000000000, 1\).*memory"),
])
def test_declared_coo_shapes_are_checked_before_allocating(tmp_path, capsys, arrays, needle):
    path = tmp_path / "qp.npz"
    np.savez(path, **{k: np.asarray(v) for k, v in arrays.items()})
    assert path.stat().st_size < 4096
    rc, err = _solve(path, capsys)
    assert rc == 2 and re.search(needle, err), err


def test_dense_array_headers_are_checked_before_decompressing(tmp_path, capsys):
    """A 1 KB .npz whose P header declares 1e5 x 1e5 (80 GB): refused from the header alone."""
    path = tmp_path / "qp.npz"
    np.savez(path, q=np.zeros(10**5), G=np.zeros((0, 10**5)))
    _fake_npy_member(path, "P", (10**5, 10**5))
    rc, err = _solve(path, capsys)
    assert rc == 2 and "'P' declares shape (100000, 100000)" in err and "memory" in err, err


def test_mat_sparse_row_count_is_checked(tmp_path, capsys):
    G = sp.csc_matrix((np.array([1.0]), (np.array([2 * 10**9 - 1]), np.array([0]))), shape=(2 * 10**9, 2))
    scipy.io.savemat(tmp_path / "qp.mat", {"P": np.eye(2), "q": np.zeros(2), "G": G})
    rc, err = _solve(tmp_path / "qp.mat", capsys)
    assert rc == 2 and "(2000000000, 2)" in err and "memory" in err, err


def test_qp_file_unknowns_go_through_the_memory_guard(tmp_path, capsys):
    n = 10**8                     # a 1 MB file declaring 1e8 unknowns: the memory model refuses it
    np.savez_compressed(tmp_path / "qp.npz", P_data=[1.0], P_row=[0], P_col=[0], P_shape=[n, n], q=np.zeros(n),
                        G=np.zeros((0, 1)))
    rc, err = _solve(tmp_path / "qp.npz", capsys, "--max-memory", "10")
    assert rc == 2 and "n = 100000000" in err and "memory" in err, err


# ------------------------------------------------------------------ QP files: never silently misread
def test_complex_data_is_refused_anywhere(tmp_path, capsys):
    cases = {
        "dense.npz": lambda p: np.savez(p, P=np.eye(2) * (1 + 1j), q=np.zeros(2), G=np.eye(2)),
        "coo.npz": lambda p: np.savez(p, P_data=np.array([1 + 1j, 1.0]), P_row=[0, 1], P_col=[0, 1], P_shape=[2, 2],
                                      q=np.zeros(2), G=np.eye(2)),
        "sparse.mat": lambda p: scipy.io.savemat(p, {"P": sp.csc_matrix(np.eye(2) * (2 + 1e-3j)), "q": np.zeros(2),
                                                     "G": sp.csc_matrix(np.eye(2))}),
        "weights.npz": lambda p: np.savez(p, **{**QP(sp.eye(2), np.ones(2), sp.eye(2)).to_dict(),
                                                "weights": np.ones(2) + 0j}),
    }
    for name, make in cases.items():
        make(tmp_path / name)
        rc, err = _solve(tmp_path / name, capsys)
        assert rc == 2 and "complex" in err, (name, err)


def test_dense_matrix_beside_its_triplets_is_ambiguous(tmp_path, capsys):
    np.savez(tmp_path / "qp.npz", P=np.eye(2), P_data=[5.0, 5.0], P_row=[0, 1], P_col=[0, 1], P_shape=[2, 2],
             q=-np.ones(2), G=np.eye(2))
    rc, err = _solve(tmp_path / "qp.npz", capsys)
    assert rc == 2 and "both the matrix 'P' and the triplets" in err and "ambiguous" in err, err
    # an exported .mat holds K twice (sparse and triplets): accepted when equal, refused when they differ
    qp = load_scene("f2", {"N": 8}).build()
    qp.save(tmp_path / "e.mat")
    assert QP.load(tmp_path / "e.mat").key() == qp.key()
    m = {k: v for k, v in scipy.io.loadmat(tmp_path / "e.mat").items() if not k.startswith("__")}
    m["K"] = m["K"] * 2
    scipy.io.savemat(tmp_path / "e2.mat", m)
    with pytest.raises(InputError, match="both the matrix 'K' and the triplets .* differ"):
        QP.load(tmp_path / "e2.mat")


def test_no_unknowns_is_refused_and_no_constraints_answered(tmp_path, capsys):
    np.savez(tmp_path / "n0.npz", P=np.zeros((0, 0)), q=np.zeros(0), G=np.zeros((0, 0)))
    for cmd in ("solve", "compare"):
        rc = main([cmd, str(tmp_path / "n0.npz")])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and "at least one unknown" in err[0], err
    with pytest.raises(InputError, match="at least one unknown"):
        compare_solvers(QP(sp.csc_matrix((0, 0)), np.zeros(0), sp.csr_matrix((0, 0))), ["pdas"])
    np.savez(tmp_path / "m0.npz", P=np.eye(2), q=-np.ones(2), G=np.zeros((0, 2)))
    rc = main(["compare", str(tmp_path / "m0.npz"), "--solvers", "pdas,clarabel", "--json"])
    out = capsys.readouterr().out
    assert rc == 0 and '"reference"' in out


# ------------------------------------------------------------------ crafted export maps
def _export_with(tmp_path: Path, **maps) -> Path:
    d = load_scene("f2", {"N": 8}).build().to_dict()
    for k, v in maps.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v(d[k]) if callable(v) else v
    np.savez(tmp_path / "qp.npz", **d)
    return tmp_path / "qp.npz"


@pytest.mark.parametrize("maps, needle", [
    ({"map_defect_upper": lambda a: a + 10**6}, r"map 'defect_upper' .* node ids in \[0, 84\)"),
    ({"map_defect_tips": lambda a: np.full_like(a, 10**9)}, r"map 'defect_tips' .* node ids"),
    ({"map_defect_id": lambda a: np.full_like(a, 10**12)}, r"map 'defect_id' .* defect numbers in \[0, 1\)"),
    ({"map_defect_s": lambda a: a.astype(str)}, r"map 'defect_s' .* real numbers"),
    ({"map_defect_normals": lambda a: a[:, :2]}, r"map 'defect_normals' .* shape \(2, 3\)"),
    ({"map_normal": np.zeros(5)}, r"map 'normal' .* shape \(2,\)"),
    ({"map_nodes": lambda a: a[:1]}, r"map_nodes but not a consistent mesh"),
    ({"map_nodes": lambda a: a.astype(str)}, r"'map_nodes' .* must hold numbers"),
])
def test_crafted_maps_are_refused_at_load(tmp_path, capsys, maps, needle):
    rc, err = _solve(_export_with(tmp_path, **maps), capsys, "--vtk", str(tmp_path / "out.vtu"))
    assert rc == 2 and re.search(needle, err), err
    assert not (tmp_path / "out.vtu").exists()


@pytest.mark.parametrize("maps, needle", [
    ({"map_node_dofs": lambda a: a[:1]}, r"node_dofs \(map_node_dofs\) must have 2 rows"),
    ({"map_defect_lower": None}, r"defect_upper, defect_lower and defect_s together"),
])
def test_maps_the_vtk_writer_needs_are_checked_at_vtk(tmp_path, capsys, maps, needle):
    rc, err = _solve(_export_with(tmp_path, **maps), capsys, "--vtk", str(tmp_path / "out.vtu"))
    assert rc == 2 and re.search(needle, err), err
    assert not (tmp_path / "out.vtu").exists()


# ------------------------------------------------------------------ bench specs: sizes bounded


def _spec(**over) -> dict:
    d = {"name": "t", "repeats": 1, "warmup": False, "scenes": [{"scene": "f2", "N": 8}],
         "solvers": [{"name": "pdas"}]}
    d.update(over)
    return d


@pytest.mark.parametrize("over, needle", [
    ({"repeats": 1e9}, r"repeats must be an integer in \[1, 1000\]"),
    ({"floor": {"repeats": 10**6}}, r"floor.repeats must be an integer in \[1, 1000\]"),
    ({"scenes": [{"scene": "f2", "N": 8, "repeats": 5000}]}, r"repeats in \[\[scenes\]\] block 1 .* \[1, 1000\]"),
    ({"solvers": [{"name": "pdas", "repeats": 10**9}]}, r"repeats of solver 'pdas' .* \[1, 1000\]"),
    ({"scenes": [{"scene": "f2", "N": 8, "delta": [1e-3] * 200, "load_scale": [1.0] * 200}]},
     r"\[\[scenes\]\] block 1 makes 40,000 scenes \(delta \(200\) x load_scale \(200\)\); the limit is 10,000"),
    ({"solvers": [{"name": "osqp", "grid": {"max_iter": list(range(1, 101)), "scaling": list(range(20))}}]},
     r"grid of solver 'osqp' makes 2,000 variants .* the limit is 1,000"),
    ({"scenes": [{"scene": "f2", "N": 8, "delta": [1e-3] * 100, "load_scale": [1.0] * 100}],
      "solvers": [{"name": "osqp", "grid": {"max_iter": list(range(1, 31))}}]},
     r"the spec makes up to 300,000 runs .* the limit is 100,000"),
])
def test_spec_sizes_are_bounded_before_expanding(over, needle):
    with pytest.raises(InputError, match=needle):
        spec_mod.parse_spec(_spec(**over))


def test_spec_file_size_is_bounded(tmp_path):
    deltas = ", ".join(["1e-3"] * 300_000)
    path = tmp_path / "s.toml"
    path.write_text(f'name = "d"\n[[scenes]]\nscene = "f2"\ndelta = [{deltas}]\n[[solvers]]\nname = "pdas"\n')
    with pytest.raises(InputError, match=r"is 1,8\d\d,\d+ bytes; the limit is 1,000,000"):
        spec_mod.load_spec(path)


def test_bench_tasks_that_would_not_fit_are_skipped_with_the_reason(monkeypatch):
    spec = spec_mod.parse_spec(_spec(scenes=[{"scene": "f2", "N": [8, 256]}]))
    monkeypatch.setattr(limits, "available_bytes", lambda: 150 * 2**20)      # 150 MB: N = 8 fits, N = 256 not
    scenes = expand_scenes(spec)
    tasks = {t["label"]: t for t in expand_tasks(spec, scenes)}
    assert tasks["f2 N=8"]["skip"] is None
    why = tasks["f2 N=256"]["skip"]
    assert why.startswith("not run: N=256") and "GB of memory" in why and "ulimit -v" in why
    assert [f["label"] for f in floor_tasks(spec, scenes)] == ["floor N=8"]


def test_defect_geometry_checks_are_bounded():
    """The crossing checks are near-linear: the curve points they take are bounded by memory, the defects by
    the mesh they need (the triangle estimate, naming the count), both before anything is meshed."""
    x = np.linspace(0.1, 0.9, 100)
    wavy = [{"points": np.c_[x, 0.1 + 0.008 * k + 0.001 * np.sin(50 * x)].tolist(), "curve": "spline"}
            for k in range(100)]
    with pytest.raises(InputError, match=r"defects: 100 defects with 10000 points give 633,700 curve points .* "
                                         r"400,000"):
        load_scene("f2", {"mesh": "gmsh", "defects": wavy}).build()
    with pytest.raises(InputError, match=r"defects\[0\]\.points has 5000 points; the limit is 4096"):
        load_scene("f2", {"defects": [{"points": [[0.5, 0.5]] * 5000}]})
    many = [{"points": [[0.01 + 0.98 * i / 3000, 0.2], [0.01 + 0.98 * i / 3000, 0.8]]} for i in range(3000)]
    with pytest.raises(InputError, match=r"tip_size=1e-05 gives about [\d,]+ triangles \(limit 5,000,000\) on the "
                                         r"1 x 1 body with 3,000 defects \(6,000 tips, size_growth=0.3\)"):
        load_scene("f2", {"mesh": "gmsh", "defects": many, "mesh_size": 0.01, "tip_size": 1e-5})


def test_exported_qp_beside_qpsolvers_letters_is_ambiguous(tmp_path, capsys):
    d = load_scene("f2", {"N": 8}).build().to_dict()
    np.savez(tmp_path / "qp.npz", **d, q=np.zeros(d["F"].size))
    rc, err = _solve(tmp_path / "qp.npz", capsys)
    assert rc == 2 and "both an exported QP" in err and "q" in err, err
