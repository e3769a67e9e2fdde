"""The problem layer: stiffness, kernel, patch test, interface term, defect doubling, loads."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.problems.thin_defect import lame


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_stiffness_symmetric_spd_after_bc(scene, plane):
    _, qp = scene("f2", 8, 1e-5, plane)
    K = qp.K.toarray()
    assert np.abs(K - K.T).max() <= 1e-12 * np.abs(K).max()
    assert np.linalg.eigvalsh(K).min() > 0
    # the elastic part alone (delta-independent) is SPD too: the cracked body stays connected
    assert np.linalg.eigvalsh(qp.K_fixed.toarray()).min() > 0


def test_rigid_motions_in_kernel_before_bc():
    problem = load_scene("f2", {"N": 8})
    K_all, _, basis = problem.assemble()
    x, y = problem.mesh()[0].p
    nd = basis.nodal_dofs
    for ux, uy in ((np.ones_like(x), 0 * x), (0 * x, np.ones_like(x)), (-y, x)):
        u = np.zeros(basis.N)
        u[nd[0]], u[nd[1]] = ux, uy
        assert np.abs(K_all @ u).max() <= 1e-9 * np.abs(K_all).max()
    # and nothing else: exactly three zero eigenvalues (the doubled nodes do not add any)
    ev = np.linalg.eigvalsh(K_all.toarray())
    assert np.sum(ev < 1e-9 * ev.max()) == 3


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_patch_uniaxial_stress_reproduced_exactly(plane):
    """u linear with sigma_11 = s only: the defect faces are traction free and the jump is 0,
    so prescribing u on the outer boundary must give u exactly at every node (both copies)."""
    E, nu = 69000.0, 0.3
    problem = load_scene("f2", {"N": 8, "E": E, "nu": nu, "plane": plane})
    K_all, _, basis = problem.assemble()
    mesh = problem.mesh()[0]
    lam, mu = lame(E, nu, plane)
    s11 = 5.0
    # sigma_22 = lam (e11 + e22) + 2 mu e22 = 0  ->  e22 = -lam e11 / (lam + 2 mu)
    e11 = s11 / (lam + 2 * mu - lam**2 / (lam + 2 * mu))
    e22 = -lam * e11 / (lam + 2 * mu)
    x, y = mesh.p
    u = np.zeros(basis.N)
    u[basis.nodal_dofs[0]] = e11 * x + 0.1
    u[basis.nodal_dofs[1]] = e22 * y - 0.2
    bnd = np.unique(basis.nodal_dofs[:, mesh.boundary_nodes()].ravel())
    # the defect faces are (internal) boundary facets of the doubled mesh: keep them free
    outer = np.flatnonzero(np.isclose(x, 0) | np.isclose(x, 1) | np.isclose(y, 0) | np.isclose(y, 1))
    D = np.unique(basis.nodal_dofs[:, outer].ravel())
    assert D.size < bnd.size  # the defect faces really are boundary here
    I = np.setdiff1d(np.arange(basis.N), D)
    uI = sla.spsolve(K_all[I][:, I].tocsc(), -K_all[I][:, D] @ u[D])
    assert np.abs(uI - u[I]).max() <= 1e-12 * np.abs(u).max()


def test_interface_term_is_trapezoid_rule_of_jump_squared():
    delta = 1e-3
    problem = load_scene("f2", {"N": 8, "delta": delta})
    qp = problem.build()
    nd = qp.geometry.node_dofs
    up, lo = qp.interface.upper, qp.interface.lower
    s = qp.interface.s
    rng = np.random.default_rng(0)
    x = rng.normal(size=qp.n)
    jx = x[nd[0, up]] - x[nd[0, lo]]
    jy = x[nd[1, up]] - x[nd[1, lo]]
    # by hand: trapezoid rule over the defect edges, jump = 0 at the two (undoubled) tips
    f = np.r_[0.0, jx**2 + jy**2, 0.0]
    nodes_s = np.r_[0.0, s, 0.5]
    hand = np.sum(np.diff(nodes_s) * 0.5 * (f[:-1] + f[1:]))
    Kp = qp.K - qp.K_fixed
    assert x @ (Kp @ x) == pytest.approx(hand / delta, rel=1e-12)
    # weights: m interior nodes, spacing 1/N
    assert qp.m == 3 and np.allclose(qp.weights, 1 / 8)
    assert np.allclose(s, [1 / 8, 2 / 8, 3 / 8])


def test_defect_doubling_structure(scene):
    _, qp = scene("f2", 16, 1e-5)
    p, t = qp.geometry.nodes, qp.geometry.cells
    up, lo = qp.interface.upper, qp.interface.lower
    assert np.allclose(p[:, up], p[:, lo])                 # same place
    assert np.allclose(p[1, up], 0.5)
    cen = p[:, t].mean(axis=1)
    uses_up = np.isin(t, up).any(axis=0)
    uses_lo = np.isin(t, lo).any(axis=0)
    assert np.all(cen[1, uses_up] > 0.5) and np.all(cen[1, uses_lo & ~uses_up] < 0.5)
    assert not np.any(uses_up & uses_lo)
    tips = qp.interface.front
    assert np.allclose(p[:, tips].T, [[0.25, 0.5], [0.75, 0.5]])
    # B is the normal (x2) jump: +1 on the upper y-DOF, -1 on the lower one
    nd = qp.geometry.node_dofs
    B = qp.B.toarray()
    for j in range(qp.m):
        assert B[j, nd[1, up[j]]] == 1 and B[j, nd[1, lo[j]]] == -1 and np.count_nonzero(B[j]) == 2


def test_diagonal_defect_normal_not_x2():
    problem = load_scene("f2", {"N": 8, "defect": [[0.25, 0.25], [0.75, 0.75]]})
    qp = problem.build()
    assert qp.m == 3
    assert np.allclose(qp.maps["normal"], [-np.sqrt(0.5), np.sqrt(0.5)])
    assert np.allclose(qp.weights, np.sqrt(2) / 8)


@pytest.mark.parametrize("solver", ["clarabel"])
def test_f3_opens_and_f1_closes(solver):
    from dualfem.experiments.runner import run

    qp3 = load_scene("f3", {"N": 16, "delta": 0.1}).build()
    s3 = run(solver, qp3)
    assert s3.ok and np.all(qp3.B @ s3.x > 0) and not evaluator.contact_set(qp3, s3.x).any()
    assert np.abs(s3.multipliers).max() <= 1e-8 * np.abs(qp3.F).max()
    qp1 = load_scene("f1", {"N": 16, "delta": 0.1}).build()
    s1 = run(solver, qp1)
    assert s1.ok and evaluator.contact_set(qp1, s1.x).all()
    assert np.all(s1.multipliers > 0)


def test_load_cases_resultant():
    # f1: -3 on a unit top side; f2: -10 / +10 halves; f3: +3
    for name, total in (("f1", -3.0), ("f2", 0.0), ("f3", 3.0)):
        problem = load_scene(name, {"N": 8})
        _, F_all, basis = problem.assemble()
        assert F_all[basis.nodal_dofs[1]].sum() == pytest.approx(total, abs=1e-12)
        assert np.abs(F_all[basis.nodal_dofs[0]]).max() == 0
    # user expression and callable give the same load vector
    a = load_scene("f2", {"N": 8, "load": "-10*sin(pi*x)"}).assemble()[1]
    b = load_scene("f2", {"N": 8, "load": lambda x, y: -10 * np.sin(np.pi * x)}).assemble()[1]
    assert np.allclose(a, b) and abs(a.sum() + 20 / np.pi) < 1e-3


def test_plane_stress_softer_than_plane_strain():
    from dualfem.experiments.runner import run

    e = {}
    for plane in ("strain", "stress"):
        qp = load_scene("f3", {"N": 8, "plane": plane}).build()
        e[plane] = run("clarabel", qp).residuals["energy"]
    assert e["stress"] < e["strain"] < 0  # more compliant -> lower (more negative) energy


@pytest.mark.parametrize("params, words", [
    ({"N": 10}, "cannot carry the defect"),
    ({"N": 4, "defect": [[0.25, 0.5], [0.5, 0.5]]}, "too coarse"),
    ({"defect": [[0.25, 0.5], [0.75, 0.625]]}, "does not run along mesh edges"),
    ({"defect": [[0.0, 0.5], [0.5, 0.5]]}, "strictly inside"),
    ({"defect": [[0.5, 0.5], [0.5, 0.5]]}, "zero length"),
    ({"delta": 0}, "delta"), ({"delta": float("nan")}, "delta"), ({"E": -1}, "E"),
    ({"nu": 0.5}, "nu"), ({"nu": -1}, "nu"), ({"plane": "axi"}, "plane"), ({"load": "f9"}, "load"),
    ({"load": "__import__('os')"}, "load"), ({"N": 3.5}, "N"),
])
def test_bad_scene_parameters(params, words):
    with pytest.raises(InputError, match=words):
        load_scene("f2", params).build()


def test_delta_free_assembly_is_reused_only_when_only_delta_changes():
    """with_params for a new delta or load reuses the instance's mesh and K_el (read-only) and gives the same
    QP as a fresh build; any other key, or another instance, assembles afresh."""
    import numpy as np

    from dualfem.core.scene import load_scene

    first = load_scene("f2", {"N": 12, "delta": 1e-5})
    a = first.build()
    second = first.with_params(delta=1e-3)
    b = second.build()
    assert np.shares_memory(b.K_fixed.data, a.K_fixed.data) and second.shared is first.shared   # reused
    assert first.shared.assemblies == 1
    fresh = load_scene("f2", {"N": 12, "delta": 1e-3}).build()      # another instance: its own assembly
    assert not np.shares_memory(fresh.K_fixed.data, a.K_fixed.data)
    for M in ("K", "K_fixed", "B"):
        assert abs(getattr(b, M) - getattr(fresh, M)).max() == 0.0
    assert np.array_equal(b.F, fresh.F) and np.array_equal(b.geometry.node_dofs, fresh.geometry.node_dofs)
    with pytest.raises(ValueError):
        b.K_fixed.data[0] = 1.0                                     # shared, so read-only
    b.F[0] = 1.0                                                    # F is each QP's own
    assert first.with_params(delta=1e-7).build().F[0] == fresh.F[0]
    f1 = first.with_params(load="f1").build()                       # another load: same K_el, its own F
    assert np.shares_memory(f1.K_fixed.data, a.K_fixed.data)
    assert np.array_equal(f1.F, load_scene("f1", {"N": 12}).build().F) and first.shared.assemblies == 1
    other_problem = first.with_params(E=1000.0)
    other = other_problem.build()
    assert other_problem.shared is not first.shared                 # anything else: a new assembly
    assert not np.shares_memory(other.K_fixed.data, a.K_fixed.data)


@pytest.mark.parametrize("scene_name", ["f2", "f1", "f3"])
def test_planned_stiffness_sum_equals_scipys_sum_bit_for_bit(scene_name):
    """From the second delta on a mesh, K = K_el + interface term comes from a plan (a copy of the
    values and 8 m additions): the same pattern and the same bits as scipy's sum, for every delta."""
    import numpy as np

    from dualfem.core.scene import load_scene
    from dualfem.problems.thin_defect.assemble import interface

    first = load_scene(scene_name, {"N": 12, "delta": 1e-1})
    for delta in (1e-1, 1e-5, 3e-9, 1e-5):
        sc = first.with_params(delta=delta)
        qp = sc.build()
        a = sc.shared.data["delta_free"]
        c, maps = a["cut"], a["maps"]
        coef = c.weights / np.array([d["delta"] for d in sc._defects])[c.defect_id]
        K_par, B_ref, _ = interface(maps["node_dofs"], c.lower, c.upper, a["interface"].normals.T, coef, a["n"])
        ref = (a["K_el"] + K_par).tocsc()
        assert qp.K.format == "csc" and qp.K.has_canonical_format
        assert np.array_equal(qp.K.indptr, ref.indptr) and np.array_equal(qp.K.indices, ref.indices)
        assert np.array_equal(qp.K.data, ref.data)
        assert abs(qp.B - B_ref).max() == 0.0
        assert "B" not in a or not np.shares_memory(qp.B.data, a["B"].data)      # each QP's own B
    assert a["interface_sum"]                                         # planned (builds 2, 3, 4 used it)
    qp.K.data[0] += 1.0                                               # each QP's values are its own
    assert first.with_params(delta=1e-5).build().K.data[0] == ref.data[0]


def test_planned_stiffness_sum_falls_back_on_an_exact_cancellation():
    """A coefficient that cancels a stiffness entry exactly: scipy drops the entry, and so does the plan
    (it hands the sum back to scipy)."""
    import numpy as np

    from dualfem.core.scene import load_scene
    from dualfem.problems.thin_defect import ThinDefect
    from dualfem.problems.thin_defect.assemble import interface

    problem = load_scene("f2", {"N": 12, "delta": 1e-1})
    problem.build()
    problem.with_params(delta=1e-2).build()
    a = problem.shared.data["delta_free"]
    plan, c, maps = a["interface_sum"], a["cut"], a["maps"]
    coef = np.ones(c.lower.size)
    j = 0                          # coefficient of node j chosen to cancel K_el's (up, up) entry
    up = maps["node_dofs"][0, c.upper[j]]
    coef[j] = -a["K_el"][up, up]
    K, _, _ = ThinDefect._stiffness(a, coef)
    ref = (a["K_el"] + interface(maps["node_dofs"], c.lower, c.upper, a["interface"].normals.T, coef,
                                 a["n"])[0]).tocsc()
    assert plan and K.nnz == ref.nnz and abs(K - ref).max() == 0.0 and K[up, up] == 0.0


def _random_mesh(seed: int, npts: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A Delaunay mesh of random points in the unit square (corners included), triangles in random order."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    p = np.vstack([[0, 0], [1, 0], [1, 1], [0, 1], rng.random((npts, 2))]).T
    t = Delaunay(p.T).simplices.T.astype(np.int32)
    return p, t[:, rng.permutation(t.shape[1])]


def _reference_stiffness(p, t, lam, mu, node_dofs, n):
    """The textbook assembly: one dense 6 x 6 element matrix per triangle (B' D B area), scattered with
    scipy's COO -> CSC (duplicates summed)."""
    import scipy.sparse as sp

    D = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    rows, cols, vals = [], [], []
    for tri in t.T:
        x, y = p[0, tri], p[1, tri]
        twoA = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
        bx = np.array([y[1] - y[2], y[2] - y[0], y[0] - y[1]]) / twoA
        by = np.array([x[2] - x[1], x[0] - x[2], x[1] - x[0]]) / twoA
        Bm = np.zeros((3, 6))                        # local unknown 2 a + c
        Bm[0, 0::2], Bm[1, 1::2], Bm[2, 0::2], Bm[2, 1::2] = bx, by, by, bx
        Ke = Bm.T @ D @ Bm * abs(twoA) / 2
        dofs = np.array([node_dofs[c, a] for a in tri for c in range(2)])
        for i in range(6):
            for j in range(6):
                if dofs[i] >= 0 and dofs[j] >= 0:
                    rows.append(dofs[i])
                    cols.append(dofs[j])
                    vals.append(Ke[i, j])
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, n))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("clamp", ["none", "nodes", "one_component", "other_numbering"])
def test_stiffness_equals_the_textbook_assembly(seed, clamp):
    """The direct compressed assembly (node pairs sorted once, bincount, 2 x 2 blocks) gives the matrix of
    the element-by-element assembly to rounding, in canonical form with the same pattern."""
    from dualfem.problems.thin_defect.assemble import free_dofs, stiffness

    p, t = _random_mesh(seed)
    nn = p.shape[1]
    bottom = np.flatnonzero(p[1] == 0)
    if clamp == "none":
        nd = np.arange(2 * nn).reshape(nn, 2).T
    elif clamp == "nodes":
        nd = free_dofs(bottom, nn)
    else:
        free = np.ones((nn, 2), bool)
        free[bottom, 1] = False                     # rollers: only the vertical component clamped
        free[3, :] = False                          # and one whole node
        nd = np.where(free, np.cumsum(free.ravel()).reshape(nn, 2) - 1, -1).T.copy()
        if clamp == "other_numbering":             # components numbered block-wise: scipy's path
            k = int(free.sum())
            order = np.concatenate([np.flatnonzero(free[:, 0]), nn + np.flatnonzero(free[:, 1])])
            nd = np.full(2 * nn, -1)
            nd[order] = np.arange(k)
            nd = nd.reshape(2, nn)
    n = int(nd.max()) + 1
    lam, mu = 1.2e5, 7.7e4
    K = stiffness(p, t, lam, mu, nd, n)
    ref = _reference_stiffness(p, t, lam, mu, nd, n)
    assert K.format == "csc" and K.shape == (n, n) and K.has_canonical_format
    srt = K.copy()
    srt.has_sorted_indices = srt.has_canonical_format = False
    srt.sum_duplicates()                                      # really canonical: nothing to merge or sort
    assert np.array_equal(srt.indices, K.indices) and np.array_equal(srt.indptr, K.indptr)
    assert np.array_equal(K.indptr, ref.indptr) and np.array_equal(K.indices, ref.indices)
    assert np.abs(K - ref).max() <= 1e-12 * np.abs(ref).max()


def test_stiffness_equals_scikit_fem():
    """The same bilinear form as scikit-fem's linear elasticity on the doubled structured mesh."""
    skfem = pytest.importorskip("skfem")
    from skfem.models.elasticity import linear_elasticity

    problem = load_scene("f2", {"N": 8, "nu": 0.3})
    K_all, _, basis = problem.assemble()
    lam, mu = lame(problem.params["E"], problem.params["nu"], problem.params["plane"])
    ref = skfem.asm(linear_elasticity(lam, mu), basis)
    assert abs(K_all - ref).max() <= 1e-12 * abs(ref).max()
