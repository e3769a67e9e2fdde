"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.evaluator`."""
from dualfem.core.evaluator import *  # noqa: F401,F403
