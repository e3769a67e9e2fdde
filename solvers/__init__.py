"""Solver plugins of dualfem: every module here not starting with ``_`` is imported and its
``@register_solver`` classes registered.

One module per backend, named with a trailing underscore where it wraps a library of the same
name (``osqp_``, ``clarabel_``, ``cvxpy_``) so that ``import osqp`` is never shadowed.
"""
