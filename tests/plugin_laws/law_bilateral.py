"""A toy constraint law as a plugin: bilateral (glued) rows, ``G x = 0`` with a free multiplier.

Everything the framework asks of a law (:class:`dualfem.core.laws.Law`), for glued crack faces: no
jump at all, the multiplier (force, either sign) holds the faces together. ``name = "bilateral"`` is
the word a solver lists in ``Solver.accepts``; ``conic() = "zero"`` is how a conic backend builds it.
"""
from __future__ import annotations

import numpy as np

from dualfem.laws import Law


class Bilateral(Law):
    """``G x = 0``, mu free: the dual set is all of R^m, every row is active, no complementarity."""

    name = "bilateral"

    def project(self, mu, weights=None, mus=()):
        return np.asarray(mu, float)

    def primal(self, gap):
        return float(np.abs(gap).max(initial=0.0))

    def dual(self, mu, weights=None, mus=()):
        return 0.0

    def complementarity(self, mu_s, gap_s, weights=None, fs=1.0, mus=()):
        return np.zeros_like(mu_s)      # an equality: its violation is the primal residual

    def support(self, mu, gap, weights=None, mus=()):
        return float(mu @ gap)          # 0 at a feasible gap (G x = 0)

    def energy(self, gap, weights=None):
        return 0.0                      # a constraint: no term of the objective

    def complementary(self, mu, gap, weights=None, mus=()):
        return np.asarray(mu, float)    # an equality row: any force is complementary

    def face(self, mu, gap, c):
        return np.ones(np.shape(mu), bool)

    def face_holds(self, mu1, gap1, face, mu_margin, gap_margin):
        return True                     # every row is on the face, mu free: the face's point is the solution

    def conic(self):
        return "zero"
