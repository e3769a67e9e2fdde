"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.scene`."""
from dualfem.core.scene import *  # noqa: F401,F403
