"""The QP's typed parts (dualfem.core.parts): validated at construction, read by the algorithms instead
of ``params``/``maps``, exported as the documented ``map_*`` arrays, and the old ``maps`` keys still
answered for one release with a DeprecationWarning."""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.errors import InputError
from dualfem.qp import QP, GeometryPart, LocalPart, MaterialPart, ShiftPart, UnitsPart
from dualfem.scene import load_scene


@pytest.fixture(scope="module")
def qp():
    return load_scene("f2", {"N": 8}).build()


def _tiny(**parts) -> QP:
    K = sp.diags([2.0, 3.0, 4.0]).tocsc()
    return QP(K=K, F=np.ones(3), B=sp.csr_matrix(np.array([[1.0, -1.0, 0.0]])), **parts)


def test_a_scene_provides_every_part(qp):
    g = qp.geometry
    assert g.dim == 2 and g.nodes.shape[0] == 2 and g.cells.shape[0] == 3
    assert g.node_dofs.shape == (2, g.nodes.shape[1]) and g.node_dofs.max() == qp.n - 1
    assert qp.units == UnitsPart(E=69000.0, length=1.0)
    assert qp.material == MaterialPart(69000.0, 0.3, "strain")
    assert qp.shift is None
    assert qp.local.K_fixed is qp.K_fixed and np.array_equal(qp.local.dofs, qp.local_dofs)
    assert set(np.unique(qp.B.indices)) <= set(qp.local.dofs.tolist())


@pytest.mark.parametrize("parts, match", [
    ({"geometry": GeometryPart(2, np.zeros((3, 4)), np.zeros((3, 1), int), np.zeros((2, 4), int))}, "geometry.nodes"),
    ({"geometry": GeometryPart(2, np.zeros((2, 4)), np.array([[0], [1], [9]]), np.full((2, 4), -1))}, "geometry.cells"),
    ({"geometry": GeometryPart(2, np.zeros((2, 2)), np.zeros((3, 0), int), np.array([[0, 1], [1, 2]]))},
     "one unknown for two"),
    ({"geometry": GeometryPart(2, np.zeros((2, 2)), np.zeros((3, 0), int), np.array([[0, 1], [2, 7]]))},
     "geometry.node_dofs"),
    ({"geometry": GeometryPart(4, np.zeros((4, 2)), np.zeros((5, 0), int), np.full((4, 2), -1))}, "geometry.dim"),
    ({"shift": ShiftPart(np.zeros(2))}, "shift.x"),
    ({"shift": ShiftPart(np.array([0.0, np.nan, 0.0]))}, "shift.x"),
    ({"units": UnitsPart(E=-1.0, length=1.0)}, "units.E"),
    ({"units": UnitsPart(E=1.0, length=float("inf"))}, "units.length"),
    ({"material": MaterialPart(1.0, 0.5)}, "material.nu"),
    ({"local": LocalPart.make(sp.eye(3), [2])}, "outside local.dofs"),
    ({"local": LocalPart.make(sp.eye(4), [0, 1])}, "local.K_fixed"),
    ({"local": LocalPart.make(sp.eye(3), [0, 1, 5])}, "local.dofs"),
])
def test_a_wrong_part_is_refused_at_construction(parts, match):
    with pytest.raises(InputError, match=match):
        _tiny(**parts)


def test_old_maps_keys_are_answered_with_a_deprecation_warning(qp):
    with pytest.warns(DeprecationWarning, match=r"qp.geometry.node_dofs"):
        nd = qp.maps["node_dofs"]
    assert nd is qp.geometry.node_dofs
    with pytest.warns(DeprecationWarning, match=r"qp.geometry.cells"):
        assert qp.maps.get("triangles") is qp.geometry.cells
    assert "nodes" in qp.maps and "defect_upper" in qp.maps
    assert "nodes" not in list(qp.maps)            # stored once, in the part
    with pytest.warns(DeprecationWarning, match=r"qp.interface.upper"):
        assert qp.maps["defect_upper"] is qp.interface.upper
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        qp.maps["normal"]                          # a problem-specific extra: no warning


def test_old_style_construction_makes_the_parts_with_a_warning():
    with pytest.warns(DeprecationWarning, match="shift=ShiftPart"):
        q = _tiny(maps={"x_shift": np.array([1.0, 2.0, 3.0]), "objective_offset": np.array(4.0)})
    assert np.array_equal(q.shift.x, [1.0, 2.0, 3.0]) and q.shift.objective == 4.0
    with pytest.warns(DeprecationWarning, match="geometry=GeometryPart"):
        q = _tiny(maps={"nodes": np.zeros((2, 3)), "triangles": np.array([[0], [1], [2]]),
                        "node_dofs": np.array([[0, 1, 2]])})
    assert q.geometry.dim == 2 and q.geometry.node_dofs.shape == (1, 3)


def test_export_writes_the_documented_arrays_and_reads_back_the_parts(qp, tmp_path):
    d = qp.to_dict()
    for k in ("map_nodes", "map_triangles", "map_node_dofs", "map_defect_upper", "param_E"):
        assert k in d
    back = QP.load(qp.save(tmp_path / "f2.npz"))
    assert np.array_equal(back.geometry.cells, qp.geometry.cells)
    assert np.array_equal(back.geometry.node_dofs, qp.geometry.node_dofs)
    assert back.material == qp.material
    assert back.units is None                      # a file carries no scale the solvers would trust


def test_parameters_are_provenance_only(qp):
    """uzawa's scaled r reads qp.units: editing the write-only params changes nothing."""
    from dualfem.solvers.uzawa import paper_r_in_scene_units

    forged = dataclasses.replace(qp, params={**qp.params, "E": 1.0, "width": 1e6})
    assert paper_r_in_scene_units(1e7, forged.units) == paper_r_in_scene_units(1e7, qp.units)
    assert paper_r_in_scene_units(1e7, qp.units)[0] == pytest.approx(1e7)
    assert paper_r_in_scene_units(1e7, UnitsPart(E=69.0, length=1e3))[0] == pytest.approx(1e7 * 1e-3 * 1e-3)
    assert paper_r_in_scene_units(1e7, None) == (1e7, "as given (the QP has no units: E and width)")


def test_a_shift_is_undone_for_the_user(tmp_path):
    from dualfem.evaluator import size_max

    q = _tiny(shift=ShiftPart.make([5.0, 5.0, 5.0], 2.5))
    # x = 0 of a shifted QP still has a size: the load's length F'F / F'KF |F|_inf = 1/3 (issue 26: the
    # size is never taken from the shift, which the input controls; a larger shift does not grow it)
    assert size_max(q, np.zeros(3)) == pytest.approx(1.0 / 3.0)
    assert size_max(_tiny(shift=ShiftPart.make([5e6, 5e6, 5e6], 2.5)), np.zeros(3)) == pytest.approx(1.0 / 3.0)
