"""Numerical kernels: orderings, factorizations, the exact reduction onto the defect unknowns, scaling."""
