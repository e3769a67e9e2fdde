"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.solver`."""
from dualfem.core.solver import *  # noqa: F401,F403
