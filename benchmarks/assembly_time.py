"""Time scene -> QP (mesh, defect doubling, assembly, maps) of the structured f2 scene.

    PYTHONPATH=. python benchmarks/assembly_time.py [N ...] [--repeat 3]

Each repeat runs in a fresh process (no caches, no warm imports counted: imports happen before
the clock starts) and prints the median wall time per N.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = """
import json, time, sys
from dualfem.core.scene import load_scene
import dualfem.problems.thin_defect  # imports outside the timed region
t = time.perf_counter()
qp = load_scene("f2", {"N": int(sys.argv[1])}).build()
print(json.dumps({"t": time.perf_counter() - t, "n": qp.n}))
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("N", nargs="*", type=int, default=[128, 256, 512])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    print("| N | unknowns | scene -> QP (s), median | runs (s) |\n|---|---|---|---|")
    for N in a.N:
        runs = [json.loads(subprocess.run([sys.executable, "-c", CHILD, str(N)], check=True,
                                          capture_output=True, text=True).stdout) for _ in range(a.repeat)]
        ts = [r["t"] for r in runs]
        print(f"| {N} | {runs[0]['n']} | {statistics.median(ts):.3f} | {', '.join(f'{t:.3f}' for t in ts)} |",
              flush=True)


if __name__ == "__main__":
    main()
