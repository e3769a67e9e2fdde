"""The floor of a scene, in its own process: ``python benchmarks/floor.py SCENE '{"N": 512}'``.

Loads the factorization library on a tiny QP first (not timed), then times the scene's meshing +
assembly, one factorization of K by the fastest installed backend (or ``DUALFEM_FACTOR``) and one
solve, and prints one JSON line: backend, threads, assembly, factor, solve, floor (= factor +
solve), n, m, n_local, peak_rss_mb. Used by end_to_end.py, small_end.py and fractured.py.
"""
import json
import resource
import sys
import time

from dualfem.core.scene import load_scene
from dualfem.numerics.factor import get_default
from dualfem.numerics.linalg import sparse_factor
from dualfem.numerics.threads import get_threads

warm = load_scene("f2", {"N": 4}).build()
sparse_factor(warm.K, get_default()).solve(warm.F)       # the library is loaded before timing
t0 = time.perf_counter()
qp = load_scene(sys.argv[1], json.loads(sys.argv[2]) if len(sys.argv) > 2 else {}).build()
t1 = time.perf_counter()
f = sparse_factor(qp.K.tocsc(), get_default())
t2 = time.perf_counter()
f.solve(qp.F)
t3 = time.perf_counter()
print(json.dumps({"backend": get_default(), "threads": get_threads(), "assembly": t1 - t0, "factor": t2 - t1,
                  "solve": t3 - t2, "floor": t3 - t1, "n": qp.n, "m": qp.m, "n_local": int(qp.local_dofs.size),
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
