"""Time the vectorised P1 tetrahedron stiffness (problems/three_d/assemble.py) against scikit-fem's.

    python benchmarks/assembly3d.py [k ...] [--repeat 3] [--skfem]

Mesh: the unit cube cut into k^3 small cubes of 6 tetrahedra each (scikit-fem's ``MeshTet.init_tensor``),
bottom face clamped. Each repeat runs in a fresh process (imports and mesh outside the clock); the median
wall time of the assembly (gradients, pattern, values, CSC with the clamped unknowns dropped), the
tetrahedra per second and the process's CPU time over the same span (numpy runs it on one thread: on a
shared machine the CPU time tells what an idle core would take) are printed. ``--skfem`` also times
scikit-fem's ``linear_elasticity`` assembly (same Lame parameters, its default quadrature) followed by
the same restriction.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = """
import json, sys, time
import numpy as np
from skfem import MeshTet
from dualfem.problems.three_d.assemble import free_dofs, gradients, stiffness
k, which = int(sys.argv[1]), sys.argv[2]
m = MeshTet.init_tensor(*[np.linspace(0, 1, k + 1)] * 3)
p, t = m.p, m.t.copy()
_, vol = gradients(p, t)
t[:, vol < 0] = t[[0, 2, 1, 3]][:, vol < 0]
fixed = np.zeros((3, p.shape[1]), bool)
fixed[:, p[2] == 0] = True
nd = free_dofs(fixed)
n = int(nd.max()) + 1
lam, mu = 40384.6, 26538.5
c0 = time.process_time()
if which == "ours":
    t0 = time.perf_counter()
    K = stiffness(p, t, lam, mu, nd, n)
else:
    from skfem import Basis, ElementTetP1, ElementVector
    from skfem.models.elasticity import linear_elasticity
    t0 = time.perf_counter()
    A = linear_elasticity(lam, mu).assemble(Basis(MeshTet(p, t), ElementVector(ElementTetP1())))
    keep = nd.T.ravel() >= 0
    K = A[keep][:, keep].tocsc()
dt = time.perf_counter() - t0
print(json.dumps({"t": dt, "cpu": time.process_time() - c0, "tets": t.shape[1], "n": n, "nnz": K.nnz}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("k", nargs="*", type=int, default=[20, 40, 60])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skfem", action="store_true", help="also time scikit-fem's assembly")
    a = ap.parse_args()
    print("| k | tetrahedra | unknowns | assembly | median wall s | tetrahedra / s | median CPU s (process) |")
    print("|---|---|---|---|---|---|---|")
    for k in a.k:
        for which in (["ours", "skfem"] if a.skfem else ["ours"]):
            runs = []
            for _ in range(a.repeat):
                out = subprocess.run([sys.executable, "-c", CHILD, str(k), which], capture_output=True, text=True,
                                     check=True)
                runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
            t = statistics.median(r["t"] for r in runs)
            cpu = statistics.median(r["cpu"] for r in runs)
            r = runs[0]
            print(f"| {k} | {r['tets']:,} | {r['n']:,} | {which} | {t:.3f} | {r['tets'] / t:,.0f} | {cpu:.3f} |",
                  flush=True)


if __name__ == "__main__":
    main()
