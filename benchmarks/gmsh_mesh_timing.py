"""Time of dualfem.problems.gmsh_mesh.mesh_with_defects (gmsh, one thread) against the mesh size.

    python benchmarks/gmsh_mesh_timing.py [--scene scenes/curved.toml] [--sizes 0.02,0.01,0.005,0.0025]
                                          [--nodes 65000] [--repeats 3] [--json FILE]

For each mesh size, the scene's defects are meshed without and with tip refinement
(tip_size = mesh_size / 4): best wall time of ``--repeats`` runs, node and triangle counts,
unknowns = 2 x nodes (before doubling the defect nodes). ``--nodes N`` adds the mesh size that
gives about N nodes (uniform mesh: nodes ~ 2 / sqrt(3) x area / h^2).
"""
from __future__ import annotations

import argparse
import json
import math
import time
import tomllib
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(Path(__file__).resolve().parents[1] / "scenes" / "curved.toml"))
    ap.add_argument("--sizes", default="0.02,0.01,0.005,0.0025")
    ap.add_argument("--nodes", type=int, default=65000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from dualfem.problems.gmsh_mesh import mesh_with_defects

    sc = tomllib.loads(Path(a.scene).read_text(encoding="utf-8"))
    W, H = sc.get("width", 1.0), sc.get("height", 1.0)
    sizes = [float(s) for s in a.sizes.split(",") if s]
    if a.nodes:
        sizes.append(round(math.sqrt(2 / math.sqrt(3) * W * H / a.nodes), 6))
    recs = []
    print(f"{'mesh_size':>9s} {'tip_size':>9s} {'nodes':>8s} {'triangles':>9s} {'unknowns':>9s} {'time_s':>7s}")
    for h in sizes:
        for tip in (None, h / 4):
            best = math.inf
            for _ in range(a.repeats):
                t0 = time.perf_counter()
                m = mesh_with_defects(W, H, sc["defects"], h, tip)
                best = min(best, time.perf_counter() - t0)
            n, nt = m.points.shape[1], m.triangles.shape[1]
            recs.append({"mesh_size": h, "tip_size": tip, "nodes": n, "triangles": nt, "unknowns": 2 * n,
                         "time_s": best})
            print(f"{h:9.5g} {tip or 0:9.4g} {n:8d} {nt:9d} {2 * n:9d} {best:7.3f}", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(recs, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
