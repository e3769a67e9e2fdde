"""PDAS (semismooth Newton) iteration counts from a cold start over scenes, mesh sizes and delta.

    python benchmarks/pdas_iterations.py [--N 64,128,256,512] [--delta 1e-1,1e-3,1e-5,1e-7,1e-9]
                                         [--scenes f1,f2,f3] [--json FILE]

One line per solve on stdout (scene, N, delta, status, Newton steps, evaluator KKT error, setup
and solve time); one Workspace per (scene, N): assembled and factorized once for all deltas. With --json, all records
are also written to FILE.
"""
from __future__ import annotations

import argparse
import json
import sys
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", default="64,128,256,512")
    ap.add_argument("--delta", default="1e-1,1e-2,1e-3,1e-4,1e-5,1e-6,1e-7,1e-8,1e-9")
    ap.add_argument("--scenes", default="f1,f2,f3")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from dualfem.core import evaluator
    from dualfem.workspace import Workspace

    recs = []
    print(f"{'scene':5s} {'N':>4s} {'delta':>7s} {'status':8s} {'newton':>6s} {'active':>6s} {'kkt':>8s} "
          f"{'setup_s':>7s} {'solve_s':>7s}", flush=True)
    for N in [int(v) for v in a.N.split(",")]:
        for sc in a.scenes.split(","):
            ws = Workspace(sc, {"N": N})            # one assembly and factorization for every delta
            for d in [float(v) for v in a.delta.split(",")]:
                t0 = time.perf_counter()
                qp = ws.update(delta=d).qp
                tb = time.perf_counter() - t0
                s = ws.solve("pdas")
                kkt = evaluator.kkt_error(s.residuals) if s.residuals else float("nan")
                rec = {"scene": sc, "N": N, "delta": d, "status": str(s.status), "newton": s.iterations.get("newton"),
                       "n_active": s.info.get("n_active"), "m": qp.m, "kkt": kkt, "build_s": tb, **s.time_s}
                recs.append(rec)
                print(f"{sc:5s} {N:4d} {d:7.0e} {rec['status']:8s} {rec['newton']:6d} {rec['n_active']:6d} "
                      f"{kkt:8.1e} {s.time_s['setup']:7.3f} {s.time_s['solve']:7.3f}", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(recs, fh, indent=1)
    worst = max(r["newton"] for r in recs)
    print(f"max Newton steps: {worst}; all solved: {all(r['status'] == 'solved' for r in recs)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
