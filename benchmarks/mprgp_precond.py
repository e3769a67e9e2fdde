"""MPRGP with and without its preconditioners: iterations against h, and the time against the floor.

    python benchmarks/mprgp_precond.py [--cracks 8] [--h 0.02,0.01,0.005,0.0025] [--delta 1e-5,1e-1]
        [--f2 64,128,256,512] [--big 20,0.003] [--repeats 3]
        [--variants none,jacobi,lumped,dirichlet,dirichlet:layers=8] [--out FILE.md]

Part 1 (iterations): the many-crack scene (``/work/wt/many_cracks.py`` or ``--scene-module``: a
fixed staggered grid of cracks x cracks straight cracks, gmsh mesh of size h, load f1) for each h
and delta, and the structured scene f2 for each N (delta 1e-5); mprgp with operator=matrix_free
for each variant (``precond[:key=value...]``): MPRGP's iterations (cg / expansion /
proportioning), the operator applications (products D v, = K-solves apart from b0 and x), and
the polish's CG iterations. Iteration counts are deterministic; the times of part 1 are single runs.

Part 2 (time): the big many-crack scene (``--big rows,h``: 20 x 20 cracks, h = 0.003: 269 k
unknowns, m = 3,200) at delta 1e-5: the floor (one factorization of K + one solve, the default
backend) and each variant (setup + solve, the factorization of K included: the QP's store is
cleared before every run), alternated, ``--repeats`` times; medians, and the ratio to the floor's
median. Prints markdown (machine, threads, load average) and writes it to ``--out``.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time


def parse_variant(spec: str) -> tuple[str, dict]:
    name, *kv = spec.split(":")
    return spec, {"precond": name, **{k: int(v) for k, v in (a.split("=") for a in kv)}}


def run_mprgp(qp, params: dict, clear: bool = True):
    from dualfem.core.registry import solvers
    from dualfem.numerics.linalg import store_of

    if clear:
        store_of(qp).clear()
    t0 = time.perf_counter()
    s = solvers()["mprgp"](operator="matrix_free", **params)
    s.setup(qp)
    t1 = time.perf_counter()
    sol = s.solve()
    t2 = time.perf_counter()
    return sol, t1 - t0, t2 - t1


def cell(sol) -> str:
    it = sol.iterations
    ok = "" if str(sol.status) == "solved" else f" {sol.status}"
    return f"{it['cg']}/{it['expansion']}/{it['proportioning']} ({sol.info['applications']}){ok}"


def machine() -> list[str]:
    from dualfem.numerics import threads
    from dualfem.numerics.factor import choose

    threads.ensure_threads()
    pools = ", ".join(f"{p.get('api')}: {p.get('threads')}" for p in threads.info())
    return [f"- machine: {platform.node()}, {platform.processor() or platform.machine()}, "
            f"{os.cpu_count()} cores, Python {platform.python_version()}, {platform.platform()}",
            f"- threads: {threads.get_threads()} (pools: {pools}); factorization backend: {choose(None).name}",
            f"- load average at start: {os.getloadavg()[0]:.2f} (the machine is shared: compare ratios within one run)"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cracks", type=int, default=8)
    ap.add_argument("--h", default="0.02,0.01,0.005,0.0025")
    ap.add_argument("--delta", default="1e-5,1e-1")
    ap.add_argument("--f2", default="64,128,256,512")
    ap.add_argument("--big", default="20,0.003", help="rows(=cols),h of the timed scene; '' to skip")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", default="none,jacobi,lumped,dirichlet,dirichlet:layers=8")
    ap.add_argument("--scene-module", default="/work/wt")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    sys.path.insert(0, a.scene_module)
    from many_cracks import many_cracks_problem

    from dualfem.core.scene import build_qp, load_scene
    from dualfem.experiments.workspace import Workspace

    variants = [parse_variant(v) for v in a.variants.split(",")]
    lines = ["# mprgp: preconditioners (benchmarks/mprgp_precond.py)", "",
             f"`{' '.join(['python benchmarks/mprgp_precond.py', *(argv if argv is not None else sys.argv[1:])])}`",
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})", "", *machine(), "",
             "Cells: MPRGP iterations cg / expansion / proportioning (operator applications D v = K-solves, "
             "power iterations, diagonal estimate and polish included); operator=matrix_free.", ""]

    def emit(text=""):
        print(text, flush=True)
        lines.append(text)

    for line in lines:
        print(line)
    head = "| scene | n | m | " + " | ".join(v for v, _ in variants) + " |"
    sep = "|---|---|---|" + "---|" * len(variants)
    if a.h:
        for d in [float(v) for v in a.delta.split(",")]:
            emit(f"## Many cracks ({a.cracks} x {a.cracks}, fixed crack set), delta = {d:g}, against h")
            emit()
            emit(head)
            emit(sep)
            for h in [float(v) for v in a.h.split(",")]:
                qp = build_qp(many_cracks_problem(rows=a.cracks, cols=a.cracks, h=h, delta=d))
                cells = []
                for _, params in variants:
                    sol, ts, tv = run_mprgp(qp, params, clear=False)
                    cells.append(cell(sol))
                emit(f"| h = {h:g} | {qp.n} | {qp.m} | " + " | ".join(cells) + " |")
                del qp
            emit()
    if a.f2:
        emit("## f2 (structured, one defect), delta = 1e-5, against N")
        emit()
        emit(head)
        emit(sep)
        for N in [int(v) for v in a.f2.split(",")]:
            qp = build_qp(load_scene("f2", {"N": N, "delta": 1e-5}))
            cells = [cell(run_mprgp(qp, params, clear=False)[0]) for _, params in variants]
            emit(f"| N = {N} | {qp.n} | {qp.m} | " + " | ".join(cells) + " |")
            del qp
        emit()
    if a.big:
        rows, h = a.big.split(",")
        ws = Workspace(many_cracks_problem(rows=int(rows), cols=int(rows), h=float(h), delta=1e-5))
        qp = ws.qp
        emit(f"## Time: many cracks {rows} x {rows}, h = {h}, delta = 1e-5 (n = {qp.n}, m = {qp.m}), "
             f"median of {a.repeats}")
        emit()
        from dualfem.numerics.factor import choose

        backend = choose(None)
        K = qp.K.tocsr()
        floor, times, sols = [], {v: [] for v, _ in variants}, {}
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            f = backend.factor(K)
            f.solve(qp.F)
            floor.append(time.perf_counter() - t0)
            del f
            for v, params in variants:
                sol, ts, tv = run_mprgp(qp, params)
                times[v].append((ts + tv, ts, tv))
                sols[v] = sol
        fl = statistics.median(floor)
        emit(f"Floor (one {backend.name} factorization of K + one solve): median {fl:.2f} s "
             f"(runs: {', '.join(f'{t:.2f}' for t in floor)}); load average now {os.getloadavg()[0]:.2f}.")
        emit()
        emit("| precond | iterations cg/exp/prop | applications | K-solves | polish CG | setup s | solve s | "
             "total s | total / floor |")
        emit("|---|---|---|---|---|---|---|---|---|")
        for v, _ in variants:
            tot = statistics.median(t[0] for t in times[v])
            ts = statistics.median(t[1] for t in times[v])
            tv = statistics.median(t[2] for t in times[v])
            s = sols[v]
            it = s.iterations
            emit(f"| {v} | {it['cg']}/{it['expansion']}/{it['proportioning']} | {s.info['applications']} | "
                 f"{s.info['solves']} | {s.info['cg_iterations']} | {ts:.2f} | {tv:.2f} | {tot:.2f} | "
                 f"{tot / fl:.1f} |")
        emit()
    if a.out:
        with open(a.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
