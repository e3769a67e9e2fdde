"""Experiments: compare, bench and stress sweeps, and the harness they share."""
