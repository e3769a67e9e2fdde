"""Numerical building blocks: sparse factorization backends, threads and memory estimates."""
