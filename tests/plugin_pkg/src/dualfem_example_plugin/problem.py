"""``example_string``: a taut string over a flat rigid floor (the 1D obstacle problem).

A string of length 1 and tension T, fixed at both ends at height ``lift`` above a floor at height
0, loaded by a downward line load ``q``. Unknowns: heights ``y_i`` of the
N - 1 interior nodes (finite differences = P1 finite elements). Energy
``1/2 y'Ky - F'y`` with ``K = T/h tridiag(-1, 2, -1)``, ``F = -q h + (T/h) lift e_end``;
constraint ``y >= 0`` (B = I). Without the floor the sag is ``q x(1-x)/(2T)``, so the string
touches the floor iff ``q / (8 T) > lift``. Multipliers = nodal floor reactions; equilibrium:
sum(mu) + end reactions = q.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.errors import check_int, check_positive
from dualfem.problem import Problem
from dualfem.qp import QP


class StringOverFloor(Problem):
    name = "example_string"
    description = "taut string over a rigid floor, 1D obstacle problem (third-party example)"
    defaults = {"N": 64, "tension": 1.0, "q": 1.0, "lift": 0.05}
    presets = {"string": {}}

    def validate(self) -> None:
        p = self.params
        p["N"] = check_int("N", p["N"], 2, 10**6)
        p["tension"] = check_positive("tension", p["tension"])
        p["q"] = check_positive("q", p["q"], allow_zero=True)
        p["lift"] = check_positive("lift", p["lift"], allow_zero=True)

    def build(self) -> QP:
        p = self.params
        N, T = p["N"], p["tension"]
        h = 1.0 / N
        n = N - 1
        K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]) * (T / h)
        F = np.full(n, -p["q"] * h)
        F[0] += T / h * p["lift"]
        F[-1] += T / h * p["lift"]
        # solve for the height above the floor directly: y >= 0
        return QP(K=K.tocsc(), F=F, B=sp.identity(n, format="csr"), weights=np.full(n, h),
                  name="example_string", params=dict(p),
                  maps={"x": np.linspace(h, 1 - h, n)})
