"""membrane: a membrane stretched over a flat rigid floor (a problem plugin template for dualfem).

Copy this file to ``problems/membrane.py`` of a dualfem checkout (in-tree plugin) or into your
own package with an entry point in the group ``dualfem.problems``; rename the class, ``name``
and the presets. See docs/plugins.md.

Model (the classical 2D obstacle problem): a membrane with tension T over the unit square, its
edge held at height ``lift`` above a flat floor, pressed down by a uniform load q (force per
area). Unknown: the height y >= 0 of every interior P1 node above the floor. Energy
``1/2 y'Ky - F'y`` with ``K = T * stiffness`` and ``F = -q * (integral of each hat function)``
minus the lifting term of the boundary values; constraint ``y >= 0``, so ``B = I`` and
``B y`` is the gap to the floor. Multipliers are the nodal floor reactions (force), the
contact pressure is ``mu / weights`` with ``weights = integral of each hat function``.
Without the floor the sag in the middle is ``0.0737 q / T`` (Poisson on the unit square), so the
membrane touches the floor iff ``0.0737 q / T > lift``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.errors import check_int, check_positive
from dualfem.problem import Problem
from dualfem.qp import QP, GeometryPart
from dualfem.registry import register_problem


@register_problem
class MembraneOverFloor(Problem):
    name = "membrane"
    description = "membrane over a flat rigid floor, 2D obstacle problem (template from docs/plugins.md)"
    defaults = {"N": 16, "tension": 1.0, "q": 1.0, "lift": 0.05}
    presets = {"membrane": {}, "membrane_heavy": {"q": 4.0}}

    def validate(self) -> None:
        # scene parameters arrive as strings from --set; check and convert them, naming the range
        p = self.params
        p["N"] = check_int("N", p["N"], 2, 2048)
        p["tension"] = check_positive("tension", p["tension"])
        p["q"] = check_positive("q", p["q"], allow_zero=True)
        p["lift"] = check_positive("lift", p["lift"], allow_zero=True)

    def build(self) -> QP:
        from skfem import Basis, ElementTriP1, MeshTri, asm
        from skfem.models.poisson import laplace, unit_load

        p = self.params
        grid = np.linspace(0.0, 1.0, p["N"] + 1)
        mesh = MeshTri.init_tensor(grid, grid)
        basis = Basis(mesh, ElementTriP1())
        A = p["tension"] * asm(laplace, basis)
        hat = asm(unit_load, basis)                       # integral of each hat function
        edge = basis.get_dofs().all()                     # boundary nodes: height = lift
        free = np.setdiff1d(np.arange(basis.N), edge)
        K = A[free][:, free].tocsc()
        F = -p["q"] * hat[free] - A[free][:, edge] @ np.full(edge.size, p["lift"])
        node_dofs = np.full((1, basis.N), -1)
        node_dofs[0, free] = np.arange(free.size)
        return QP(K=K, F=F, B=sp.identity(free.size, format="csr"), weights=hat[free],
                  name=f"membrane[q={p['q']:g}]", params=dict(p),
                  geometry=GeometryPart.make(mesh.p, mesh.t, node_dofs))
