"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.qp`
and :mod:`dualfem.core.parts` (the typed optional parts of a QP)."""
from dualfem.core.parts import GeometryPart, InterfacePart, LocalPart, MaterialPart, ShiftPart, UnitsPart  # noqa: F401
from dualfem.core.qp import *  # noqa: F401,F403
