"""ParaView output: VTU/XDMF written, read back with meshio, fields and sizes checked; CLI options."""
from __future__ import annotations

import os

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from dualfem.cli.main import main  # noqa: E402
from dualfem.core.scene import load_scene  # noqa: E402
from dualfem.experiments.runner import run  # noqa: E402
from dualfem.post.fields import Post  # noqa: E402
from dualfem.post.figures import pick_solver  # noqa: E402
from dualfem.post.vtk import to_meshio, write_vtu, write_xdmf  # noqa: E402


@pytest.fixture(scope="module")
def case():
    qp = load_scene("f2", {"N": 16, "delta": 1e-1}).build()
    sol = run(pick_solver(), qp)
    assert sol.ok
    return qp, sol


def _check(mesh, qp, sol):
    p = Post(qp, sol)
    nn = qp.geometry.nodes.shape[1]
    ntri = qp.geometry.cells.shape[1]
    m = qp.m
    assert mesh.points.shape == (nn, 3)
    assert np.allclose(mesh.points[:, :2], qp.geometry.nodes.T)
    types = [c.type for c in mesh.cells]
    assert types == ["triangle", "line"]
    tri, line = mesh.cells[0].data, mesh.cells[1].data
    assert tri.shape == (ntri, 3) and np.array_equal(tri, qp.geometry.cells.T)
    assert line.shape == (2 * (m + 1), 2)  # m + 1 edges per face, two faces
    # displacement: 3 components, z = 0, equal to the solution
    d = mesh.point_data["displacement"]
    assert d.shape == (nn, 3) and np.all(d[:, 2] == 0)
    assert np.allclose(d[:, :2], p.displacement)
    # stresses on triangles, NaN on lines
    for k in ("von_mises", "s11", "s22", "s12", "s33"):
        assert np.allclose(mesh.cell_data[k][0], p.stress[k]), k
        assert np.all(np.isnan(mesh.cell_data[k][1])), k
    # defect fields on lines
    jn = mesh.cell_data["jump_normal"][1]
    face = mesh.cell_data["face"][1]
    assert np.all(np.isnan(mesh.cell_data["jump_normal"][0]))
    assert set(face[: m + 1]) == {1} and set(face[m + 1:]) == {-1}
    nodal = p.defect["jump_normal"]
    assert np.allclose(jn[: m + 1], 0.5 * (nodal[:-1] + nodal[1:]))
    pr = mesh.cell_data["pressure"][1]
    press = qp.pressure(sol.multipliers)
    assert np.isclose(pr[0], press[0]) and np.isclose(pr[m], press[-1])  # tip edges: interior value
    assert np.allclose(pr[1:m], 0.5 * (press[:-1] + press[1:]))
    # nodal defect fields: both copies carry the value, 0 elsewhere and at the tips; no point field holds NaN
    pj = mesh.point_data["jump_normal"]
    assert np.allclose(pj[qp.interface.upper], qp.B @ sol.x)
    assert np.allclose(pj[qp.interface.lower], qp.B @ sol.x)
    for k, v in mesh.point_data.items():
        assert np.all(np.isfinite(v)), k
    away = mesh.point_data["defect_id"] < 0
    assert away.sum() == nn - 2 * m - 2
    for k in ("jump_normal", "jump_tangent", "pressure"):
        assert np.all(mesh.point_data[k][away] == 0), k
    pp = mesh.point_data["pressure"]
    assert np.allclose(pp[qp.interface.upper], press) and pp.max() > 0  # f2 has a contact zone


def test_vtu_roundtrip(case, tmp_path):
    qp, sol = case
    path = write_vtu(tmp_path / "out.vtu", qp, sol)
    assert sorted(os.listdir(tmp_path)) == ["out.vtu"]  # no temporary left behind
    _check(meshio.read(path), qp, sol)


def test_xdmf_roundtrip(case, tmp_path):
    pytest.importorskip("h5py")
    qp, sol = case
    path = write_xdmf(tmp_path / "sub" / "out.xdmf", qp, sol)
    assert sorted(os.listdir(tmp_path / "sub")) == ["out.h5", "out.xdmf"]
    _check(meshio.read(path), qp, sol)


def test_to_meshio_without_defect_maps(case):
    qp, sol = case
    maps = {k: v for k, v in qp.maps.items() if not k.startswith("defect")}
    bare = type(qp)(K=qp.K, F=qp.F, B=qp.B, weights=qp.weights, maps=maps, params=qp.params,
                    geometry=qp.geometry, material=qp.material)
    mesh = to_meshio(bare, sol)
    assert [c.type for c in mesh.cells] == ["triangle"]
    assert "jump_normal" not in mesh.cell_data


def test_cli_solve_writes_vtk(tmp_path, capsys):
    vtu, xdmf = tmp_path / "a.vtu", tmp_path / "a.xdmf"
    argv = ["solve", "f2", "--set", "N=16", "--set", "delta=0.1", "--solver", pick_solver(), "--vtk", str(vtu)]
    try:
        import h5py  # noqa: F401
        argv += ["--xdmf", str(xdmf)]
    except ImportError:
        xdmf = None
    assert main(argv) == 0
    assert "wrote" in capsys.readouterr().err
    mesh = meshio.read(vtu)
    assert mesh.cells[0].data.shape[0] == 2 * 16 * 16
    assert np.nanmax(mesh.cell_data["von_mises"][0]) > 0
    if xdmf is not None:
        assert meshio.read(xdmf).points.shape == mesh.points.shape


def test_cli_rejects_bad_names_before_solving(tmp_path, capsys):
    bad = tmp_path / "a.vtk"
    assert main(["solve", "f2", "--set", "N=16", "--vtk", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "--vtk" in err and ".vtu" in err and len(err.strip().splitlines()) == 1
    assert not bad.exists()
    assert main(["solve", "f2", "--set", "N=16", "--xdmf", str(tmp_path / "a.h5")]) == 2
    assert "--xdmf" in capsys.readouterr().err


@pytest.fixture(scope="module")
def two_defects():
    pytest.importorskip("gmsh")
    qp = load_scene("two_defects", {"mesh_size": 0.1, "tip_size": 0.05}).build()
    sol = run("pdas", qp)
    assert sol.ok
    return qp, sol


@pytest.mark.parametrize("kind", ["vtu", "xdmf"])
def test_two_defect_gmsh_scene(two_defects, tmp_path, kind):
    """Line cells per defect (none joins two defects), defect ids and per-node normals, read back."""
    if kind == "xdmf":
        pytest.importorskip("h5py")
    qp, sol = two_defects
    write = write_vtu if kind == "vtu" else write_xdmf
    mesh = meshio.read(write(tmp_path / f"two.{kind}", qp, sol))
    it = qp.interface
    nn = qp.geometry.nodes.shape[1]
    ids, tips = it.defect_id, it.front
    sizes = np.bincount(ids)
    assert sizes.size == 2 and tips.size == 4
    tri, line = mesh.cells[0].data, mesh.cells[1].data
    assert np.array_equal(tri, qp.geometry.cells.T)
    assert line.shape == (2 * int(np.sum(sizes + 1)), 2)       # k + 1 edges per face of a defect with k nodes
    # every line is an edge of a triangle, and joins two nodes of its own defect
    tedges = {tuple(sorted(e)) for t in tri for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    assert all(tuple(sorted(e)) in tedges for e in line)
    pid, cid = mesh.point_data["defect_id"], mesh.cell_data["defect_id"]
    assert np.all(cid[0] == -1)
    assert np.array_equal(pid[line[:, 0]], cid[1]) and np.array_equal(pid[line[:, 1]], cid[1])
    assert np.bincount(cid[1]).tolist() == [2 * (sizes[0] + 1), 2 * (sizes[1] + 1)]
    assert np.array_equal(pid[it.upper], ids) and np.array_equal(pid[it.lower], ids)
    assert np.array_equal(pid[tips], [0, 0, 1, 1])
    assert np.sum(pid >= 0) == 2 * qp.m + 4
    # faces: +1 edges run over upper copies and tips only, -1 edges over lower copies and tips
    face = mesh.cell_data["face"][1]
    upper_or_tip = np.isin(line, np.r_[it.upper, tips]).all(axis=1)
    lower_or_tip = np.isin(line, np.r_[it.lower, tips]).all(axis=1)
    assert np.all(upper_or_tip[face == 1]) and np.all(lower_or_tip[face == -1])
    # per-node normals: the QP's at both copies, unit length on the defects, zero elsewhere
    nrm = mesh.point_data["normal"]
    assert nrm.shape == (nn, 3) and np.all(nrm[:, 2] == 0)
    for copies in (it.upper, it.lower):
        np.testing.assert_allclose(nrm[copies, :2], it.normals, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(nrm[pid >= 0], axis=1), 1.0, rtol=1e-12)
    assert np.all(nrm[pid < 0] == 0)
    # nodal jumps are B x on both copies, 0 at the tips
    pj = mesh.point_data["jump_normal"]
    np.testing.assert_allclose(pj[it.upper], qp.B @ sol.x, rtol=0, atol=1e-14 * np.abs(sol.x).max())
    np.testing.assert_allclose(pj[it.lower], qp.B @ sol.x, rtol=0, atol=1e-14 * np.abs(sol.x).max())
    assert np.all(pj[tips] == 0) and np.all(pj[pid < 0] == 0) and (pid < 0).sum() == nn - 2 * qp.m - 4
    assert all(np.all(np.isfinite(v)) for v in mesh.point_data.values())
    assert np.all(mesh.point_data["pressure"][tips] == 0)
