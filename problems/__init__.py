"""Problem plugins of dualfem: every module here not starting with ``_`` is registered."""
