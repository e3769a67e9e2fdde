"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.evaluator`."""
from dualfem._facade import moved
from dualfem.core.evaluator import (
    CONTACT_RTOL,
    EPS,
    RESIDUALS,
    ROUNDING_C,
    TINY,
    abs_product,
    active_set_solution,
    certify,
    compare,
    contact_set,
    energy_norm,
    force_scale,
    kkt_error,
    kkt_residuals,
    load_energy,
    load_length,
    residuals,
    size_energy,
    size_max,
    user_frame,
)

__all__ = [
    "CONTACT_RTOL", "EPS", "RESIDUALS", "ROUNDING_C", "TINY", "abs_product", "active_set_solution", "certify",
    "compare", "contact_set", "energy_norm", "force_scale", "kkt_error", "kkt_residuals", "load_energy",
    "load_length", "residuals", "size_energy", "size_max", "user_frame",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "QP": "dualfem.qp",
})
