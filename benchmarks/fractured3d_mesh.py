"""gmsh's stages on a box with many random disks (the 3D fractured scene), per 3D algorithm.

    python benchmarks/fractured3d_mesh.py --cracks 200 --radius 0.05 --mesh-size 0.04 --tip-size 0.015
    python benchmarks/fractured3d_mesh.py --cracks 500 --radius 0.035 --mesh-size 0.035 --tip-size 0.012

Places the disks as the scene does (seed 1, min_gap 2 x tip_size, any orientation), then per
algorithm (``--algorithms``: gmsh's Mesh.Algorithm3D numbers, 10 = HXT, 1 = Delaunay) times the OCC
fragment of the box with every disk, the size fields, and gmsh's 1D, 2D and 3D meshing (optimisation
pass included in 3D), and prints the tetrahedra, the nodes and the least normalised volume ratio
(1 for a regular tetrahedron: 6 sqrt(2) V / l_rms^3) per algorithm, one line each.
"""
from __future__ import annotations

import argparse
import time

import gmsh
import numpy as np

from dualfem.problems.three_d import mesh as M
from dualfem.problems.three_d.disks import place_disks
from dualfem.problems.three_d.geometry import Surface, _frame


def quality(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Normalised volume ratio per tetrahedron (points (3, n), tets (4, nt))."""
    X = points[:, tets]
    v = np.abs(np.einsum("ij,ij->j", np.cross((X[:, 1] - X[:, 0]).T, (X[:, 2] - X[:, 0]).T).T, X[:, 3] - X[:, 0])) / 6
    e2 = sum(np.sum((X[:, a] - X[:, b]) ** 2, axis=0) for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)))
    return 6 * np.sqrt(2) * v / np.sqrt(e2 / 6) ** 3


def stages(surfaces, h: float, tip: float, algorithm: int) -> dict:
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        for k, v in {**M._OPTIONS, "Mesh.Algorithm3D": algorithm}.items():
            gmsh.option.setNumber(k, v)
        occ = gmsh.model.occ
        t = [time.perf_counter()]
        vol = occ.addBox(0, 0, 0, 1, 1, 1)
        tags = [M._surface(gmsh, s) for s in surfaces]
        _, omap = occ.fragment([(3, vol)], [(2, x) for x in tags])
        occ.synchronize()
        t.append(time.perf_counter())
        pieces = [m[0][1] for m in omap[1:]]
        front = sorted({abs(x) for p in pieces for _, x in gmsh.model.getBoundary([(2, p)], oriented=False)})
        M._fields(gmsh, h, tip, front, None, pieces)
        t.append(time.perf_counter())
        for dim in (1, 2, 3):
            gmsh.model.mesh.generate(dim)
            t.append(time.perf_counter())
        m = M._extract(gmsh, pieces)
    finally:
        gmsh.finalize()
    d = np.diff(t)
    return {"fragment": d[0], "fields": d[1], "1D": d[2], "2D": d[3], "3D": d[4], "tets": m.tets.shape[1],
            "nodes": m.points.shape[1], "min quality": float(quality(m.points, m.tets).min())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cracks", type=int, default=200)
    ap.add_argument("--radius", type=float, default=0.05)
    ap.add_argument("--mesh-size", type=float, default=0.04)
    ap.add_argument("--tip-size", type=float, default=0.015)
    ap.add_argument("--algorithms", type=int, nargs="*", default=[10, 1])
    a = ap.parse_args()
    C, N, R = place_disks(a.cracks, a.radius, [0, 0, 1], 90, 2 * a.tip_size, 1, None, (1.0, 1.0, 1.0))
    surfaces = [Surface("disk", 1e-5, c, n, *_frame(n), a=float(r), b=float(r)) for c, n, r in zip(C, N, R)]
    for alg in a.algorithms:
        s = stages(surfaces, a.mesh_size, a.tip_size, alg)
        print(f"cracks {a.cracks} Algorithm3D {alg}: " + ", ".join(
            f"{k} {v:.2f} s" if isinstance(v, float) and k not in ("min quality",) else f"{k} {v:,}"
            if isinstance(v, int) else f"{k} {v:.3f}" for k, v in s.items()), flush=True)


if __name__ == "__main__":
    main()
