"""Example third-party plugins for dualfem (registered through entry points, see pyproject.toml)."""
