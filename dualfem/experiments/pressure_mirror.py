"""The diagnosis of the contact pressure's error: the same cracks on meshes mirror-symmetric across the crack plane.

The cases of :mod:`dualfem.experiments.pressure` (normal compression SIGMA_N and shear TAU on the crack plane, the
crack turned by ``angle``), but the body's mesh is built as one half meshed by gmsh with the crack on its boundary
(2D: the plate's lower half with the crack segment on its top edge; 3D: the cube's lower half with the disk on its
top face), mirrored across the crack plane (nodes on the plane shared), then turned by the crack's rotation about
the body's centre. The body, the crack, the mesh sizes (``mesh_size``, ``tip_size`` at the tips / front growing at
slope 0.3, as the box scenes') and the loads are those of the unstructured case; the mesh is written to a gmsh
file and read back by the ``file_body`` problem (docs/bodies.md), so the QP is built by the same code.

Why: on such a mesh the stiffness commutes with the reflection across the crack plane, so the shear's response
is antisymmetric and puts no normal force on the crack's nodes: if the pressure is exact there (to rounding) and
not on the unstructured mesh of the same sizes, the error comes from the mesh's asymmetry across the crack
(the normal-tangential coupling of the discrete interface), not from the weights, the normals or the solver.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from dualfem.core.scene import load_scene
from dualfem.experiments import pressure as P
from dualfem.experiments.runner import run
from dualfem.problems._friction import tangential_operator
from dualfem.problems.file_body.write import write_msh

_BOX_3D, _RADIUS = 10.0, 1.0


def _gmsh():
    import gmsh

    gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    return gmsh


def _size_field(gmsh, dim: int, tags: list[int], mesh_size: float, tip_size: float) -> None:
    f = gmsh.model.mesh.field
    d = f.add("Distance")
    f.setNumbers(d, "PointsList" if dim == 0 else "CurvesList", tags)
    m = f.add("MathEval")
    f.setString(m, "F", f"Min({mesh_size}, {tip_size} + 0.3 * F{d})")
    f.setAsBackgroundMesh(m)
    for key in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(key, 0)


def _nodes_and_cells(gmsh, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (dim, n), cells (dim + 1, nc) of the highest dimension, node index of each gmsh tag)."""
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    idx = np.full(int(tags.max()) + 1, -1, np.int64)
    idx[tags.astype(np.int64)] = np.arange(tags.size)
    _, nt = gmsh.model.mesh.getElementsByType(2 if dim == 2 else 4)
    return xyz.reshape(-1, 3)[:, :dim].T.copy(), idx[nt.astype(np.int64)].reshape(-1, dim + 1).T, idx


def half_2d(mesh_size: float, tip_size: float, a: float = P.A_2D):
    """The unit plate's lower half [0, 1] x [0, 0.5] with the crack [0.5 - a, 0.5 + a] x {0.5} on its top edge:
    (points, triangles, crack edges (2, k) in order along x)."""
    gmsh = _gmsh()
    try:
        gmsh.model.add("half")
        g = gmsh.model.geo
        xy = ((0, 0), (1, 0), (1, 0.5), (0.5 + a, 0.5), (0.5 - a, 0.5), (0, 0.5))
        pts = [g.addPoint(x, y, 0, mesh_size) for x, y in xy]
        lines = [g.addLine(pts[i], pts[(i + 1) % 6]) for i in range(6)]
        g.addPlaneSurface([g.addCurveLoop(lines)])
        g.synchronize()
        _size_field(gmsh, 0, [pts[3], pts[4]], mesh_size, tip_size)
        gmsh.model.mesh.generate(2)
        points, tri, _ = _nodes_and_cells(gmsh, 2)
    finally:
        gmsh.finalize()
    on = np.flatnonzero((np.abs(points[1] - 0.5) < 1e-12) & (np.abs(points[0] - 0.5) <= a + 1e-12))
    on = on[np.argsort(points[0, on])]
    return points, tri, np.vstack([on[:-1], on[1:]])


def half_3d(mesh_size: float, tip_size: float):
    """The cube [0, 10]^3's lower half (z <= 5) with the disk of radius 1 centred on its top face:
    (points, tetrahedra, the disk's triangles (3, k))."""
    gmsh = _gmsh()
    try:
        gmsh.model.add("half")
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, 0, _BOX_3D, _BOX_3D, _BOX_3D / 2)
        disk = occ.addDisk(_BOX_3D / 2, _BOX_3D / 2, _BOX_3D / 2, _RADIUS, _RADIUS)
        occ.fragment([(3, box)], [(2, disk)])
        occ.synchronize()
        c = _BOX_3D / 2
        faces = gmsh.model.getEntitiesInBoundingBox(c - 1.01, c - 1.01, c - 1e-6, c + 1.01, c + 1.01, c + 1e-6, 2)
        rims = gmsh.model.getEntitiesInBoundingBox(c - 1.01, c - 1.01, c - 1e-6, c + 1.01, c + 1.01, c + 1e-6, 1)
        _size_field(gmsh, 1, [t for _, t in rims], mesh_size, tip_size)
        gmsh.model.mesh.generate(3)
        points, tets, idx = _nodes_and_cells(gmsh, 3)
        crack = [idx[gmsh.model.mesh.getElementsByType(2, t)[1].astype(np.int64)].reshape(-1, 3).T for _, t in faces]
    finally:
        gmsh.finalize()
    return points, tets, np.hstack(crack)


def mirror(points: np.ndarray, cells: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """The mesh and its reflection across the plane x_last = ``level`` (nodes on the plane shared; the reflected
    cells' orientation restored by swapping two corners)."""
    on = np.abs(points[-1] - level) < 1e-12
    n = points.shape[1]
    ids = np.arange(n)
    ids[~on] = n + np.arange(int((~on).sum()))
    image = points[:, ~on].copy()
    image[-1] = 2 * level - image[-1]
    swapped = ids[cells][[1, 0, *range(2, cells.shape[0])]]
    return np.hstack([points, image]), np.hstack([cells, swapped])


def build(case: P.Case, folder: Path):
    """The QP of ``case`` on the mirror-symmetric mesh (module docstring), through a gmsh file in ``folder``."""
    dim = case.dim
    centre = 0.5 if dim == 2 else _BOX_3D / 2
    if dim == 2:
        points, cells, crack = half_2d(case.mesh_size, case.tip_size)
    else:
        points, cells, crack = half_3d(case.mesh_size, case.tip_size)
    points, cells = mirror(points, cells, centre)
    points = P.frame(dim, case.angle) @ (points - centre) + centre
    path = folder / f"mirror_{dim}d_{case.angle:g}_{case.mesh_size:g}.msh"
    write_msh(path, points, cells, {"crack": crack}, version=2.2)
    scene = path.with_suffix(".toml")
    scene.write_text(f"mesh_file = {json.dumps(path.name)}\nE = {P.E!r}\nnu = {P.NU!r}\ndelta = {P.DELTA!r}\n"
                     f"remote_stress = {P.remote_stress(dim, case.angle, case.tau).tolist()!r}\n"
                     "[[defects]]\ngroup = \"crack\"\n")
    return load_scene(str(scene)).build()


def coupling(qp) -> float:
    """The normal-tangential coupling of the discrete interface: max |B K^-1 T'| / max |T K^-1 T'| (B the normal
    jumps, T the tangential jumps of every node pair, K the QP's stiffness): the normal opening that a unit
    tangential force pair induces, relative to the slip it causes. Zero on a mesh mirror-symmetric across a
    straight / flat crack; one sparse factorization of K and one solve per tangential row."""
    from scipy.sparse.linalg import splu

    T = tangential_operator(qp.interface, qp.n, np.arange(qp.m))
    Z = splu(sp.csc_matrix(qp.K)).solve(T.T.toarray())
    return float(np.abs(qp.B @ Z).max() / np.abs(T @ Z).max())


def measure(case: P.Case, solver: str = "pdas") -> dict:
    """The frictionless ``case`` on the mirror-symmetric mesh: the pressure's errors (inner part and all nodes)
    and the slip's, as :func:`dualfem.experiments.pressure.measure` reports them."""
    with tempfile.TemporaryDirectory() as tmp:
        qp = build(case, Path(tmp))
    sol = run(solver, qp)
    out = {"dim": case.dim, "angle": case.angle, "mesh_size": case.mesh_size, "tip_size": case.tip_size,
           "tau": case.tau, "n": qp.n, "m": qp.m, "status": str(sol.status), "coupling": coupling(qp),
           "coupling_gmsh": coupling(P.build(case))}
    if sol.x is None:
        return out
    centre = 0.5 if case.dim == 2 else _BOX_3D / 2
    R = P.frame(case.dim, case.angle)
    X = qp.geometry.nodes[:, qp.interface.lower] - centre
    rho = np.linalg.norm(X - np.outer(R[:, -1], R[:, -1] @ X), axis=0) / (P.A_2D if case.dim == 2 else _RADIUS)
    inner, p, w = rho <= 0.8, P.pressure(qp, sol), qp.weights
    slip = P.slip_along(qp, sol, case)
    out.update(pressure_l2=P.relative_l2(w[inner], p[inner], np.full(int(inner.sum()), P.SIGMA_N)),
               pressure_all_max=float(np.abs(p - P.SIGMA_N).max() / P.SIGMA_N),
               slip_l2=P.relative_l2(w[inner], slip[inner], P.closed_form_slip(case, rho)[inner]))
    return out


#: the report's mirror cases: frictionless, 30 degrees, the unstructured study's coarser levels
CASES = (*(P.Case(2, 30.0, *lv) for lv in P.LEVELS_2D[:3]), *(P.Case(3, 30.0, *lv) for lv in P.LEVELS_3D[:3]))


def study(cases=CASES, solver: str = "pdas", progress=None) -> list[dict]:
    """:func:`measure` on every case (JSON-able rows)."""
    rows = []
    for case in cases:
        rows.append(measure(case, solver))
        if progress:
            progress(f"mirror {case.dim}D {case.angle:g} deg {case.mesh_size:g}: {rows[-1]['status']} "
                     f"p {rows[-1].get('pressure_l2', float('nan')):.1e}")
    return rows
