"""The ZZ estimator on P2 / quarter-point triangles and ``refine = "adaptive"`` on quadratic scenes (small sizes)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.experiments.runner import run
from dualfem.numerics.estimator import estimate
from dualfem.numerics.estimator_p2 import zz_estimate_p2
from dualfem.numerics.p2 import quadratic_cells
from dualfem.problems._quadratic import edge_table

pytest.importorskip("gmsh")
from test_adaptive import griffith, true_error  # noqa: E402


def _p2_mesh(quarter: bool):
    """A Delaunay mesh of the unit square, its P2 nodes (vertices, then one per sorted edge); ``quarter``: the
    mid-edge nodes of the edges at vertex 0 moved to a quarter of the edge from it (a quarter-point fan)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(3)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((10, 2)) * 0.8 + 0.1].T
    tri = Delaunay(p.T).simplices.T
    edges, _ = edge_table(tri)
    mid = 0.5 * (p[:, edges[0]] + p[:, edges[1]])
    if quarter:
        at0 = edges[0] == 0                                    # sorted pairs: vertex 0 comes first
        mid[:, at0] = 0.75 * p[:, edges[0][at0]] + 0.25 * p[:, edges[1][at0]]
    return np.hstack([p, mid]), tri


@pytest.mark.parametrize("quarter", [False, True])
def test_recovery_reproduces_the_fields_p2_holds_exactly(quarter):
    """P2 holds a quadratic displacement exactly on straight triangles (stress linear and continuous), the
    isoparametric quarter-point elements a linear one (stress constant): no error is seen; a cubic one is seen."""
    P, tri = _p2_mesh(quarter)
    x, y = P
    u = np.stack([0.01 * x + 0.02 * y, -0.003 * y], axis=1)
    if not quarter:
        u += np.stack([0.01 * x * y, 0.02 * x * x - 0.01 * y * y], axis=1)
    est = zz_estimate_p2(P, tri, u, 1.0, 1.0)
    assert est.eta < 1e-10 * est.energy and est.energy > 0 and est.order == 2.0
    assert np.isclose(est.area.sum(), 1.0)
    cubic = np.stack([x ** 3, 0 * y], axis=1)
    assert zz_estimate_p2(P, tri, cubic, 1.0, 1.0).relative > 1e-3
    assert quadratic_cells(P, tri).shape == (6, tri.shape[1])


@pytest.mark.parametrize("element, lo, hi", [("P2", 0.6, 1.0), ("P2-quarter-point", 1.5, 2.6)])
def test_effectivity_on_griffith(element, lo, hi):
    """eta / ||u - u_h|| against the closed-form energy (measured 0.78 on P2, 2.1 on quarter-point elements, whose
    singular tip stress the continuous recovery cannot follow: the estimate is conservative there)."""
    qp = griffith(element=element).build()
    sol = run("pdas", qp)
    est = estimate(qp, sol.x, sol.multipliers)
    assert est.eta2.size == qp.geometry.cells.shape[1]
    assert lo < est.eta / true_error(qp, sol.x) < hi


def test_scene_option_refines_a_quarter_point_scene():
    """refine = "adaptive" on P2-quarter-point: several meshes, the estimate falls to the target, the unknowns
    counted with the edges (size_of_mesh = qp.n + the 3 rigid-body removals), quarter points at the tips."""
    pr = griffith(element="P2-quarter-point", refine="adaptive", target_error=6e-3, max_unknowns=20_000)
    qp = pr.build()
    steps = pr.shared.data["adaptive"]
    assert len(steps) >= 2 and steps[-1][1] <= 6e-3 < steps[0][1] and qp.params["adaptive_steps"] == len(steps)
    assert pr.size_of_mesh() == qp.n + 3 and qp.n <= 20_000 and qp.geometry.element == "P2-quarter-point"
    c6 = quadratic_cells(qp.geometry.nodes, qp.geometry.cells)
    P = qp.geometry.nodes
    tips = qp.interface.front
    for k, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
        at_tip = np.isin(c6[a], tips)
        want = 0.75 * P[:, c6[a][at_tip]] + 0.25 * P[:, c6[b][at_tip]]
        assert at_tip.sum() == 0 or np.allclose(P[:, c6[3 + k][at_tip]], want)
    assert np.isin(c6[:3], tips).sum() >= 8
