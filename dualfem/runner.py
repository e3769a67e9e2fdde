"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.experiments.runner`."""
from dualfem.experiments.runner import *  # noqa: F401,F403
