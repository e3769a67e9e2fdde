"""General defect geometry on the problem layer: polylines with kinks, several defects, per-defect
delta, rigid rotation of the scene (issue 16). Physics checks: the patch test on the cut mesh
(a uniform stress gives, on each face copy of a defect node, exactly the face traction), rigid
motions, invariance of the solution under rotation."""
from __future__ import annotations

import numpy as np
import pytest
from _defects import patch_check, rotation_check

from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene

KINKED = [{"points": [[0.25, 0.5], [0.5, 0.5], [0.75, 0.75]]}]


def test_kinked_polyline_on_the_grid():
    problem = load_scene("f2", {"N": 16, "defects": KINKED})
    qp = problem.build()
    assert qp.m == 7 and "normal" not in qp.maps  # 3 + kink + 3 doubled nodes; no single normal
    j = 3  # the kink at (0.5, 0.5)
    assert np.allclose(qp.geometry.nodes[:, qp.interface.lower[j]], [0.5, 0.5])
    n = np.array([0, 1]) + np.array([-1, 1]) / np.sqrt(2)
    assert np.allclose(qp.interface.normals[j], n / np.linalg.norm(n), atol=1e-15)
    assert qp.weights[j] == pytest.approx((1 + np.sqrt(2)) / 32, rel=1e-14)
    assert np.allclose(qp.interface.s, np.r_[np.arange(1, 5) / 16, 0.25 + np.arange(1, 4) * np.sqrt(2) / 16])
    patch_check(problem, qp)
    # rigid motions only in the kernel (the doubled nodes add none): exactly three zero eigenvalues
    ev = np.linalg.eigvalsh(problem.assemble()[0].toarray())
    assert np.sum(ev < 1e-9 * ev.max()) == 3


def test_defects_table_equals_defect_key_and_deltas_add_up():
    a = load_scene("f2", {"N": 16}).build()
    b = load_scene("f2", {"N": 16, "defects": [{"points": [[0.25, 0.5], [0.75, 0.5]]}]}).build()
    assert abs(a.K - b.K).max() == 0 and np.array_equal(a.F, b.F) and abs(a.B - b.B).max() == 0
    two = [{"points": [[0.25, 0.25], [0.5, 0.25]], "delta": 1e-3}, {"points": [[0.5, 0.75], [0.25, 0.5]]}]
    problem = load_scene("f2", {"N": 16, "delta": 1e-2, "defects": two})
    qp = problem.build()
    assert np.array_equal(np.unique(qp.interface.defect_id), [0, 1]) and qp.m == 3 + 3
    # second defect runs from upper right to lower left: its normal is the tangent turned by +90 degrees
    assert np.allclose(qp.interface.normals[qp.interface.defect_id == 1], [np.sqrt(0.5), -np.sqrt(0.5)])
    patch_check(problem, qp)
    # interface term: sum_j w_j / delta_j |jump_j|^2 with each defect's delta
    x = np.random.default_rng(1).standard_normal(qp.n)
    nd, up, lo = qp.geometry.node_dofs, qp.interface.upper, qp.interface.lower
    jump2 = (x[nd[0, up]] - x[nd[0, lo]]) ** 2 + (x[nd[1, up]] - x[nd[1, lo]]) ** 2
    delta = np.where(qp.interface.defect_id == 0, 1e-3, 1e-2)
    assert x @ ((qp.K - qp.K_fixed) @ x) == pytest.approx(np.sum(qp.weights / delta * jump2), rel=1e-12)


@pytest.mark.parametrize("deg", [90.0, 37.0])
def test_rotation_leaves_solution_unchanged_structured(deg):
    rotation_check({"N": 16, "delta": 1e-5, "defects": KINKED}, deg)


@pytest.mark.parametrize("over, words", [
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "curve": "spline"}]}, "defects\\[0\\].curve.*gmsh"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "curve": "bezier"}]}, "defects\\[0\\].curve"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "width": 1}]}, "defects\\[0\\].*unknown key 'width'"),
    ({"defects": [{"curve": "polyline"}]}, "defects\\[0\\].points is missing"),
    ({"defects": [{"points": [[0.25, 0.5]]}]}, "defects\\[0\\].points.*at least two"),
    ({"defects": [{"points": [[0.25, 0.5], [1.25, 0.5]]}]}, "defects\\[0\\].points.*strictly inside"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "delta": -1}]}, "defects\\[0\\].delta"),
    ({"defects": "0.25,0.5,0.75,0.5"}, "list of tables"), ({"defects": 3}, "list of tables"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]]}], "defect": [[0.25, 0.25], [0.5, 0.25]]}, "either defect"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]]}, {"points": [[0.5, 0.25], [0.5, 0.75]]}]}, "touch"),
    ({"defects": [{"points": [[0.25, 0.5], [0.5, 0.5], [0.375, 0.5]]}]}, "retraces"),
    ({"mesh": "delaunay"}, "mesh must be one of structured, gmsh"),
    ({"mesh_size": -0.1}, "mesh_size"), ({"tip_size": "big"}, "tip_size"), ({"rotate_deg": float("inf")}, "rotate_deg"),
])
def test_bad_defect_keys(over, words):
    with pytest.raises(InputError, match=words):
        load_scene("f2", {"N": 16, **over}).build()


def mirror_symmetric_grid(N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-square N x N grid whose squares are cut by (1, -1) diagonals left of x = 1/2 and by (1, 1)
    diagonals right of it: the mesh is its own mirror image about x = 1/2. Returns nodes, triangles
    and the grid index ix[i, j] of node (i / N, j / N)."""
    x = np.linspace(0, 1, N + 1)
    p = np.vstack([np.repeat(x, N + 1), np.tile(x, N + 1)])
    ix = np.arange((N + 1) ** 2).reshape(N + 1, N + 1)
    ll, ul, ur, lr = ix[:-1, :-1], ix[:-1, 1:], ix[1:, 1:], ix[1:, :-1]
    left = np.broadcast_to((np.arange(N) < N // 2)[:, None], ll.shape)
    t1 = np.where(left, np.stack([ll, lr, ul]), np.stack([ll, lr, ur]))
    t2 = np.where(left, np.stack([lr, ur, ul]), np.stack([ll, ur, ul]))
    return p, np.hstack([t1.reshape(3, -1), t2.reshape(3, -1)]).astype(np.int32), ix


@pytest.mark.parametrize("vee, load", [(False, "-30*exp(-100*(x-0.5)**2) + 6"), (True, "f1")])
def test_mirror_symmetric_scene_gives_symmetric_contact(vee, load):
    """A body, mesh, load and defect symmetric about x = 1/2 (a straight defect, or a V kinked at the
    axis): the contact set is its own mirror image and so is the solution."""
    from dualfem.core import evaluator
    from dualfem.experiments.runner import run
    from dualfem.post.fields import nodal_displacement
    from dualfem.problems.thin_defect import ThinDefect

    N = 32

    class Mirrored(ThinDefect):
        def _reference_mesh(self):
            p, t, ix = mirror_symmetric_grid(N)
            i = np.arange(N // 4, 3 * N // 4 + 1)
            j = np.abs(i - N // 2) + N // 2 if vee else np.full(i.size, N // 2)
            return p, t, [ix[i, j]]

    pts = [[0.25, 0.75], [0.5, 0.5], [0.75, 0.75]] if vee else [[0.25, 0.5], [0.75, 0.5]]
    qp = Mirrored(N=N, load=load, delta=1e-5, defects=[{"points": pts}]).build()
    sol = run("pdas", qp)
    c = evaluator.contact_set(qp, sol.x)
    assert np.array_equal(c, c[::-1])
    assert 0 < c.sum() < c.size if not vee else c.all()
    # the solution: u1(1 - x, y) = -u1(x, y), u2(1 - x, y) = u2(x, y) at mirrored nodes (same face)
    X = qp.geometry.nodes
    u = nodal_displacement(qp, sol.x)
    key = {(round(a, 9), round(b, 9), k >= (N + 1) ** 2): k for k, (a, b) in enumerate(X.T)}
    mirror = np.array([key[(round(1 - a, 9), round(b, 9), k >= (N + 1) ** 2)] for k, (a, b) in enumerate(X.T)])
    scale = np.abs(u).max()
    assert np.abs(u[mirror, 0] + u[:, 0]).max() <= 1e-9 * scale
    assert np.abs(u[mirror, 1] - u[:, 1]).max() <= 1e-9 * scale


def test_post_defect_fields_use_the_per_node_normals():
    from dualfem.experiments.runner import run
    from dualfem.post.fields import defect_fields

    qp = load_scene("f2", {"N": 16, "defects": KINKED, "rotate_deg": 20}).build()
    sol = run("pdas", qp)
    f = defect_fields(qp, sol.x, sol.multipliers)
    assert np.allclose(f["jump_normal"][f["interior"]], qp.B @ sol.x, rtol=0, atol=1e-12 * np.abs(sol.x).max())
    assert f["s"][-1] == pytest.approx(0.25 + 0.25 * np.sqrt(2), rel=1e-14)  # arc length, kink included
    assert np.all(np.diff(f["s"]) > 0)


def test_cut_refuses_defect_nodes_not_joined_by_edges():
    from dualfem.problems.thin_defect.cut import cut
    from dualfem.problems.thin_defect.mesh import structured_mesh

    p, t = structured_mesh(4, 1.0, 1.0)
    with pytest.raises(ValueError, match="not joined by mesh edges"):
        cut(p, t, [np.array([6, 12, 16])])  # node (i, j) = 5 i + j: (1, 1), (2, 2), (3, 1): the last step is no edge
