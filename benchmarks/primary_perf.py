"""Performance of the primary solver against the floor and third-party QP solvers (issue 3).

    python benchmarks/primary_perf.py --force         # N = 64, 128, 256, 512 (about 25 min; replaces the report)
    python benchmarks/primary_perf.py --N 32,64 --repeats 2 --out /tmp/perf.md   # quick

On f2 for every delta, in one run on one machine, one worker process per N (its peak RSS is reported):
* floor: one factorization + solve of the unconstrained K by the fastest installed backend
  (``dualfem.numerics.factor.get_default()``: MKL PARDISO where pypardiso is installed), same threads;
* assembly: scene -> QP (``load_scene(...).build()``), so that **end to end** = assembly + setup +
  solve + certification of the run, what a user of the Python API waits for;
* uzawa (the paper's r = 1e7) and uzawa_auto, fast reduced path, timed FROM SCRATCH (the cached
  factorization of K_fixed is cleared before every repeat, so setup includes it);
* uzawa with linalg="full" (the textbook path; capped by a time limit, small N only);
* Clarabel and OSQP with their default dualfem settings (one repeat; N=512 only at delta=1e-5).
Times are medians over repeats (wall clock). Errors are relative energy-norm errors of x against
a certified reference: the exact KKT solve for the contact set of a tight uzawa_auto solve
(``evaluator.certify``); Clarabel's own error against it is listed too.
Writes a Markdown report and a CSV with one row per (N, delta, method).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write, atomic_write_text, refuse_overwrite
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.numerics import linalg

DELTAS = [1e-1, 1e-3, 1e-5, 1e-7, 1e-9]


def machine() -> dict:
    import clarabel
    import osqp
    import scipy
    import skfem

    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "scikit-fem": skfem.__version__,
            "osqp": osqp.__version__, "clarabel": clarabel.__version__,
            "threads": os.environ.get("OMP_NUM_THREADS", "unset"), "factor": _factor_name(),
            "factor_threads": _threads()}


def _factor_name() -> str:
    from dualfem.numerics.factor import get_default

    return get_default()


def _threads() -> int:
    from dualfem.numerics.threads import get_threads

    return get_threads()


def floor_time(qp, repeats: int) -> float:
    """Median of factorization + one solve of K by the fastest installed backend."""
    from dualfem.numerics.factor import get_default

    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        linalg.sparse_factor(qp.K, get_default()).solve(qp.F)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def timed(name, qp, params, repeats, clear=True):
    ts, sol = [], None
    for _ in range(repeats):
        if clear:
            linalg.store_of(qp).clear()                   # a cold factorization
        t0 = time.perf_counter()
        sol = run(name, qp, params)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), sol


def measure(N: int, args) -> list[dict]:
    """Every delta and method at one N (run in a worker process of its own)."""
    rows = []
    warm = load_scene("f2", {"N": 8}).build()            # imports and libraries loaded before timing
    floor_time(warm, 1)
    for name in ("uzawa", "uzawa_auto", "pdas", "clarabel", "osqp"):
        run(name, warm)
    for d in DELTAS:
        t0 = time.perf_counter()
        qp = load_scene("f2", {"N": N, "delta": d}).build()
        assembly = time.perf_counter() - t0
        fl = floor_time(qp, args.repeats)
        tref = run("uzawa_auto", qp, {"tol": 1e-12})
        xs, mus, ok = evaluator.certify(qp, tref.x)
        if not ok:
            xs, mus = tref.x, tref.multipliers
        methods = [("uzawa", "uzawa", {}, args.repeats), ("uzawa_auto", "uzawa_auto", {}, args.repeats),
                   ("pdas", "pdas", {}, args.repeats)]
        if N <= args.full_max_N:
            methods.append(("uzawa full", "uzawa", {"linalg": "full", "time_limit": args.full_time_limit}, 1))
        if N <= args.third_party_max_N or d == 1e-5:
            methods += [("clarabel", "clarabel", {}, 1), ("osqp", "osqp", {}, 1)]
        for label, name, params, reps in methods:
            t, sol = timed(name, qp, params, reps)
            err = (evaluator.compare(qp, sol.x, sol.multipliers, xs, mus)["x_energy"]
                   if sol.x is not None else float("nan"))
            rows.append({"N": N, "ndof": qp.n, "delta": d, "method": label, "time_s": t, "floor_s": fl,
                         "ratio": t / fl, "assembly_s": assembly, "end_to_end_s": assembly + t,
                         "status": str(sol.status), "iterations": sol.iterations,
                         "setup_s": sol.time_s.get("setup"), "solve_s": sol.time_s.get("solve"),
                         "error": err, "repeats": reps, "certified": ok})
            print(f"N={N} delta={d:.0e} {label:11s} {t:8.3f} s  x{t / fl:6.2f} floor  {sol.status}  "
                  f"{sol.iterations}  err {err:.1e}", file=sys.stderr, flush=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    for r in rows:
        r["process_peak_rss_mb"] = peak
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", default="64,128,256,512")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--full-max-N", type=int, default=128, help="largest N for the textbook full path")
    ap.add_argument("--full-time-limit", type=float, default=120.0)
    ap.add_argument("--third-party-max-N", type=int, default=256,
                    help="above this N, Clarabel/OSQP run only at delta=1e-5")
    ap.add_argument("--out", default="reports/primary_performance.md")
    ap.add_argument("--force", action="store_true", help="replace the report (and its .csv) already at --out")
    ap.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(measure(args.worker, args), default=str))
        return 0
    try:
        refuse_overwrite([Path(args.out), Path(args.out).with_suffix(".csv")], args.force)
    except InputError as exc:
        ap.error(str(exc))
    Ns = [int(n) for n in args.N.split(",")]
    rows = []
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    info = machine()
    passthrough = ["--repeats", str(args.repeats), "--full-max-N", str(args.full_max_N), "--full-time-limit",
                   str(args.full_time_limit), "--third-party-max-N", str(args.third_party_max_N)]
    for N in Ns:
        out = subprocess.run([sys.executable, __file__, "--worker", str(N), *passthrough], stdout=subprocess.PIPE,
                             text=True, check=True)
        rows += json.loads(out.stdout.strip().splitlines()[-1])
    load1 = os.getloadavg()
    elapsed = time.perf_counter() - t_start
    out = Path(args.out)
    fields = list(rows[0])

    def write_csv(tmp):
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields)
            w.writeheader()
            for r in rows:
                w.writerow(r)
    atomic_write(out.with_suffix(".csv"), write_csv)
    atomic_write_text(out, render(rows, info, load0, load1, elapsed, " ".join(sys.argv)))
    print(f"wrote {out} and {out.with_suffix('.csv')}", file=sys.stderr)
    return 0


def render(rows, info, load0, load1, elapsed, command) -> str:
    L = ["# Primary solver performance: Uzawa (fast path) against the floor, the textbook path, Clarabel and OSQP", "",
         f"Generated by `python {command}` in {elapsed / 60:.1f} min. Do not edit by hand.", "",
         "Machine: " + ", ".join(f"{k} {v}" for k, v in info.items()) +
         f"; load average at start {load0[0]:.1f}, at end {load1[0]:.1f} (1 min).", "",
         "Scene f2 (plane strain, unit square), every delta. **floor** = one factorization + solve of "
         f"the unconstrained K by the fastest installed backend ({info.get('factor', '?')}, threads "
         f"{info.get('factor_threads', '?')}), median of repeats. Every method is timed from scratch "
         "(the factorization cache cleared before each repeat; setup + solve + certification), wall clock, "
         "median of the repeats shown; **end to end** adds the assembly of the scene (scene -> QP) of that "
         "N and delta. **err** = relative energy-norm error of x against a certified "
         "reference (exact KKT solve for the contact set of a tight `uzawa_auto` run). k / m = outer / inner "
         "iterations for Uzawa, Newton steps for pdas, IPM or ADMM iterations otherwise. **peak RSS**: "
         "of the worker process that ran every method of that N (Clarabel and OSQP included); the exact "
         "solvers' own peaks per run are in benchmarks/results/end_to_end.", ""]
    Ns = sorted({r["N"] for r in rows})
    for N in Ns:
        rs = [r for r in rows if r["N"] == N]
        L += [f"## N = {N} ({rs[0]['ndof']} unknowns), peak RSS {rs[0]['process_peak_rss_mb']:.0f} MB", "",
              "| delta | floor (s) | assembly (s) | method | time (s) | x floor | end to end (s) | status "
              "| iterations | err |",
              "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rs:
            it = "/".join(str(v) for v in r["iterations"].values())
            L.append(f"| {r['delta']:.0e} | {r['floor_s']:.3f} | {r['assembly_s']:.3f} | {r['method']} | "
                     f"{r['time_s']:.3f} | {r['ratio']:.2f} | {r['end_to_end_s']:.3f} | {r['status']} | {it} | "
                     f"{r['error']:.1e} |")
        L.append("")
    big = max(Ns)
    fast = [r for r in rows if r["N"] == big and r["method"] in ("uzawa", "uzawa_auto", "pdas")]
    L += [f"## Target: exact solvers within 2x the floor at N = {big}", ""]
    for m in ("uzawa", "uzawa_auto", "pdas"):
        rr = [r for r in fast if r["method"] == m]
        if rr:
            worst = max(rr, key=lambda r: r["ratio"])
            L.append(f"* `{m}`: worst ratio {worst['ratio']:.2f} (delta {worst['delta']:.0e}); "
                     + ("met" if worst["ratio"] <= 2 else "NOT met") + " for every delta.")
    L.append("")
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
