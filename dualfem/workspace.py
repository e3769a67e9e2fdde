"""Stable import path of the workspace (``from dualfem.workspace import Workspace``); the code lives in
:mod:`dualfem.experiments.workspace`."""
from dualfem.experiments.workspace import Workspace

__all__ = ["Workspace"]
