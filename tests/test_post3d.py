"""3D post-processing: stresses per tetrahedron, defect fields, plane cuts, VTU output and the solve figure."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.post.fields3d import defect_fields3d, plane_cut, stresses3d, tet_gradients


@pytest.fixture(scope="module")
def penny():
    qp = load_scene("penny", {}).build()
    sol = run("pdas", qp)
    assert str(sol.status) in ("solved", "Status.SOLVED")
    return qp, sol


def test_far_field_stress_is_the_remote_stress_and_the_crack_opens(penny):
    qp, sol = penny
    st = stresses3d(qp, sol.x)
    X = qp.geometry.nodes[:, qp.geometry.cells].mean(axis=1)          # centroids
    far = np.linalg.norm(X - 5.0, axis=0) > 3.5                        # a radius 1 crack at the cube's centre
    assert np.median(st["s33"][far]) == pytest.approx(1.0, rel=0.05)   # remote sigma_zz = 1
    assert np.median(np.abs(st["s11"][far])) < 0.1
    d = defect_fields3d(qp, sol.x, sol.multipliers)
    assert d["opening"].min() > 0 and np.all(d["pressure"] == 0)
    r = np.hypot(d["points"][:, 0] - 5, d["points"][:, 1] - 5)
    assert d["opening"][np.argmin(r)] == pytest.approx(d["opening"].max(), rel=0.2)   # widest at the centre
    assert d["slip"].max() < 0.2 * d["opening"].max()


def test_plane_cut_sections_have_the_area_of_the_box_section(penny):
    qp, _ = penny
    g = qp.geometry
    polys, tets, bary = plane_cut(g.nodes, g.cells, [5.0, 5.0, 5.37], [0, 0, 1])
    a = 0.5 * (np.linalg.norm(np.cross(polys[:, 1] - polys[:, 0], polys[:, 2] - polys[:, 0]), axis=1)
               + np.linalg.norm(np.cross(polys[:, 2] - polys[:, 0], polys[:, 3] - polys[:, 0]), axis=1))
    assert a.sum() == pytest.approx(100.0, rel=1e-9)                  # the 10 x 10 section
    P = np.einsum("kva,iak->kvi", bary, g.nodes[:, g.cells[:, tets]])
    assert np.abs(P - polys).max() < 1e-12
    _, vol = tet_gradients(g.nodes, g.cells)
    assert vol.sum() == pytest.approx(1000.0, rel=1e-9)


def test_vtu_holds_tetrahedra_and_both_defect_faces(penny, tmp_path):
    meshio = pytest.importorskip("meshio")
    from dualfem.post.vtk import write_outputs

    qp, sol = penny
    (path,) = write_outputs(qp, sol, vtk=str(tmp_path / "p.vtu"))
    m = meshio.read(path)
    blocks = {c.type: c.data for c in m.cells}
    nf = qp.interface.faces.shape[0]
    assert blocks["tetra"].shape == (qp.geometry.cells.shape[1], 4) and blocks["triangle"].shape == (2 * nf, 3)
    opening = m.point_data["opening"]
    assert np.allclose(opening[qp.interface.upper], opening[qp.interface.lower])
    on = m.point_data["defect_id"] >= 0
    assert opening[on].min() > 0 and on.sum() == 2 * qp.m
    # no NaN in any point field: 0 away from the defects (and the pressure 0 at the front)
    for k, v in m.point_data.items():
        assert np.all(np.isfinite(v)), k
    assert np.all(opening[~on] == 0) and np.all(m.point_data["pressure"][~on] == 0)
    face = m.cell_data["face"]
    assert set(np.unique(face[1])) == {-1, 1} and np.all(face[0] == 0)
    # the "+" triangles use the "+" copies: none of their nodes is a "-" copy
    plus = blocks["triangle"][:nf]
    assert not np.isin(plus, qp.interface.lower).any()


def test_solve_figure_writes_maps_and_cut(tmp_path):
    from dualfem.cli import main

    out = tmp_path / "penny.png"
    assert main(["solve", "penny", "--quiet", "--figure", str(out)]) == 0
    assert out.stat().st_size > 10_000 and (tmp_path / "penny_cut.png").stat().st_size > 10_000
    assert main(["solve", "penny", "--quiet", "--figure", str(tmp_path / "x.gif")]) == 2


def test_stress_grid_on_a_3d_scene_has_no_2d_keys():
    """The nu axis sets plane strain only where the problem has the key: a 3D scene's tasks build."""
    from dualfem.core.scene import load_scene as load
    from dualfem.experiments.stress_grid import build_grid

    tasks = build_grid(["pdas"], quick=True, axes=("nu",), scene_name="penny")
    assert tasks and all("plane" not in t.scene for t in tasks)
    assert load("penny", {"nu": tasks[0].scene["nu"]}).params["nu"] == tasks[0].scene["nu"]


def test_maps_at_rounding_level_say_so_and_the_cut_names_its_plane(penny):
    from types import SimpleNamespace

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.post.figures3d import plot_cut, plot_defect_maps

    qp, sol = penny
    # a pressure of 1e-20 (rounding next to stresses of order 1) is no field: the panel says so, no colour bar
    tiny = SimpleNamespace(x=sol.x, multipliers=np.full(qp.m, 1e-20), status=sol.status)
    fig = plot_defect_maps(qp, tiny)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert titles == ["defect 0: opening", "defect 0: slip", "defect 0: pressure (no contact pressure)"]
    assert len(fig.axes) == 5                     # three maps, two colour bars (opening, slip)
    assert any("rounding" in t.get_text() for ax in fig.axes for t in ax.texts)
    assert all(ax.get_xlabel().startswith("along ") for ax in fig.axes if ax.get_title())
    plt.close(fig)
    ax = plot_cut(qp, sol)
    assert "plane through (" in ax.get_title() and "normal " in ax.get_title()
    assert ax.get_xlabel().startswith("along ") and ax.get_ylabel().startswith("along ")
    plt.close(ax.figure)
