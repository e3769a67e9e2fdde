"""Writing a body mesh with named groups as a gmsh file (MSH 2.2 or 4.1, through gmsh's API): the way a box
scene's mesh becomes a ``mesh_file`` (the round-trip check; examples).

Each group becomes one discrete entity of its dimension with one physical group of its name; the body is
one discrete entity (a surface or a volume) in the physical group ``"body"``. Node ids are kept (node i of
``points`` is gmsh node i + 1), so reading the file back gives the same node order.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .geometry import _gmsh

_TYPE = {1: 1, 2: 2, 3: 4}            # simplex dimension -> gmsh element type (line, triangle, tetrahedron)


def write_msh(path: str | Path, points: np.ndarray, cells: np.ndarray, groups: dict[str, np.ndarray],
              version: float = 4.1) -> None:
    """Write ``points`` (dim, n), ``cells`` (dim + 1, nc) and ``groups`` (name -> node ids (k + 1, ne) of
    simplices of dimension k < dim) to ``path`` as MSH ``version`` (2.2 or 4.1), ASCII."""
    gmsh = _gmsh()
    dim = points.shape[0]
    owner = not gmsh.isInitialized()
    if owner:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("dualfem_write")
        xyz = np.vstack([points, np.zeros((3 - dim, points.shape[1]))]) if dim < 3 else points
        body = gmsh.model.addDiscreteEntity(dim)
        tags = np.arange(1, points.shape[1] + 1)
        gmsh.model.mesh.addNodes(dim, body, tags, xyz.T.ravel())
        nid = 1
        gmsh.model.mesh.addElementsByType(body, _TYPE[dim], np.arange(nid, nid + cells.shape[1]),
                                          (cells.T + 1).ravel())
        nid += cells.shape[1]
        gmsh.model.addPhysicalGroup(dim, [body], name="body")
        for name, el in groups.items():
            k = el.shape[0] - 1
            ent = gmsh.model.addDiscreteEntity(k)
            gmsh.model.mesh.addElementsByType(ent, _TYPE[k], np.arange(nid, nid + el.shape[1]), (el.T + 1).ravel())
            nid += el.shape[1]
            gmsh.model.addPhysicalGroup(k, [ent], name=name)
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.Binary", 0)
        gmsh.write(str(path))
    finally:
        if owner:
            gmsh.finalize()
        else:
            gmsh.model.remove()
