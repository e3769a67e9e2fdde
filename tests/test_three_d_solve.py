"""3D scenes solved: the exact solvers and Clarabel agree, a rigid rotation of the whole scene changes
nothing, and the penny crack behaves as the closed form says (opens under tension, closes under
compression with the remote pressure). Small meshes: the full-size validation is benchmarks/penny.py."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run

pytest.importorskip("gmsh")

#: a disk under the f2 top load (part of it closes) and a spherical cap with its own delta
TWO = {"mesh_size": 0.2, "tip_size": 0.07, "defects": [
    {"shape": "disk", "center": [0.5, 0.5, 0.55], "normal": [0.1, 0.0, 1.0], "radius": 0.3},
    {"shape": "cap", "center": [0.5, 0.5, -0.05], "axis": [0, 0, 1], "curvature_radius": 0.3, "radius": 0.2,
     "delta": 1e-3}]}
E, NU, A = 1000.0, 0.3, 1.0


@functools.cache
def _two():
    return load_scene("three_d", TWO).build()


def test_exact_solvers_and_clarabel_agree():
    qp = _two()
    ref = run("pdas", qp)
    assert ref.ok
    contact = evaluator.contact_set(qp, ref.x)
    assert 0 < contact.sum() < qp.m, "the scene must have open and closed nodes"
    e = qp.energy(ref.x)
    for name in ("uzawa", "uzawa_auto", "mprgp", "dual_gradient", "clarabel"):
        s = run(name, qp)
        assert s.ok, (name, s.status, s.message)
        assert abs(qp.energy(s.x) - e) <= 1e-8 * abs(e), name
        assert np.array_equal(evaluator.contact_set(qp, s.x), contact) or name == "clarabel", name


@pytest.mark.parametrize("extra", [{}, {"remote_stress": [[0.0, 0.0, 2.0], [0.0, 0.0, 0.0], [2.0, 0.0, -3.0]],
                                        "load": "f2"}], ids=["clamped_f2", "remote_shear_compression"])
def test_rotation_of_the_whole_scene_changes_nothing(extra):
    params = {**TWO, **extra}
    a = load_scene("three_d", params).build() if extra else _two()
    b = load_scene("three_d", {**params, "rotate_deg": 37.0, "rotate_axis": [1.0, 2.0, 3.0]}).build()
    sa, sb = run("pdas", a), run("pdas", b)
    assert sa.ok and sb.ok
    assert abs(a.energy(sa.x) - b.energy(sb.x)) <= 1e-9 * abs(a.energy(sa.x))
    ca, cb = evaluator.contact_set(a, sa.x), evaluator.contact_set(b, sb.x)
    assert np.array_equal(ca, cb) and ca.any()
    assert np.allclose(sa.multipliers, sb.multipliers, rtol=0, atol=1e-8 * np.abs(sa.multipliers).max())


def _penny(stress_zz: float):
    qp = load_scene("penny", {"remote_stress": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, stress_zz]]}).build()
    sol = run("pdas", qp)
    assert sol.ok
    X = qp.geometry.nodes[:, qp.interface.lower]
    r = np.hypot(X[0] - 5.0, X[1] - 5.0)
    return qp, sol, r


def test_penny_crack_opens_under_tension():
    qp, sol, r = _penny(1.0)
    jump = qp.B @ sol.x
    w0 = 8 * (1 - NU ** 2) * 1.0 * A / (np.pi * E)
    assert jump.min() > 0 and not evaluator.contact_set(qp, sol.x).any()
    assert r[np.argmax(jump)] < 0.4 * A                                # widest near the centre
    assert 0.6 * w0 < jump.max() < 1.1 * w0                            # coarse mesh: P1 opens it less
    # the opening falls towards the front like sqrt(a^2 - r^2): decreasing in r on average
    assert np.corrcoef(r, jump)[0, 1] < -0.8
    assert np.allclose(qp.interface.normals, [0.0, 0.0, 1.0])


def test_penny_crack_closes_under_compression_with_the_remote_pressure():
    qp, sol, r = _penny(-1.0)
    jump = qp.B @ sol.x
    assert np.abs(jump).max() <= 1e-10 * np.abs(sol.x).max()
    assert evaluator.contact_set(qp, sol.x).all()
    assert sol.multipliers.sum() / qp.weights.sum() == pytest.approx(1.0, rel=0.02)
    assert np.abs(qp.pressure(sol.multipliers) - 1.0).max() < 0.1


def test_face_pressure_opens_the_penny_like_remote_tension():
    """Superposition: a pressure p on both faces of the crack in an unloaded body opens it exactly as the
    remote tension p does (their difference is the uncracked body's uniform state, exact in P1)."""
    zero = [[0.0] * 3 for _ in range(3)]
    disk = {"shape": "disk", "center": [5.0, 5.0, 5.0], "normal": [0.0, 0.0, 1.0], "radius": 1.0}
    a = load_scene("penny", {"remote_stress": zero, "defects": [{**disk, "face_pressure": 1.0}]}).build()
    b = load_scene("penny", {}).build()
    sa, sb = run("pdas", a), run("pdas", b)
    assert sa.ok and sb.ok
    ja, jb = a.B @ sa.x, b.B @ sb.x
    assert jb.min() > 0 and np.abs(ja - jb).max() <= 1e-8 * jb.max()
