"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.registry`."""
from dualfem.core.registry import *  # noqa: F401,F403
