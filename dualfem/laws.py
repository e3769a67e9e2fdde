"""Stable import path of the constraint-law API (docs/plugins.md, section 1.7); the code lives in
:mod:`dualfem.core.laws` (the laws) and :mod:`dualfem.core.constraints` (the blocks ``(G, weights, law)``)."""
from dualfem.core.constraints import Constraint, call_law, conic_rows, upper_bounds
from dualfem.core.laws import CONES, SIGNORINI, Coulomb, Friction, Law, Signorini, Tresca

__all__ = ["CONES", "SIGNORINI", "Constraint", "Coulomb", "Friction", "Law", "Signorini", "Tresca", "call_law",
           "conic_rows", "upper_bounds"]
