"""Experiments: the workspace (setup / update / solve), compare, bench and stress sweeps, the harness they share."""
