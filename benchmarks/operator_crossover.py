"""The crossover of the two dual operators: pdas with operator=dense against operator=matrix_free.

Fractured bodies (library scene ``fractured``, load f1, mesh_size = tip_size = 0.003, crack length
0.025, seed 1) with a growing number of cracks, so the local unknowns |I| (4 per defect node) grow at
an almost fixed number of unknowns. Per scene, in one process: the floor (PARDISO factor + solve of
K), then pdas setup + solve with each operator from a cold factorization store, ``--repeat`` times
(medians). Prints a Markdown table (machine, threads) and writes it to ``--out`` if given.

    python benchmarks/operator_crossover.py --cracks 25 50 100 150 200 300 \\
        --out benchmarks/results/operator_crossover.md
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path


def _time(fn, repeat: int) -> tuple[float, object]:
    ts, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def _measure(qp, repeat: int, cracks: int) -> tuple[float, dict]:
    """(floor, {operator: pdas setup + solve from a cold store}) medians of ``repeat``."""
    from dualfem.core.registry import solvers
    from dualfem.numerics.factor import get_default
    from dualfem.numerics.linalg import sparse_factor, store_of

    floor, _ = _time(lambda: sparse_factor(qp.K, get_default()).solve(qp.F), repeat)
    row = {}
    for op in ("dense", "matrix_free"):
        def once(op=op):
            store_of(qp).clear()
            s = solvers()["pdas"](operator=op)
            s.setup(qp)
            return s.solve()
        try:
            row[op], sol = _time(once, repeat)
            if str(sol.status) != "solved":
                row[op] = float("nan")
        except Exception as exc:  # noqa: BLE001 - a refused or failed path is reported, not fatal
            print(f"{cracks} cracks, {op}: {type(exc).__name__}: {exc}", file=sys.stderr)
            row[op] = float("nan")
    return floor, row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cracks", type=int, nargs="+", default=[25, 50, 100, 150, 200, 300])
    ap.add_argument("--mesh-size", type=float, default=0.003)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    from dualfem.core.scene import load_scene
    from dualfem.numerics.factor import get_default
    from dualfem.numerics.threads import ensure_threads

    ensure_threads()
    lines = [f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, factorization "
             f"{get_default()}; medians of {a.repeat}; started {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.",
             "", "| cracks | unknowns | defect nodes m | local unknowns | floor (s) | dense (s) | matrix-free (s) | "
             "dense / floor | matrix-free / floor | faster |", "|---|---|---|---|---|---|---|---|---|---|"]
    for c in a.cracks:
        qp = load_scene("fractured", {"cracks": c, "seed": 1, "crack_length": 0.025, "mesh_size": a.mesh_size,
                                      "tip_size": a.mesh_size, "load": "f1"}).build()
        floor, row = _measure(qp, a.repeat, c)
        faster = min(row, key=lambda k: row[k] if row[k] == row[k] else float("inf"))
        lines.append(f"| {c} | {qp.n:,} | {qp.m:,} | {qp.local_dofs.size:,} | {floor:.2f} | {row['dense']:.2f} | "
                     f"{row['matrix_free']:.2f} | {row['dense'] / floor:.1f} | {row['matrix_free'] / floor:.1f} | "
                     f"{faster} |")
        print(lines[-1], file=sys.stderr, flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
