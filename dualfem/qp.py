"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.qp`
and :mod:`dualfem.core.parts` (the typed optional parts of a QP)."""
from dualfem._facade import moved
from dualfem.core.parts import GeometryPart, InterfacePart, LocalPart, MaterialPart, ShiftPart, UnitsPart
from dualfem.core.qp import PROMOTED_MAPS, QP, Maps

__all__ = [
    "GeometryPart", "InterfacePart", "LocalPart", "Maps", "MaterialPart", "PROMOTED_MAPS", "QP", "ShiftPart",
    "UnitsPart",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors", "atomic_write": "dualfem.core.io", "check_maps": "dualfem.core.qpfile",
    "check_params": "dualfem.core.qpfile", "coo_from_arrays": "dualfem.core.qpfile", "export_matrix":
    "dualfem.core.qpfile", "read_arrays": "dualfem.core.qpfile",
})
