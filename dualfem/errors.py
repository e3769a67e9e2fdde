"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.errors`."""
from dualfem.core.errors import (
    DISTRIBUTIONS,
    InputError,
    MissingDependency,
    OutputError,
    check_int,
    check_open_interval,
    check_positive,
    describe_exception,
    install_hint,
    missing_module,
)

__all__ = [
    "DISTRIBUTIONS", "InputError", "MissingDependency", "OutputError", "check_int", "check_open_interval",
    "check_positive", "describe_exception", "install_hint", "missing_module",
]
