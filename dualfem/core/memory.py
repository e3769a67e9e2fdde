"""Refuse, before assembly, a scene whose solve cannot fit in this machine's memory.

The model is peak resident memory ~ ``BYTES_PER_UNKNOWN * n * (1 + log2(n / 1e6) / 8)`` for n
unknowns (assembly, one sparse factorization with nested-dissection fill ~ n log n, the dense
Schur block on the defect unknowns), calibrated on measured runs of ``dualfem solve f2 --solver
pdas`` on this 2-core, 23 GB machine (SuperLU path: 13.4 GB at N = 1024, 2.1 M unknowns; see
reports/benchmark.md). It is deliberately conservative; ``--max-memory`` overrides the limit.
"""
from __future__ import annotations

import math

from dualfem.core.errors import InputError

#: measured peak bytes per unknown at 2.1 M unknowns (13.4 GB / 2.1 M)
BYTES_PER_UNKNOWN = 6.4e3


def estimate_peak_bytes(n: int) -> float:
    """Predicted peak memory (bytes) of assembling and solving a QP with ``n`` unknowns."""
    n = max(int(n), 1)
    return BYTES_PER_UNKNOWN * n * max(1.0 + math.log2(n / 2.1e6) / 8.0, 0.5)


def available_bytes() -> float:
    """MemAvailable of this machine in bytes (Linux /proc/meminfo; inf elsewhere)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024.0
    except (OSError, ValueError):
        pass
    return float("inf")


def check_fits(problem, max_bytes: float | None = None) -> None:
    """InputError naming the size, the estimate and the available memory when the scene cannot fit."""
    est = problem.size_estimate() if hasattr(problem, "size_estimate") else None
    if est is None:
        return
    n, label = est
    need = estimate_peak_bytes(n)
    have = available_bytes() if max_bytes is None else max_bytes
    if need > have:
        raise InputError(f"{label} ({n / 1e6:.1f} M unknowns) needs about {need / 1e9:.0f} GB of memory (estimate), "
                         f"{'allowed' if max_bytes is not None else 'available'}: {have / 1e9:.1f} GB; use a smaller "
                         f"size, or --max-memory GB to override the estimate")
