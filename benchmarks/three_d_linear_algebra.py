"""3D linear algebra: the floor and each dual path on synthetic 3D contact QPs, one process per run.

The QP: tests/_three_d_qp.py (unit cube of N^3 x 6 P1 tetrahedra, clamped base, a rigid lid on the top
face: one constraint u_z <= 0 per top node; load up on half the lid, down on the other half, plus shear).
Per size N and path, a fresh worker process (so its peak RSS is that path's) builds the QP and runs:

* ``floor``: the fastest factorization + one solve of K (PARDISO) when the 3D memory model
  (:func:`dualfem.numerics.memory.factor_bytes`, ``dim=3``) says it fits, else one AMG-CG solve
  (hierarchy setup + CG to 1e-8);
* ``newton:amg``: :func:`dualfem.numerics.amg.full_space_newton` (semismooth Newton on all unknowns, its
  K + B_A' C B_A systems by AMG-preconditioned CG; not a plugin) plus the certificate through the AMG
  K-solves (:class:`dualfem.numerics.certify.KSolver` with ``ksolve="amg"``) and the evaluator's residuals;
* ``<solver>:<operator>``: the solver through :func:`dualfem.experiments.runner.run` (setup, solve and
  certification, the runner's own KSolver: a factorization where one fits, else AMG-CG), e.g.
  ``pdas:amg``, ``pdas:matrix_free``, ``pdas:dense``; refused paths (the memory model) are reported.

Output: a Markdown table (n, m, path, status, assembly, setup, solve, certify, total seconds, K-solves,
AMG iterations, certified error, peak RSS) printed and written to ``--out``; each finished row is also
kept as JSON in ``--out``'s folder (``<stem>.rows.jsonl``) so ``--render-only`` re-renders.

    python benchmarks/three_d_linear_algebra.py --N 8 12 16 --out dualfem-results/three_d_la.md
    python benchmarks/three_d_linear_algebra.py --N 36 60 --paths floor pdas:amg --out dualfem-results/three_d_large.md

Sizes: N = 16, 24, 36, 48, 60 give 14 k, 45 k, 148 k, 346 k, 670 k unknowns (``tests/_three_d_qp.SIZES``).
Not a test: timings on a shared machine are not claims.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PATHS = ("floor", "newton:amg", "pdas:dense", "pdas:matrix_free", "pdas:amg", "mprgp:amg", "uzawa_auto:amg",
         "penalty:amg")


def _peak_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def floor_solve(qp) -> dict:
    """The floor of a 3D QP: one PARDISO factorization + solve of K when the memory model of the QP's
    dimension says it fits, else one AMG-preconditioned CG solve (rtol 1e-8). ``status`` names the path;
    ``setup`` (factorization or hierarchy) and ``solve`` in seconds; ``residual`` = max|K x - F| / max|F|."""
    import numpy as np

    from dualfem.numerics.amg import amg_for
    from dualfem.numerics.dual_operator import qp_dim
    from dualfem.numerics.linalg import sparse_factor
    from dualfem.numerics.memory import SAFETY, available_bytes, factor_bytes

    need = SAFETY * factor_bytes(qp.n, "pardiso", dim=qp_dim(qp))
    t0 = time.perf_counter()
    if need <= available_bytes():
        f = sparse_factor(qp.K, "pardiso")
        t1 = time.perf_counter()
        x = f.solve(qp.F)
        out = {"status": "pardiso", "nnz_L": f.info.get("factor_nnz")}
    else:
        a = amg_for(qp)
        t1 = time.perf_counter()
        x = a.solve(qp.F, rtol=1e-8)
        out = {"status": "amg-cg 1e-8", "amg_iterations": a.counters.iterations}
    t2 = time.perf_counter()
    res = float(np.abs(qp.K @ x - qp.F).max() / np.abs(qp.F).max())
    return {**out, "setup": t1 - t0, "solve": t2 - t1, "residual": res}


def _newton(qp) -> dict:
    from dualfem.core.evaluator import RESIDUALS, residuals
    from dualfem.numerics.amg import full_space_newton
    from dualfem.numerics.certify import KSolver, certified_error

    t0 = time.perf_counter()
    r = full_space_newton(qp)
    t1 = time.perf_counter()
    cert = certified_error(qp, r.x, r.mu, KSolver(qp, ksolve="amg"))
    res = residuals(qp, r.x, r.mu)
    t2 = time.perf_counter()
    ok = r.converged and max(res[k] for k in RESIDUALS) <= 1e-9 and cert["value"] <= 1e-9
    return {"status": "certified" if ok else f"not certified ({r.message})", "setup": 0.0, "solve": t1 - t0,
            "certify": t2 - t1, "certificate": cert["value"], "amg_iterations": r.cg_iterations,
            "k_solves": r.al_steps, "message": f"{r.newton_steps} Newton steps, {r.hierarchies} hierarchies"}


def worker(N: int, path: str) -> dict:
    """One row: build the QP of size N and run ``path`` (in this process)."""
    sys.path.insert(0, str(REPO / "tests"))
    from _three_d_qp import box_qp

    from dualfem.experiments.runner import run

    t0 = time.perf_counter()
    qp = box_qp(N)
    row: dict = {"N": N, "n": qp.n, "m": qp.m, "path": path, "assembly": time.perf_counter() - t0}
    if path == "floor":
        row.update(floor_solve(qp))
    elif path == "newton:amg":
        row.update(_newton(qp))
    else:
        solver, op = path.split(":")
        s = run(solver, qp, {"operator": op})
        ts = s.time_s
        row.update(status=str(s.status), setup=ts.get("setup"), solve=ts.get("solve"), certify=ts.get("certify"),
                   k_solves=s.info.get("solves"), amg_iterations=s.info.get("amg_iterations"),
                   certificate=(s.info.get("certificate") or {}).get("value"), message=s.message[:160])
    row["total"] = time.perf_counter() - t0
    row["peak_rss_mb"] = _peak_mb()
    return row


def _fmt(v, f="{:.1f}") -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f.format(v)
    return str(v)


def render(rows: list[dict]) -> str:
    head = ("| N | unknowns | m | path | status | assembly s | setup s | solve s | certify s | total s | K-solves "
            "| AMG its | certified error | peak GB |")
    out = [f"3D linear algebra (tests/_three_d_qp.py), {platform.node()}, {os.cpu_count()} cores; one process "
           f"per row (peak = that process's peak RSS)", "", head, "|" + "---|" * 14]
    for r in rows:
        out.append("| " + " | ".join([str(r["N"]), f"{r['n']:,}", str(r["m"]), r["path"], str(r.get("status", "")),
                                      _fmt(r.get("assembly")), _fmt(r.get("setup")), _fmt(r.get("solve")),
                                      _fmt(r.get("certify")), _fmt(r.get("total")), _fmt(r.get("k_solves")),
                                      _fmt(r.get("amg_iterations")), _fmt(r.get("certificate"), "{:.1e}"),
                                      _fmt(r.get("peak_rss_mb", 0) / 1024, "{:.2f}")]) + " |")
    return "\n".join(out) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, nargs="+", default=[8, 12, 16])
    ap.add_argument("--paths", nargs="+", default=list(PATHS))
    ap.add_argument("--out", type=Path, default=Path("dualfem-results/three_d_linear_algebra.md"))
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per worker process")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--worker", nargs=2, metavar=("N", "PATH"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        print(json.dumps(worker(int(a.worker[0]), a.worker[1])))
        return 0
    for N in a.N:
        if not 2 <= N <= 200:
            ap.error(f"--N must lie in [2, 200], got {N}")
    for p in a.paths:
        ops = ("auto", "dense", "matrix_free", "amg")
        if p not in ("floor", "newton:amg") and (":" not in p or p.split(":")[1] not in ops):
            ap.error(f"--paths: 'floor', 'newton:amg' or SOLVER:OPERATOR (operator {', '.join(ops)}), got {p!r}")
    rows_file = a.out.with_suffix(".rows.jsonl")
    rows = [json.loads(line) for line in rows_file.read_text().splitlines() if line.strip()] \
        if rows_file.exists() else []
    if not a.render_only:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        for N in a.N:
            for p in a.paths:
                t0 = time.perf_counter()
                try:
                    cp = subprocess.run([sys.executable, __file__, "--worker", str(N), p], capture_output=True,
                                        text=True, timeout=a.timeout, cwd=REPO)
                    row = json.loads(cp.stdout.strip().splitlines()[-1]) if cp.returncode == 0 else \
                        {"N": N, "n": 0, "m": 0, "path": p, "status": f"failed: {cp.stderr.strip()[-160:]}"}
                except subprocess.TimeoutExpired:
                    row = {"N": N, "n": 0, "m": 0, "path": p, "status": f"timeout {a.timeout:g} s"}
                print(f"N={N} {p}: {row.get('status')} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
                rows = [r for r in rows if not (r["N"] == N and r["path"] == p)] + [row]
                tmp = rows_file.with_suffix(".tmp")
                tmp.write_text("".join(json.dumps(r) + "\n" for r in rows))
                tmp.replace(rows_file)
    rows.sort(key=lambda r: (r["N"], r["path"]))
    md = render(rows)
    tmp = a.out.with_suffix(".md.tmp")
    tmp.write_text(md)
    tmp.replace(a.out)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
