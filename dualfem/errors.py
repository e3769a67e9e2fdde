"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.errors`."""
from dualfem.core.errors import *  # noqa: F401,F403
