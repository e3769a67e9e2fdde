"""Factorization backends on the f2 stiffness matrix: time and peak memory (issue 17).

    python benchmarks/factor_backends.py                       # N = 128, 256, 512, every installed backend
    python benchmarks/factor_backends.py --N 64,128 --repeats 1 --out /tmp/fb.md
    python benchmarks/factor_backends.py --dense                # 1 vs 2 BLAS threads, dense m x m phases

One worker process per (backend, N), so that its peak RSS (``ru_maxrss``) belongs to that run:
build the QP (f2, delta = 1e-5, plane strain), then `repeats` times, from scratch
(``linalg.store_of(qp).clear()``):
* ``schur``: what the exact solvers' setup does: factorize the delta-free K_fixed with the Schur
  complement onto the defect unknowns (``linalg.factor_fixed``) + one solve with it;
* ``K``: analysis + factorization of the whole K + one solve (``linalg.sparse_factor``).
Times are medians (wall clock); threads: ``dualfem.numerics.threads.set_threads`` default (all
cores for MKL/PARDISO, OpenBLAS 1). Peak RSS: after building the QP, after the schur runs, after
everything. PARDISO's own analysis estimate of its peak (iparm[14..16]) is listed where reported.
"""
from __future__ import annotations

import argparse
import gc
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0     # Linux: KiB


def _rss_now_mb() -> float:
    """Current resident set size (Linux /proc)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 2**20


def worker(backend: str, N: int, repeats: int) -> dict:
    import numpy as np

    from dualfem.core.scene import load_scene
    from dualfem.numerics import linalg
    from dualfem.numerics.threads import get_threads, set_threads

    set_threads(None)
    t0 = time.perf_counter()
    qp = load_scene("f2", {"N": N, "delta": 1e-5}).build()
    out = {"backend": backend, "N": N, "n": qp.n, "local": int(np.size(qp.local_dofs)),
           "build_s": time.perf_counter() - t0, "rss_build_mb": _rss_mb(), "threads": get_threads()}
    gc.collect()
    out["rss_after_build_now_mb"] = _rss_now_mb()
    ts, info = [], {}
    for _ in range(repeats):
        linalg.store_of(qp).clear()
        gc.collect()
        t0 = time.perf_counter()
        ff = linalg.factor_fixed(qp, backend)
        ff.solve(qp.F)
        ts.append(time.perf_counter() - t0)
        info = {k: v for k, v in ff.fact.info.items() if k != "time_s"}
        del ff
    linalg.store_of(qp).clear()
    gc.collect()
    out.update(schur_s=statistics.median(ts), schur_runs=ts, rss_schur_mb=_rss_mb(), schur_info=info)
    ts = []
    for _ in range(repeats):
        gc.collect()
        t0 = time.perf_counter()
        f = linalg.sparse_factor(qp.K, backend)
        f.solve(qp.F)
        ts.append(time.perf_counter() - t0)
        info = {k: v for k, v in f.info.items() if k != "time_s"}
        f.free()
        del f
    out.update(K_s=statistics.median(ts), K_runs=ts, rss_all_mb=_rss_mb(), K_info=info)
    return out


def dense(repeats: int = 5) -> list[dict]:
    """Median ms of the dense m x m phases with 1 and 2 BLAS threads."""
    import numpy as np
    import scipy.linalg as la
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    rows = []
    for nI, m in ((1020, 255), (2044, 511)):
        A = rng.standard_normal((nI, nI))
        S = A @ A.T + nI * np.eye(nI)
        BI = rng.standard_normal((m, nI))
        for nt in (1, 2):
            with threadpool_limits(limits=nt):
                t = {"cho": [], "D": [], "matvec": []}
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    c = la.cho_factor(S, lower=True)
                    t1 = time.perf_counter()
                    BI @ la.cho_solve(c, BI.T)
                    t2 = time.perf_counter()
                    for _ in range(100):
                        S @ BI[0]
                    t3 = time.perf_counter()
                    t["cho"].append(t1 - t0)
                    t["D"].append(t2 - t1)
                    t["matvec"].append((t3 - t2) / 100)
            rows.append({"nI": nI, "m": m, "threads": nt, **{k: 1e3 * statistics.median(v) for k, v in t.items()}})
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| N | unknowns | backend | threads | K factor+solve (s) | Schur onto defect + solve (s) | "
             "peak RSS after QP / Schur / all (MB), RSS held by the QP | "
             "PARDISO analysis: peak est. (MB), factor nnz |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        si = r.get("schur_info", {})
        est = (f"{si['peak_bytes'] / 2**20:.0f}, {si['factor_nnz']:,}" if "peak_bytes" in si
               else f"-, {si.get('factor_nnz', 0):,}")
        lines.append(f"| {r['N']} | {r['n']:,} | {r['backend']} | {r['threads']} | {r['K_s']:.2f} | "
                     f"{r['schur_s']:.2f} | {r['rss_build_mb']:.0f} / {r['rss_schur_mb']:.0f} / "
                     f"{r['rss_all_mb']:.0f}, {r.get('rss_after_build_now_mb', float('nan')):.0f} | {est} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--N", default="128,256,512")
    p.add_argument("--backends", default=None, help="comma-separated (default: every installed one)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", default=None, help="write the Markdown table (and a .json) here")
    p.add_argument("--dense", action="store_true", help="only the dense-phase thread measurement")
    p.add_argument("--worker", nargs=2, metavar=("BACKEND", "N"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.worker[0], int(a.worker[1]), a.repeats)))
        return 0
    if a.dense:
        for r in dense():
            print(json.dumps(r))
        return 0
    from dualfem.numerics.factor import available

    backends = a.backends.split(",") if a.backends else available()
    rows = []
    for N in (int(x) for x in a.N.split(",")):
        for b in backends:
            res = subprocess.run([sys.executable, __file__, "--worker", b, str(N), "--repeats", str(a.repeats)],
                                 capture_output=True, text=True, check=True)
            rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(json.dumps({k: v for k, v in rows[-1].items() if not k.endswith("_runs")}), file=sys.stderr)
    md = table(rows)
    print(md)
    if a.out:
        Path(a.out).write_text(md + "\n")
        Path(a.out).with_suffix(".json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
