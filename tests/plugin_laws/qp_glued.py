"""A QP that uses the toy law: scene f2 with every other defect node glued (bilateral), the rest Signorini."""
from __future__ import annotations

import numpy as np
from law_bilateral import Bilateral

from dualfem.laws import Constraint
from dualfem.qp import QP
from dualfem.scene import load_scene


def glued_qp(N: int = 16, every: int = 2, signorini: bool = True) -> QP:
    """f2 at ``N`` with the defect rows ``every``-th from row 1 glued (all of them with ``signorini=False``)."""
    base = load_scene("f2", {"N": N}).build()
    rows = np.arange(base.m)
    glued = rows % every == 1 if signorini else np.ones(base.m, bool)
    return QP(K=base.K, F=base.F, B=base.B[~glued], weights=base.weights[~glued],
              K_fixed=base.local.K_fixed, local_dofs=base.local.dofs, name=f"f2_glued_{N}",
              blocks=(Constraint.make(base.B[glued], base.weights[glued], Bilateral()),))
