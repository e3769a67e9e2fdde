"""The typed defect interface (:class:`dualfem.core.parts.InterfacePart`): one (m, dim) convention in 2D
and 3D, its jump operator, its validation, the old ``maps`` keys and the exported files."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.parts import InterfacePart
from dualfem.core.qp import QP
from dualfem.core.scene import load_scene

FIELDS = ("upper", "lower", "plus_dofs", "minus_dofs", "normals", "tangents", "weights", "defect_id", "front",
          "front_id", "faces", "s", "delta")


@pytest.fixture(scope="module", params=[("two_defects", {"N": 12}), ("penny", {"mesh_size": 2.0, "tip_size": 1.5})])
def qp(request):
    name, params = request.param
    return load_scene(name, params).build()


def test_every_per_node_array_has_one_row_per_pair_in_2d_and_3d(qp):
    it, m, d = qp.interface, qp.m, qp.geometry.dim
    assert it.dim == d and it.m == m and m > 0
    assert it.normals.shape == (m, d) and it.tangents.shape == (m, d - 1, d)
    assert it.plus_dofs.shape == it.minus_dofs.shape == (m, d)
    assert np.array_equal(it.plus_dofs, qp.geometry.node_dofs[:, it.upper].T)
    assert it.weights is qp.weights or np.array_equal(it.weights, qp.weights)
    assert it.delta.shape == (m,) and np.all(it.delta > 0)
    assert (it.s is not None) == (d == 2) and (it.faces is not None) == (d == 3)
    assert it.front.shape == it.front_id.shape and set(np.unique(it.front_id)) == set(np.unique(it.defect_id))


def test_the_jump_operator_gives_b_and_the_tangential_jumps(qp):
    it = qp.interface
    J = it.jump_operator(qp.n)
    assert J.shape == (qp.geometry.dim * qp.m, qp.n)
    assert abs(J[:qp.m] - qp.B).max() < 1e-15                     # the normal block is B
    x = np.random.default_rng(0).standard_normal(qp.n)
    normal, tangential = it.jumps(x)
    np.testing.assert_allclose(normal, qp.B @ x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(tangential, (J[qp.m:] @ x).reshape(-1, qp.m).T, rtol=0, atol=1e-13)
    jump = x[it.plus_dofs] - x[it.minus_dofs]                    # the frame is orthonormal: |[u]|^2 is kept
    np.testing.assert_allclose(normal ** 2 + (tangential ** 2).sum(axis=1), (jump ** 2).sum(axis=1), rtol=1e-12)


def test_the_old_maps_keys_answer_in_their_old_layout_with_a_warning(qp):
    it = qp.interface
    with pytest.warns(DeprecationWarning, match=r"qp.interface.normals"):
        old = qp.maps["defect_normals"]
    assert np.array_equal(old, it.normals.T if it.dim == 2 else it.normals)     # 2D: (2, m), 3D: (m, 3)
    key = "defect_tips" if it.dim == 2 else "defect_front"
    with pytest.warns(DeprecationWarning, match=r"qp.interface.front"):
        assert np.array_equal(qp.maps.get(key), it.front)
    assert "defect_upper" in qp.maps and "defect_upper" not in list(qp.maps)


def test_an_exported_file_gives_the_same_part_and_an_older_one_too(qp, tmp_path):
    for suffix in (".mat", ".npz"):
        qp.save(tmp_path / f"q{suffix}")
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            back = QP.load(tmp_path / f"q{suffix}").interface
        for f in FIELDS:
            a, b = getattr(qp.interface, f), getattr(back, f)
            assert (a is None and b is None) or np.array_equal(a, b), (suffix, f)
    d = dict(np.load(tmp_path / "q.npz"))
    del d["map_defect_delta"]                                   # a file of the last release: no per-node delta
    if qp.geometry.dim == 2:
        del d["map_defect_tangents"]                            # nor tangents
    np.savez(tmp_path / "old.npz", **d)
    old = QP.load(tmp_path / "old.npz").interface
    assert old.delta is None
    for f in FIELDS[:-1]:
        a, b = getattr(qp.interface, f), getattr(old, f)
        assert (a is None and b is None) or np.allclose(a, b, rtol=0, atol=1e-12), f


def test_a_plugin_handing_old_maps_gets_the_part_with_a_warning(qp):
    legacy = qp.maps.legacy()
    with pytest.warns(DeprecationWarning, match="interface=InterfacePart"):
        q = QP(K=qp.K, F=qp.F, B=qp.B, weights=qp.weights, geometry=qp.geometry, maps=legacy)
    assert np.array_equal(q.interface.normals, qp.interface.normals)


def _with(qp, **changes):
    it = qp.interface
    fields = {f: getattr(it, f) for f in ("dim", *FIELDS)} | changes
    return QP(K=qp.K, F=qp.F, B=qp.B, weights=qp.weights, geometry=qp.geometry, interface=InterfacePart(**fields))


def test_a_wrong_part_is_refused_naming_the_field(qp):
    it = qp.interface
    with pytest.raises(InputError, match=r"interface.normals must have shape"):
        _with(qp, normals=it.normals.T.copy() if it.dim == 3 else it.normals[:-1])
    with pytest.raises(InputError, match=r"orthonormal frame"):
        _with(qp, normals=2 * it.normals)
    with pytest.raises(InputError, match=r"interface.plus_dofs"):
        _with(qp, plus_dofs=it.minus_dofs)
    with pytest.raises(InputError, match=r"interface.weights must equal"):
        _with(qp, weights=2 * it.weights)
    with pytest.raises(InputError, match=r"interface.delta must be > 0"):
        _with(qp, delta=-it.delta)


def test_a_plugin_gets_the_part_read_only(qp, tmp_path):
    from dualfem.experiments.runner import guarded_view

    qp.save(tmp_path / "q.npz")
    mine = QP.load(tmp_path / "q.npz")                           # its arrays are writable
    assert mine.interface.normals.flags.writeable
    it = guarded_view(mine).interface
    for f in FIELDS:
        a = getattr(it, f)
        assert a is None or not a.flags.writeable, f
    with pytest.raises(ValueError, match="read-only"):
        it.normals[0] = 0


def test_old_maps_that_do_not_fit_the_qp_stay_plain_extras(qp):
    """Another QP's maps (other rows of B) make no interface part: they stay unread extras, as before."""
    import scipy.sparse as sp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        q = QP(K=qp.K, F=qp.F, B=sp.eye(qp.n, format="csr"), maps=qp.maps)
    assert q.interface is None and q.geometry is not None and "defect_upper" in list(q.maps)
