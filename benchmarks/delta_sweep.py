"""A sweep over delta on one mesh against one solve (issue 17's targets on delta).

    python benchmarks/delta_sweep.py --N 512 --solvers pdas uzawa_auto --out benchmarks/results/delta_sweep [--force]

For each solver, in fresh worker processes (f2, plane strain, the process-wide factorization backend):
* **cold**: one process per delta in 1e-1 ... 1e-9 that builds the scene and solves it once
  (``dualfem.runner.run``: setup + solve + certification), as `dualfem solve` does;
* **sweep**: one process that builds and solves the nine deltas one after the other through a
  :class:`dualfem.workspace.Workspace` (``ws.update(delta=d).solve(solver)``), so the delta-free
  assembly and the factorization of K_fixed are reused (only the interface term and the dense
  reduced phase change); the workspace's counters (assemblies, factorizations) are recorded.
Times are wall clock inside the worker (imports excluded; the first, untimed, N = 8 solve warms the
imports up); one untimed worker per solver and N runs first (the first process after a while pays
for the file-system caches: it measured 1.4-1.6x the others). The ratio asked for by the issue:
sweep total / one cold solve, where one cold solve is the median of the nine cold processes (one
process varies by +-10 %, mostly in assembly: first touch of fresh memory); the ratio to the cold
solve at delta = 1e-5 is given too.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DELTAS = [10.0 ** -k for k in range(1, 10)]

WORKER = """
import json, sys, time
from dualfem.numerics.factor import get_default
from dualfem.workspace import Workspace
N, solver, deltas = int(sys.argv[1]), sys.argv[2], [float(d) for d in sys.argv[3].split(",")]
Workspace("f2", {"N": 8}).solve(solver)
ws = Workspace("f2", {"N": N})
rows = []
for d in deltas:
    t0 = time.perf_counter()
    qp = ws.update(delta=d).qp
    t1 = time.perf_counter()
    sol = ws.solve(solver)
    t2 = time.perf_counter()
    rows.append({"delta": d, "assembly": t1 - t0, "setup": sol.time_s["setup"], "solve": sol.time_s["solve"],
                 "certify": sol.time_s.get("certify", 0.0), "total": t2 - t0, "status": str(sol.status),
                 "iterations": sol.iterations})
print(json.dumps({"factor": get_default(), "n": qp.n, "rows": rows, "assemblies": ws.assemblies,
                  "factorizations": ws.factorizations}))
"""


def worker(N: int, solver: str, deltas: list[float]) -> dict:
    out = subprocess.run([sys.executable, "-c", WORKER, str(N), solver, ",".join(f"{d:g}" for d in deltas)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median_run(runs: list[dict], total) -> dict:
    """The run of median ``total(run)`` (the lower middle one for an even count), with all totals."""
    ranked = sorted(runs, key=total)
    return {**ranked[(len(ranked) - 1) // 2], "all_totals": [round(total(r), 4) for r in runs]}


def measure(N: int, solver: str, repeat: int = 1) -> dict:
    print(f"  {solver} N={N} warm-up process (untimed: file-system caches)", file=sys.stderr, flush=True)
    worker(N, solver, [1e-5])
    cold = {}
    for d in DELTAS:
        print(f"  {solver} N={N} cold delta={d:g} x {repeat}", file=sys.stderr, flush=True)
        cold[f"{d:g}"] = _median_run([worker(N, solver, [d])["rows"][0] for _ in range(repeat)], lambda r: r["total"])
    print(f"  {solver} N={N} sweep of {len(DELTAS)} deltas x {repeat}", file=sys.stderr, flush=True)
    sweeps = [worker(N, solver, DELTAS) for _ in range(repeat)]
    sweep = _median_run(sweeps, lambda w: sum(r["total"] for r in w["rows"]))
    return {"solver": solver, "N": N, "n": sweep["n"], "factor": sweep["factor"], "repeat": repeat, "cold": cold,
            "sweep": sweep["rows"], "sweep_totals": sweep["all_totals"],
            "sweep_counters": {k: sweep.get(k) for k in ("assemblies", "factorizations")}}


def table(results: list[dict]) -> str:
    L = []
    for r in results:
        c5 = r["cold"]["1e-05"]["total"]
        L += [f"### {r['solver']}, N = {r['N']} ({r['n']:,} unknowns), factorization: {r['factor']}", "",
              "| delta | cold: total (s) | cold / cold at 1e-5 | status | in the sweep: assembly | setup | solve "
              "| certify | total (s) |", "|---|---|---|---|---|---|---|---|---|"]
        for s in r["sweep"]:
            c = r["cold"][f"{s['delta']:g}"]
            L.append(f"| {s['delta']:g} | {c['total']:.2f} | {c['total'] / c5:.2f} | {c['status']} | "
                     f"{s['assembly']:.2f} | {s['setup']:.2f} | {s['solve']:.2f} | {s['certify']:.2f} | "
                     f"{s['total']:.2f} |")
        tot = sum(s["total"] for s in r["sweep"])
        cm = float(np.median([c["total"] for c in r["cold"].values()]))
        further = [s["total"] for s in r["sweep"][1:]]
        L += ["", f"Sweep of {len(r['sweep'])} deltas: {tot:.2f} s = **{tot / cm:.2f} x** one cold solve (median "
              f"of the nine: {cm:.2f} s; {tot / c5:.2f} x the one at delta = 1e-5, {c5:.2f} s); each further delta "
              f"{min(further):.2f}-{max(further):.2f} s (median {np.median(further):.2f}); slowest cold delta "
              f"{max(c['total'] for c in r['cold'].values()) / cm:.2f} x the median."
              + (f" The sweep's workspace assembled {r['sweep_counters']['assemblies']} time(s) and factorized "
                 f"{r['sweep_counters']['factorizations']} time(s)." if r.get("sweep_counters") else ""), ""]
    return "\n".join(L)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--N", type=int, nargs="+", default=[512])
    p.add_argument("--solvers", nargs="+", default=["pdas", "uzawa_auto"])
    p.add_argument("--out", required=True, help="folder for delta_sweep.json and delta_sweep.md")
    p.add_argument("--repeat", type=int, default=1, choices=range(1, 10), metavar="R",
                   help="processes per cold delta and sweeps per solver (the median is used; 1 ... 9)")
    p.add_argument("--force", action="store_true", help="replace the results already in --out")
    a = p.parse_args()
    out = Path(a.out)
    from dualfem.core.errors import InputError
    from dualfem.core.io import refuse_overwrite

    try:
        refuse_overwrite([out / "delta_sweep.json", out / "delta_sweep.md"], a.force)
    except InputError as exc:
        p.error(str(exc))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    load0 = os.getloadavg()[0]
    results = [measure(N, s, a.repeat) for N in a.N for s in a.solvers]
    head = (f"# Delta sweep on one mesh (f2)\n\nGenerated by `python benchmarks/delta_sweep.py --N "
            f"{' '.join(map(str, a.N))} --solvers {' '.join(a.solvers)} --repeat {a.repeat} --out {a.out}` in "
            f"{time.time() - t0:.0f} s; "
            f"cores {os.cpu_count()}, load average at start {load0:.1f}, at end {os.getloadavg()[0]:.1f}. "
            f"Times inside the worker process, imports excluded; each cold time and the sweep: the median of "
            f"{a.repeat} process(es).\n\n")
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "delta_sweep.json", json.dumps({"results": results}, indent=1))
    atomic_write_text(out / "delta_sweep.md", head + table(results))
    print(head + table(results))


if __name__ == "__main__":
    main()
