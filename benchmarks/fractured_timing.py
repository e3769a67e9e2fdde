"""Scene -> QP of a fractured body, stage by stage, against the floor (factor + solve of K).

    python benchmarks/fractured_timing.py [--cracks 400] [--mesh-size 0.003] [--seed 1]
                                          [--variants frontal_unsmoothed:1,frontal:1,frontal:0]
                                          [--repeats 3] [--json FILE]

The reference scene of issue 25: ``cracks`` straight cracks of length 0.025 in the unit square
(problems/fractured.py, default min_gap = 2 x mesh_size), mesh_size = tip_size, load f1. Each repeat
builds the scene afresh in this process (imports and the plugin registry loaded before the clock starts)
and times: placement (the generator and the key checks), the mesher's geometry checks, gmsh's
``generate`` and the uniform refinement (per variant ALGORITHM:REFINE: a 2D algorithm of
``gmsh_mesh.ALGORITHMS`` and the number of refinements after it; ``frontal_unsmoothed:1`` is what the
problem uses, ``frontal:0`` meshing at mesh_size directly as the scene files do;
``gmsh_mesh.refine_uniformly``), reading gmsh's arrays, the node doubling (cut), the elastic stiffness
(``assemble.stiffness``), and the whole ``load_scene(...).build()``. The floor is one factorization +
solve of that K by the PARDISO backend (``dualfem.numerics.factor``), measured right after each build.
Medians of the repeats are printed (every run written with ``--json``).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path


def _wrap(mod, name: str, label: str, T: dict) -> None:
    f = getattr(mod, name)

    def timed(*a, **k):
        t = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            T[label] = T.get(label, 0.0) + time.perf_counter() - t

    setattr(mod, name, timed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cracks", type=int, default=400)
    ap.add_argument("--mesh-size", type=float, default=0.003)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--variants", default="frontal_unsmoothed:1,frontal:1,frontal:0")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--factor", default="pardiso")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)

    import gmsh

    import dualfem.problems.thin_defect as td
    from dualfem.core.registry import problems
    from dualfem.core.scene import load_scene
    from dualfem.numerics import linalg
    from dualfem.problems import fractured
    from dualfem.problems import gmsh_mesh as gm

    problems()                                       # the registry, outside the clock
    import numpy as np
    import scipy.sparse as sp

    warm = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(50, 50), format="csr")
    linalg.sparse_factor(warm, a.factor).solve(np.ones(50))     # the backend's library loaded, outside too
    T: dict[str, float] = {}
    _wrap(gm, "validate", "geometry checks", T)
    _wrap(gmsh.model.mesh, "generate", "gmsh generate", T)
    _wrap(gm, "refine_uniformly", "refine (numpy)", T)
    _wrap(gm, "_extract", "read gmsh arrays", T)
    _wrap(td, "cut", "cut", T)
    _wrap(td, "stiffness", "stiffness", T)
    scene = {"cracks": a.cracks, "mesh_size": a.mesh_size, "tip_size": a.mesh_size, "seed": a.seed, "load": "f1"}
    recs = []
    for rep in range(a.repeats):
        for algo in a.variants.split(","):
            fractured.Fractured.gmsh_algorithm, refine = algo.split(":")
            fractured.Fractured.gmsh_refine = int(refine)
            T.clear()
            t0 = time.perf_counter()
            pr = load_scene("fractured", scene)
            T["placement"] = time.perf_counter() - t0
            qp = pr.build()
            T["total"] = time.perf_counter() - t0
            T["other (maps, interface, load)"] = T["total"] - sum(v for k, v in T.items() if k != "total")
            t = time.perf_counter()
            linalg.sparse_factor(qp.K, a.factor).solve(qp.F)
            T["floor"] = time.perf_counter() - t
            T.setdefault("refine (numpy)", 0.0)
            recs.append({"algorithm": algo, "repeat": rep, "ndof": qp.n, "defect_nodes": int(qp.B.shape[0]),
                         **{k: round(v, 4) for k, v in T.items()}})
            print(json.dumps(recs[-1]), flush=True)
            del pr, qp
    print("medians (min in brackets):")
    keys = [k for k in recs[0] if k not in ("algorithm", "repeat")]
    for algo in a.variants.split(","):
        rs = [r for r in recs if r["algorithm"] == algo]
        med = {k: statistics.median(r[k] for r in rs) for k in keys}
        low = {k: min(r[k] for r in rs) for k in keys}
        print(f"{algo:10s} " + "  ".join(f"{k} {v:g} [{low[k]:g}]" for k, v in med.items())
              + f"  total/floor {med['total'] / med['floor']:.2f} [{low['total'] / low['floor']:.2f}]")
    if a.json:
        Path(a.json).write_text(json.dumps(recs, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
