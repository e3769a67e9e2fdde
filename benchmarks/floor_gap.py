"""Why an exact solver's setup + solve can take less than "the floor" (issue 28, item 7d).

    python benchmarks/floor_gap.py --N 256 512 --repeats 5 --threads 1 --force \
        --out benchmarks/results/floor_gap/floor_gap.md

The floor (benchmarks/floor.py, ``dualfem bench``'s floor rows, benchmarks/primary_perf.py) is one
analysis + factorization + solve of the QP's K. The exact solvers (pdas, uzawa, uzawa_auto, mprgp)
factorize another matrix: K_fixed (``QP.K_fixed``, the delta-free elastic stiffness K_el) with the
Schur complement onto the defect unknowns I (``dualfem.numerics.linalg.factor_fixed``). The two
differ in their sparsity pattern, not only in values: K = K_el + interface term is a scipy sum,
which drops the entries that are exactly zero (on the f2 mesh, the x-x and y-y couplings of the two
ends of each triangle's diagonal), while K_el keeps them as stored zeros. This script factorizes (analysis +
numeric factorization + one solve, PARDISO, from scratch each time) five matrices in one process,
alternating, and prints a Markdown table with wall and CPU seconds, PARDISO's analysis and numeric
seconds and nnz(L), plus the pattern facts (stored zeros, nodes whose two unknowns have identical
rows):

* ``K`` (the floor), ``K`` on K_el's pattern (K's values, K_el's stored zeros put back: same matrix,
  other pattern), ``K_el`` alone, ``K`` with the Schur set I, ``K_el`` with the Schur set I
  (what the exact solvers' setup factorizes).

``--threads 1`` (default) measures CPU seconds that a loaded machine does not inflate; wall seconds
are listed too. A measurement, not a claim about another machine.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp


def with_pattern(A: sp.csr_matrix, P: sp.csr_matrix) -> sp.csr_matrix:
    """A's values on the union of A's and P's patterns (P's extra positions stored as zeros)."""
    Ac, Pc = A.tocoo(), P.tocoo()
    out = sp.coo_matrix((np.r_[Ac.data, np.zeros(Pc.nnz)], (np.r_[Ac.row, Pc.row], np.r_[Ac.col, Pc.col])),
                        shape=A.shape).tocsr()          # coo -> csr sums duplicates, keeps stored zeros
    out.sum_duplicates()
    return out


def identical_rows(A: sp.csr_matrix, node_dofs: np.ndarray) -> int:
    """How many nodes have the same column pattern in the rows of their two unknowns."""
    A = A.copy()
    A.sort_indices()
    a, b = node_dofs
    la, lb = np.diff(A.indptr)[a], np.diff(A.indptr)[b]
    same = 0
    for i, j, n1, n2 in zip(a, b, la, lb):
        same += n1 == n2 and np.array_equal(A.indices[A.indptr[i]:A.indptr[i + 1]],
                                            A.indices[A.indptr[j]:A.indptr[j + 1]])
    return int(same)


def measure(N: int, repeats: int) -> list[str]:
    from dualfem.core.scene import load_scene
    from dualfem.numerics.factor import choose

    qp = load_scene("f2", {"N": N, "delta": 1e-5}).build()
    be = choose("pardiso")
    local = np.asarray(qp.local_dofs, np.int64)
    K, Kf = qp.K.tocsr(), qp.K_fixed.tocsr()
    KU = with_pattern(K, Kf)
    nd = np.asarray(qp.geometry.node_dofs)
    cases = {"K (the floor)": (K, None), "K on K_el's pattern": (KU, None), "K_el": (Kf, None),
             "K, Schur set I": (K, local), "K_el, Schur set I (exact solvers' setup)": (Kf, local)}
    res: dict[str, list[tuple]] = {}
    for _ in range(repeats):
        for name, (A, loc) in cases.items():
            w0, c0 = time.perf_counter(), time.process_time()
            f = be.make(loc).analyze(A).factorize(A)
            if loc is not None:
                f.schur()
            f.solve(qp.F)
            w1, c1 = time.perf_counter(), time.process_time()
            ts = f.info["time_s"]
            res.setdefault(name, []).append((w1 - w0, c1 - c0, ts["analyze"], ts["factorize"], f.info["factor_nnz"]))
            f.free()
            del f
    L = [f"## N = {N}: {qp.n:,} unknowns, |I| = {local.size}", "",
         f"Stored entries: K {K.nnz:,} (stored zeros {int((K.data == 0).sum()):,}), K_el {Kf.nnz:,} (stored zeros "
         f"{int((Kf.data == 0).sum()):,}). Nodes whose two unknowns have identical rows: K "
         f"{identical_rows(K, nd):,} of {nd.shape[1]:,}, K_el {identical_rows(Kf, nd):,}. Medians of {repeats}.", "",
         "| matrix (analysis + factorization + one solve) | wall [s] | CPU [s] | CPU / floor | analysis [s] "
         "| numeric [s] | nnz(L) |", "|---|---|---|---|---|---|---|"]
    floor_cpu = statistics.median(v[1] for v in res["K (the floor)"])
    for name, v in res.items():
        m = [statistics.median(x) for x in zip(*v)]
        L.append(f"| {name} | {m[0]:.3f} | {m[1]:.3f} | {m[1] / floor_cpu:.2f} | {m[2]:.3f} | {m[3]:.3f} "
                 f"| {m[4]:.3g} |")
    return L + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, nargs="+", default=[256])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, help="write the Markdown here (atomically) as well as to stdout")
    ap.add_argument("--force", action="store_true", help="replace the file at --out")
    a = ap.parse_args(argv)
    if any(n < 4 or n > 1024 for n in a.N) or not 1 <= a.repeats <= 20 or not 1 <= a.threads <= 256:
        ap.error("--N must be in [4, 1024], --repeats in [1, 20], --threads in [1, 256]")
    from dualfem.core.errors import InputError
    from dualfem.core.io import atomic_write_text, refuse_overwrite

    try:
        refuse_overwrite([a.out] if a.out else [], a.force)
    except InputError as exc:
        ap.error(str(exc))
    from dualfem.core.scene import load_scene
    from dualfem.numerics.linalg import sparse_factor
    from dualfem.numerics.threads import set_threads

    set_threads(a.threads)
    warm = load_scene("f2", {"N": 8}).build()
    sparse_factor(warm.K, "pardiso").solve(warm.F)          # the library is loaded before timing
    load0 = np.round(np.array(__import__("os").getloadavg()[:1]), 1)[0]
    L = ["# The floor against the exact solvers' factorization", "",
         f"`python benchmarks/floor_gap.py --N {' '.join(map(str, a.N))} --repeats {a.repeats} --threads "
         f"{a.threads}`; f2, delta = 1e-5, PARDISO, {a.threads} thread(s), 1-minute load average at start "
         f"{load0}. Every factorization from scratch, the five matrices alternating. See the script's "
         "docstring for what each row is.", ""]
    for N in a.N:
        L += measure(N, a.repeats)
    text = "\n".join(L)
    print(text)
    if a.out:
        atomic_write_text(a.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
