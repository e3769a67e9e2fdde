"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.runner`."""
from dualfem.core.runner import *  # noqa: F401,F403
