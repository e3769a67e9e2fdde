"""The friction scene keys (problems/_friction_keys.py) on thin_defect, fractured and three_d: the blocks they
build (law, rows, thresholds per node), per-defect tables over the top level, one-line refusals, units."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.laws import Coulomb, Tresca
from dualfem.scene import load_scene

pytest.importorskip("gmsh")

TWO = [{"points": [[0.25, 0.25], [0.5, 0.25]]}, {"points": [[0.25, 0.75], [0.75, 0.75]]}]


def _qp(name="f2", **keys):
    return load_scene(name, {"N": 16, **keys}).build()


def test_no_friction_adds_no_block_and_no_param():
    qp = _qp()
    assert qp.blocks == () and "friction" not in qp.params and "friction_bound" not in qp.params


def test_tresca_block_on_every_defect_node_with_the_expression_at_the_nodes():
    qp = _qp(friction="tresca", friction_bound="1 + x")
    (b,) = qp.blocks
    assert isinstance(b.law, Tresca) and b.m == qp.m and b.law.components == 1
    nodes = qp.geometry.nodes[:, qp.interface.lower]
    assert np.allclose(b.law.bound, 1 + nodes[0])
    assert qp.params["friction"] == "tresca(g=1 + x)"


def test_per_defect_tables_override_the_top_level():
    defects = [{**TWO[0], "friction": "coulomb", "friction_coefficient": 0.4}, {**TWO[1]}]
    qp = _qp(defects=defects, friction="tresca", friction_bound=2.0)
    tresca, coulomb = qp.blocks
    did = qp.interface.defect_id
    assert isinstance(tresca.law, Tresca) and isinstance(coulomb.law, Coulomb)
    assert tresca.m == np.sum(did == 1) and coulomb.m == np.sum(did == 0)
    assert np.array_equal(coulomb.law.normal_rows, np.flatnonzero(did == 0))
    assert np.allclose(coulomb.law.coefficient, 0.4) and np.allclose(tresca.law.bound, 2.0)
    # a defect may opt out of the top-level friction
    qp = _qp(defects=[{**TWO[0], "friction": "none"}, TWO[1]], friction="tresca", friction_bound=2.0)
    assert qp.blocks[0].m == np.sum(qp.interface.defect_id == 1)


@pytest.mark.parametrize("keys, match", [
    ({"friction": "stick"}, "friction must be one of"),
    ({"friction_bound": 1.0}, "friction_bound is Tresca's threshold"),
    ({"friction": "coulomb", "friction_bound": 1.0}, "friction_bound is Tresca's threshold"),
    ({"friction": "tresca", "friction_coefficient": 0.3, "friction_bound": 1.0}, "friction_coefficient is Coulomb"),
    ({"friction": "tresca"}, "needs friction_bound"),
    ({"friction": "coulomb"}, "needs friction_coefficient"),
    ({"friction": "tresca", "friction_bound": -1.0}, "friction_bound must be >= 0"),
    ({"friction": "tresca", "friction_bound": "x - 0.5"}, "must be finite and >= 0 at every node"),
    ({"friction": "tresca", "friction_bound": "log(x - 2)"}, "friction_bound"),
    ({"friction": "coulomb", "friction_coefficient": -0.1}, "friction_coefficient must be a finite number >= 0"),
    ({"friction": "coulomb", "friction_coefficient": True}, "friction_coefficient must be a finite number >= 0"),
    ({"defects": [{**TWO[0], "friction_bound": 1.0}, TWO[1]]}, r"defects\[0\].friction_bound is Tresca"),
    ({"defects": [{**TWO[0], "friction": "tresca"}, TWO[1]]}, r"defects\[0\].friction = 'tresca' needs"),
    ({"defects": [], "friction": "tresca", "friction_bound": 1.0}, "has no defect"),
])
def test_refusals_name_the_key(keys, match):
    with pytest.raises(InputError, match=match):
        _qp(**keys)


def test_fractured_takes_the_top_level_keys():
    qp = load_scene("fractured", {"cracks": 3, "mesh_size": 0.05, "tip_size": 0.05, "friction": "coulomb",
                                  "friction_coefficient": 0.3}).build()
    (b,) = qp.blocks
    assert isinstance(b.law, Coulomb) and b.m == qp.m and qp.params["friction"] == "coulomb(mu_f=0.3)"


def test_three_d_disc_rows_two_per_node():
    qp = load_scene("three_d", {"N": 4, "friction": "tresca", "friction_bound": 0.5}).build()
    (b,) = qp.blocks
    assert isinstance(b.law, Tresca) and b.law.components == 2 and b.m == 2 * qp.m
    with pytest.raises(InputError, match=r"defects\[0\]: unknown key 'friction_bond'"):
        load_scene("three_d", {"N": 4, "defects": [{"shape": "disk", "center": [0.5, 0.5, 0.5], "radius": 0.2,
                                                     "normal": [0, 0, 1], "friction_bond": 1.0}]}).build()


def test_units_scale_the_bound_as_a_stress():
    from dualfem.problems.thin_defect import ThinDefect

    umap = ThinDefect.unit_map
    out = umap.convert(ThinDefect.defaults, {"friction": "tresca", "friction_bound": 2.0}, 1e3, 1.0)
    assert out["friction_bound"] == 2e3
    out = umap.convert(ThinDefect.defaults, {"friction": "tresca", "friction_bound": "1 + x",
                                             "defects": [{**TWO[0], "friction_bound": 3.0}]}, 10.0, 2.0)
    assert out["defects"][0]["friction_bound"] == 30.0
    a = load_scene("f2", {"N": 16, "width": 2.0, "height": 2.0, "defect": [[0.5, 1.0], [1.5, 1.0]],
                          "friction": "tresca", "friction_bound": out["friction_bound"]}).build()
    b = _qp(friction="tresca", friction_bound="1 + x")
    assert np.allclose(a.blocks[0].law.bound, 10.0 * b.blocks[0].law.bound)


def test_signorini_plugin_friction_on_the_foundation():
    pytest.importorskip("clarabel")
    from dualfem.experiments.runner import run

    free = run("clarabel", load_scene("signorini_flat", {"N": 16}).build())
    zero = load_scene("signorini_flat", {"N": 16, "friction": "tresca", "friction_bound": 0.0}).build()
    stuck = load_scene("signorini_flat", {"N": 16, "friction": "tresca", "friction_bound": 1e4}).build()
    (b,) = stuck.blocks
    assert isinstance(b.law, Tresca) and b.m == stuck.m and np.array_equal(b.weights, stuck.weights)
    assert np.abs(run("clarabel", zero).x - free.x).max() < 1e-12 * np.abs(free.x).max()
    s = run("clarabel", stuck)
    assert s.status == "solved" and np.abs(b.G @ s.x).max() < 1e-14 * np.abs(s.x).max()     # no slip at all
    assert np.abs(b.G @ free.x).max() > 1e-3 * np.abs(free.x).max()                         # it slid without
    with pytest.raises(InputError, match="friction_coefficient is Coulomb"):
        load_scene("signorini", {"friction_coefficient": 0.2}).build()
