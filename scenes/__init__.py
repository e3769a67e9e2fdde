"""The scene library: small TOML scenes (``dualfem solve NAME``; ``dualfem list`` shows them)."""
