"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.qp`."""
from dualfem.core.qp import *  # noqa: F401,F403
