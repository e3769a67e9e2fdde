"""Friction against closed forms at small size (dualfem.experiments.friction, clarabel): a stuck crack is the
uncracked body to rounding; the 2D inclined closed crack slips by 4 (1 - nu^2) (|tau| - g) / E sqrt(a^2 - x^2)
(and by exactly (|tau| - g) / |tau| times its frictionless slip: the discrete friction force g w_j is the
consistent load of the traction g), sticks exactly when |tau| <= g; the 3D penny's slip error is within a point
of the frictionless one on the same mesh (Segedin)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.experiments import friction as fr

pytest.importorskip("gmsh")
pytest.importorskip("clarabel")


def test_a_stuck_crack_is_the_uncracked_body_to_rounding():
    out = fr.stuck_2d(N=16, bound=10.0)
    assert out["status"] == "solved"
    assert out["difference"] < 1e-12 and out["max_slip"] < 1e-14 and out["stick_nodes"] == out["m"]


@pytest.mark.parametrize("angle", [30.0, 60.0])
def test_inclined_crack_slips_by_the_closed_form(angle):
    g = 0.1
    sigma_n, tau = fr.resolved(angle)
    assert abs(tau) > g                                    # it slips
    t = fr.inclined_2d(angle, "tresca", g)
    free = fr.inclined_2d(angle, "none", 0.0)
    assert t["status"] == free["status"] == "solved"
    assert t["error"] < 0.10                               # 11 pairs: 7.6 % (30 deg), 8.0 % (60 deg)
    ratio = (abs(tau) - g) / abs(tau)
    assert np.allclose(t["slip"], ratio * np.asarray(free["slip"]), rtol=0, atol=1e-9 * free["max_slip"])
    assert t["closure"] < 1e-10                            # closed: compression holds the faces together


def test_inclined_crack_sticks_exactly_below_the_threshold():
    sigma_n, tau = fr.resolved(20.0)
    assert abs(tau) < 0.5
    out = fr.inclined_2d(20.0, "tresca", 0.5)
    assert out["status"] == "solved" and "error" not in out
    assert out["max_slip"] <= 1e-14 * out["scale"]


@pytest.mark.slow
def test_penny_slip_within_a_point_of_the_frictionless_error():
    t = fr.penny_3d("tresca", 0.2, mesh_size=3.0, tip_size=0.5)
    free = fr.penny_3d("none", 0.0, mesh_size=3.0, tip_size=0.5)
    assert t["status"] == free["status"] == "solved"
    assert abs(t["error"] - free["error"]) < 0.01
    ratio = (fr.TAU - 0.2) / fr.TAU
    assert np.abs(np.asarray(t["slip"]) - ratio * np.asarray(free["slip"])).max() < 2e-3 * free["max_slip"]
