"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.problem`."""
from dualfem.core.problem import *  # noqa: F401,F403
