"""The ``dualfem`` command line: one module per command group; :func:`main` is the entry point."""
from dualfem.cli.main import main

__all__ = ["main"]
