"""The floor of a scene, in its own process: ``python benchmarks/floor.py SCENE '{"N": 512}'``.

Loads the factorization library on a tiny QP first (not timed), then times the scene's meshing +
assembly, one factorization of K by the fastest installed backend (or ``DUALFEM_FACTOR``) and one
solve, on K's own pattern and on the elastic part's pattern (the same K with explicit zeros:
:func:`dualfem.numerics.linalg.on_fixed_pattern`), and prints one JSON line: backend, threads,
assembly, factor, solve, floor (= factor + solve of the faster pattern), pattern ("own" or
"elastic"), floors (both), n, m, n_local, peak_rss_mb. Used by end_to_end.py, small_end.py and fractured.py.
"""
import json
import resource
import sys
import time

from dualfem.core.scene import load_scene
from dualfem.numerics.factor import get_default
from dualfem.numerics.linalg import on_fixed_pattern, sparse_factor
from dualfem.numerics.threads import get_threads

warm = load_scene("f2", {"N": 4}).build()
sparse_factor(warm.K, get_default()).solve(warm.F)       # the library is loaded before timing
t0 = time.perf_counter()
qp = load_scene(sys.argv[1], json.loads(sys.argv[2]) if len(sys.argv) > 2 else {}).build()
t1 = time.perf_counter()

def factor_and_solve(K) -> tuple[float, float]:
    """(factor, solve) seconds of one factorization + one solve of K by the default backend."""
    ta = time.perf_counter()
    f = sparse_factor(K, get_default())
    tb = time.perf_counter()
    f.solve(qp.F)
    tc = time.perf_counter()
    del f
    return tb - ta, tc - tb


# K as assembled, and the same K on the elastic part's pattern (explicit zeros: the node blocks a
# supernodal factorization exploits; numerics.linalg.on_fixed_pattern): the floor is the faster
times = {"own": factor_and_solve(qp.K.tocsc())}
if qp.local is not None:
    times["elastic"] = factor_and_solve(on_fixed_pattern(qp.K, qp.local.K_fixed).tocsc())
pattern = min(times, key=lambda k: sum(times[k]))
factor, solve = times[pattern]
print(json.dumps({"backend": get_default(), "threads": get_threads(), "assembly": t1 - t0, "factor": factor,
                  "solve": solve, "floor": factor + solve, "pattern": pattern,
                  "floors": {k: sum(v) for k, v in times.items()}, "n": qp.n, "m": qp.m,
                  "n_local": int(qp.local_dofs.size),
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
