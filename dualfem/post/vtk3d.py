"""ParaView output of a 3D solution (VTU/XDMF via meshio): the tetrahedra and the defect surfaces.

One unstructured grid holds the points (every node, both copies of a defect node; quadratic tetrahedra:
``tetra10`` cells, their mid-edge nodes points like the others), point data
``displacement`` (3 components: *Warp By Vector*), ``opening``, ``slip``, ``pressure`` (``pressure`` only
with multipliers; 0 away from the defects and at front nodes, which carry no constraint; both copies of
a defect node carry its value; no point field holds NaN), ``defect_id`` (-1 elsewhere) and
``normal`` (the unit normal pointing to the "+" face at defect nodes, 0 elsewhere), ``K_I``, ``K_II``,
``K_III`` (with `dualfem solve --sif`: stress intensity factors at the front nodes, 0 elsewhere:
:mod:`dualfem.post.sif`); cell blocks: the
tetrahedra, then, when the QP has its defect surface triangles (``qp.interface.faces``, (n_faces, 3)
node ids of the "-" face, the front nodes single), the triangles of every "+" face followed by those
of every "-" face. Cell data: the stress
components ``s11 s22 s33 s23 s13 s12`` and ``von_mises`` (units of E, NaN on the surface cells),
``opening``/``slip``/``pressure`` on the surface cells (means of the three nodes, NaN on the
tetrahedra), ``defect_id`` and ``face`` (0 tetrahedron, +1 "+" face, -1 "-" face).
"""
from __future__ import annotations

import numpy as np

from dualfem.post.fields3d import VOIGT, defect_fields3d, stresses3d

NODAL = ("opening", "slip", "pressure")


def to_meshio3d(qp, sol, sif=None):
    """The meshio.Mesh described in the module docstring."""
    import meshio

    g = qp.geometry
    npts = g.nodes.shape[1]
    from dualfem.post.fields import nodal_displacement
    from dualfem.post.vtk import _point_field, finite_mean

    u = nodal_displacement(qp, sol.x)
    st = stresses3d(qp, sol.x)
    ntet = g.cells.shape[1]
    cells = [("tetra10" if g.cells.shape[0] == 10 else "tetra", g.cells.T.astype(np.int64))]
    cell_data = {k: [np.asarray(st[k], float)] for k in (*VOIGT, "von_mises")}
    point_data = {"displacement": u}
    face = [np.zeros(ntet, dtype=np.int32)]
    if qp.interface is not None:
        d = defect_fields3d(qp, sol.x, sol.multipliers)
        has_p = "pressure" in d
        d.setdefault("pressure", np.full(qp.m, np.nan))
        for k in NODAL:
            if k == "pressure" and not has_p:
                continue
            v = np.asarray(d[k], float)
            if k == "pressure":         # front nodes (weight 0): no constraint acts, the pressure is 0
                v = np.where(np.asarray(qp.weights, float) > 0, v, 0.0)
            point_data[k] = _point_field(npts, d["lower"], d["upper"], v)
        point_data["defect_id"] = np.full(npts, -1, dtype=np.int32)
        point_data["normal"] = np.zeros((npts, 3))
        for ids in (d["lower"], d["upper"]):
            point_data["defect_id"][ids] = d["defect_id"]
            point_data["normal"][ids] = d["normal"]
        faces = qp.interface.faces
        if faces is not None and np.size(faces):
            f = np.asarray(faces, dtype=np.int64).T        # node ids of the "-" face; the front single
            plus = np.arange(npts)
            plus[d["lower"]] = d["upper"]
            tri = np.vstack([plus[f].T, f.T])
            nf = f.shape[1]
            row_of = np.full(npts, -1)
            row_of[d["lower"]] = np.arange(qp.m)
            cells.append(("triangle", tri))
            for k in cell_data:
                cell_data[k].append(np.full(2 * nf, np.nan))
            face.append(np.concatenate([np.ones(nf, np.int32), -np.ones(nf, np.int32)]))
            r = row_of[f]
            for k in NODAL:         # the front: opening and slip 0, pressure undefined (ignored in the mean)
                vals = np.where(r >= 0, np.asarray(d[k], float)[np.maximum(r, 0)], np.nan if k == "pressure" else 0.0)
                v = finite_mean(vals)
                cell_data[k] = [np.full(ntet, np.nan), np.concatenate([v, v])]
            did = d["defect_id"][np.max(r, axis=0)].astype(np.int32)
            cell_data["defect_id"] = [np.full(ntet, -1, dtype=np.int32), np.concatenate([did, did])]
    cell_data["face"] = face
    if sif is not None:
        point_data.update(_front_fields(sif, npts))
    return meshio.Mesh(g.nodes.T.copy(), cells, point_data=point_data, cell_data=cell_data)


def _front_fields(sif, npts: int) -> dict:
    """``K_I``, ``K_II``, ``K_III`` at the front nodes (0 elsewhere; :mod:`dualfem.post.sif`) of the factors
    ``dualfem solve --sif`` computed."""
    from dualfem.post.sif_outputs import front_point_data

    return front_point_data(None, sif, npts)
