"""Tresca friction through the conic backends (clarabel: epigraph cones, numerics/epigraph.py; cvxpy: norm
terms) and the exact face polish (numerics/face_polish.py), on small 2D and 3D scenes: both certified, agreeing
with each other, the multipliers in the block layout with the QP's sign (K x - F = G' mu), and g = 0 giving the
frictionless answer to 1e-12."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.solution import Status
from dualfem.experiments.runner import run
from dualfem.scene import load_scene

pytest.importorskip("gmsh")
pytest.importorskip("clarabel")

SCENES = {"2d": ("f2", {"N": 16}, 5.0), "3d": ("three_d", {"N": 6}, 0.05)}


def _qp(dim, bound=None):
    name, keys, g = SCENES[dim]
    extra = {} if bound is False else {"friction": "tresca", "friction_bound": g if bound is None else bound}
    return load_scene(name, {**keys, **extra}).build()


def _rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("dim", ["2d", "3d"])
def test_clarabel_and_cvxpy_solve_tresca_certified_and_agree(dim):
    pytest.importorskip("cvxpy")
    qp = _qp(dim)
    a, b = run("clarabel", qp), run("cvxpy", qp)
    assert a.status == b.status == Status.SOLVED, (a.message, b.message)
    assert a.info["polished"] and b.info["polish"]["applied"]
    assert a.info["certificate"]["value"] < 1e-9 and b.info["certificate"]["value"] < 1e-9
    assert _rel(a.x, b.x) < 1e-9 and _rel(a.multipliers, b.multipliers) < 1e-8
    # the layout: Signorini forces first, then the friction forces; K x - F = G' mu (the QP's sign)
    assert a.multipliers.size == qp.m_total
    r = qp.K @ a.x - qp.F - qp.G.T @ a.multipliers
    assert np.abs(r).max() < 1e-9 * np.abs(qp.F).max()
    # friction does something here: some node slips, so the answer is not the frictionless one
    assert _rel(a.x, run("clarabel", _qp(dim, bound=False)).x) > 1e-4


def test_unpolished_clarabel_is_only_as_good_as_its_interior_point():
    sol = run("clarabel", _qp("3d"), {"polish": False})
    assert "polished" not in sol.info and sol.info["certificate"]["value"] > 1e-12


@pytest.mark.parametrize("dim", ["2d", "3d"])
def test_zero_threshold_gives_the_frictionless_answer(dim):
    free = run("clarabel", _qp(dim, bound=False))
    zero = run("clarabel", _qp(dim, bound=0.0))
    assert zero.status == Status.SOLVED and zero.info["polished"]
    assert _rel(zero.x, free.x) < 1e-12
    assert _rel(zero.multipliers[:free.multipliers.size], free.multipliers) < 1e-12
    assert np.abs(zero.multipliers[free.multipliers.size:]).max() == 0.0


def test_epigraph_soc_and_linear_forms_give_the_same_multipliers():
    import clarabel
    import scipy.sparse as sp

    from dualfem.numerics.epigraph import epigraph

    qp = _qp("2d")
    out = []
    for soc in (False, True):
        e = epigraph(qp, soc_2d=soc)
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        cone = {"nonneg": clarabel.NonnegativeConeT, "soc": clarabel.SecondOrderConeT}
        sol = clarabel.DefaultSolver(sp.triu(e.P, format="csc"), e.q, (-e.A).tocsc(), np.zeros(e.A.shape[0]),
                                     [cone[k](m) for k, m in e.cones], settings).solve()
        out.append(e.unscale(np.array(sol.x), np.array(sol.z)))
    assert _rel(out[0][0], out[1][0]) < 1e-6 and _rel(out[0][1], out[1][1]) < 1e-5


def test_coulomb_is_skipped_by_a_backend_without_it_with_a_reason():
    from dualfem.core.registry import solvers

    if "qp_pyqpmad" not in solvers() or solvers()["qp_pyqpmad"].missing():
        pytest.skip("qp_pyqpmad is not installed")
    qp = load_scene("f2", {"N": 16, "friction": "coulomb", "friction_coefficient": 0.3}).build()
    sol = run("qp_pyqpmad", qp)        # the other qp_ backends take 2D Coulomb (tests/test_qpsolvers_coulomb.py)
    assert sol.status == Status.SKIPPED and "coulomb" in sol.message


@pytest.mark.parametrize("name", ["osqp", "qp_proxqp", "qp_daqp"])
def test_qp_backends_take_2d_friction_and_skip_3d_discs(name):
    from dualfem.core.registry import solvers

    if name not in solvers() or solvers()[name].missing():
        pytest.skip(f"{name} is not installed")
    ref = run("clarabel", _qp("2d"))
    sol = run(name, _qp("2d"))
    assert sol.status == Status.SOLVED and _rel(sol.x, ref.x) < 1e-6, sol.message
    sol = run(name, _qp("3d"))
    assert sol.status == Status.SKIPPED and "second-order cones" in sol.message
    if name == "osqp":                  # Coulomb's Tresca problems are discs in 3D too
        coul = load_scene("three_d", {"N": 4, "friction": "coulomb", "friction_coefficient": 0.3}).build()
        sol = run(name, coul)
        assert sol.status == Status.SKIPPED and "second-order cones" in sol.message


def test_rotation_and_unit_invariance():
    """The frictional answer of a rotated scene has the same jumps in the defect's frame; in other units the
    displacements scale by the length and the forces by stress x length (friction_bound converts as a stress)."""
    from dualfem.problems.thin_defect import ThinDefect

    keys = {"N": 16, "friction": "tresca", "friction_bound": 2.0}
    base = _qp_of(keys)
    a = run("clarabel", base)
    rot = _qp_of({**keys, "rotate_deg": 30.0})
    b = run("clarabel", rot)
    ja, jb = np.concatenate(base.interface.jumps(a.x), axis=None), np.concatenate(rot.interface.jumps(b.x), axis=None)
    assert np.abs(ja - jb).max() < 1e-9 * np.abs(ja).max()
    assert _rel(b.multipliers, a.multipliers) < 1e-8
    s, L = 1e3, 2.0
    conv = ThinDefect.unit_map.convert(ThinDefect.defaults, {**keys, "load": "f2"}, s, L)
    c = run("clarabel", _qp_of(conv))
    assert c.status == Status.SOLVED
    assert _rel(c.x, L * a.x) < 1e-8 and _rel(c.multipliers, s * L * a.multipliers) < 1e-8


def _qp_of(keys):
    return load_scene("f2", keys).build()
