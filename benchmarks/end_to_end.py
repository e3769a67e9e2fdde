"""End to end: the whole `dualfem solve` process against the floor, per N (issue 17's table).

For each N: the floor (the fastest installed library factorization + one solve of K, in its own
process, after assembly) and, per solver and delta, the whole command `dualfem solve f2 --set N=..
--solver S --json --quiet` (wall time of the process, and its own time_s split and peak_rss_mb).
One run each unless --repeat; the machine, threads and load are recorded.

    python benchmarks/end_to_end.py --N 256 512 1024 --solvers pdas uzawa_auto --deltas 1e-5 1e-9 \\
        --out benchmarks/results/end_to_end
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

FLOOR = """
import json, resource, sys, time
from dualfem.core.scene import load_scene
from dualfem.numerics.factor import get_default
from dualfem.numerics.linalg import sparse_factor
qp = load_scene("f2", {"N": int(sys.argv[1])}).build()
K = qp.K.tocsc()
t0 = time.perf_counter()
f = sparse_factor(K, get_default())
t1 = time.perf_counter()
x = f.solve(qp.F)
t2 = time.perf_counter()
print(json.dumps({"backend": get_default(), "factor": t1 - t0, "solve": t2 - t1, "n": qp.n,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _run(cmd: list[str]) -> tuple[float, dict]:
    env = dict(os.environ, MPLBACKEND="Agg")
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    try:
        return wall, json.loads(r.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return wall, {"error": (r.stderr or r.stdout).strip()[-300:]}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--N", type=int, nargs="+", default=[256, 512, 1024])
    ap.add_argument("--solvers", nargs="+", default=["pdas", "uzawa_auto"])
    ap.add_argument("--deltas", type=float, nargs="+", default=[1e-5, 1e-9])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--out", default="dualfem-results/end_to_end")
    a = ap.parse_args()
    rows = []
    for N in a.N:
        fl = [_run([sys.executable, "-c", FLOOR, str(N)]) for _ in range(a.repeat)]
        floor = {"N": N, "kind": "floor", **fl[-1][1],
                 "floor_s": statistics.median(r[1].get("factor", float("nan")) + r[1].get("solve", 0) for r in fl)}
        rows.append(floor)
        print(json.dumps(floor), file=sys.stderr, flush=True)
        for s in a.solvers:
            for d in a.deltas:
                runs = [_run([sys.executable, "-m", "dualfem", "solve", "f2", "--set", f"N={N}", "--set", f"delta={d}",
                              "--solver", s, "--json", "--quiet"]) for _ in range(a.repeat)]
                wall = statistics.median(r[0] for r in runs)
                rec = runs[-1][1]
                t = rec.get("time_s", {})
                row = {"N": N, "kind": "solve", "solver": s, "delta": d, "status": rec.get("status"),
                       "whole_process_s": wall, "assembly_s": t.get("assembly"), "setup_s": t.get("setup"),
                       "solve_s": t.get("solve"), "certify_s": t.get("certify"), "total_s": t.get("total"),
                       "peak_rss_mb": rec.get("peak_rss_mb"), "factor": rec.get("factor"),
                       "threads": rec.get("threads"), "floor_s": floor["floor_s"],
                       "setup_solve_over_floor": ((t.get("setup") or 0) + (t.get("solve") or 0)) / floor["floor_s"],
                       "whole_over_floor": wall / floor["floor_s"], "error": rec.get("error")}
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"loadavg_end": os.getloadavg(), "cores": os.cpu_count(), "argv": sys.argv[1:],
            "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (out / "end_to_end.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
