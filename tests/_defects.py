"""Shared checks of the defect tests (tests/test_defects.py, tests/test_gmsh_defects.py)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.scene import load_scene
from dualfem.problems.thin_defect import lame


def defect_polylines(qp) -> list[np.ndarray]:
    """Ordered node ids (tips included, "-" copies inside) of each defect, from the interface part."""
    it = qp.interface
    tips, ids = it.front.reshape(-1, 2), it.defect_id
    return [np.r_[tips[k, 0], it.lower[ids == k], tips[k, 1]] for k in range(tips.shape[0])]


def face_forces(qp, sigma: np.ndarray) -> np.ndarray:
    """Per constrained node j, sum over its two defect edges e of sigma nu_e |e| / 2, shape (m, 2)."""
    X = np.asarray(qp.geometry.nodes)
    out = []
    for nodes in defect_polylines(qp):
        d = np.diff(X[:, nodes], axis=1)
        nu_len = np.vstack([-d[1], d[0]])  # edge normal times edge length (tangent turned by +90 degrees)
        half = 0.5 * (nu_len[:, :-1] + nu_len[:, 1:])
        out.append((sigma @ half).T)
    return np.vstack(out)


def patch_check(problem, qp) -> None:
    """Uniform strain on every node (both copies): K u on the copies equals -/+ the face tractions."""
    E, nu, plane = qp.params["E"], qp.params["nu"], qp.params["plane"]
    lam, mu = lame(E, nu, plane)
    eps = np.array([[2e-3, 0.7e-3], [0.7e-3, -1e-3]])
    sigma = lam * np.trace(eps) * np.eye(2) + 2 * mu * eps
    K_all, _, _ = problem.assemble()
    X = np.asarray(qp.geometry.nodes)
    u = (eps @ X).T.ravel() + np.tile([0.3, -0.1], X.shape[1])  # DOF 2 i + c
    f = (K_all @ u).reshape(-1, 2)
    ref = face_forces(qp, sigma)
    up, lo = qp.interface.upper, qp.interface.lower
    scale = np.abs(ref).max()
    assert np.abs(f[up] + ref).max() <= 1e-10 * scale
    assert np.abs(f[lo] - ref).max() <= 1e-10 * scale
    # nodes off the defect (and not on the outer boundary) feel no force
    inner = np.ones(X.shape[1], bool)
    inner[np.r_[up, lo]] = False
    W, H = qp.params["width"], qp.params["height"]
    c = problem.cut()[0].points
    inner &= (c[0] > 1e-9) & (c[0] < W - 1e-9) & (c[1] > 1e-9) & (c[1] < H - 1e-9)
    assert np.abs(f[inner]).max() <= 1e-10 * scale


def _solve(over):
    from dualfem.experiments.runner import run

    qp = load_scene("f2", over).build()
    sol = run("pdas", qp)
    assert sol.ok
    return qp, sol


def rotation_check(over: dict, deg: float) -> None:
    """Energy, contact set and |jump| (normal and whole vector) unchanged by ``rotate_deg`` to 1e-9."""
    from dualfem.core import evaluator
    from dualfem.post.fields import nodal_displacement

    qp0, s0 = _solve(over)
    qp1, s1 = _solve({**over, "rotate_deg": deg})
    R = np.array([[np.cos(np.deg2rad(deg)), -np.sin(np.deg2rad(deg))],
                  [np.sin(np.deg2rad(deg)), np.cos(np.deg2rad(deg))]])
    c = np.array([qp0.params["width"], qp0.params["height"]]) / 2
    assert np.allclose(qp1.geometry.nodes, R @ (qp0.geometry.nodes - c[:, None]) + c[:, None], atol=1e-14)
    assert qp1.energy(s1.x) == pytest.approx(qp0.energy(s0.x), rel=1e-9)
    assert np.array_equal(evaluator.contact_set(qp0, s0.x), evaluator.contact_set(qp1, s1.x))
    j0, j1 = qp0.B @ s0.x, qp1.B @ s1.x
    # (scale: the largest jump, or the contact tolerance 1e-6 |x| when the defect is closed everywhere)
    assert np.abs(j1 - j0).max() <= 1e-9 * max(np.abs(j0).max(), 1e-6 * np.abs(s0.x).max())
    u0 = nodal_displacement(qp0, s0.x).T
    u1 = nodal_displacement(qp1, s1.x).T
    assert np.abs(u1 - R @ u0).max() <= 1e-9 * np.abs(u0).max()  # displacements rotate with the body
    assert np.abs(s1.multipliers - s0.multipliers).max() <= 1e-9 * np.abs(s0.multipliers).max()
