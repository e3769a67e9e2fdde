"""A body mesh from a mesh file (``mesh_file``): gmsh MSH 2 and 4, or any format meshio reads with cell sets.

The body is every element of the highest dimension in the file: triangles (2D; every node's z must be the
same) or tetrahedra (3D), first order only. Groups: gmsh physical groups by name (``$PhysicalNames``; a
group without a name is called by its number, ``"7"``), or meshio's cell sets of other formats. Refused
before reading: a file larger than :data:`MAX_FILE_BYTES` or one whose reading would not fit in memory
(:func:`check_file_size`); after reading: other element types in the body's dimension
(quadrilaterals, second-order elements, hexahedra, ... : "mixed or unsupported element types"), no body.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dualfem.errors import InputError, MissingDependency

from .body import P1_TYPES, BodyMesh, Group, make_body

#: the largest mesh file read (bytes): about 10 M tetrahedra in MSH 4 ASCII
MAX_FILE_BYTES = 2_000_000_000
#: memory while a file is read, per byte of the file (meshio's text parsing: measured ~3-5)
READ_BYTES_PER_BYTE = 6
#: meshio's names of element types that are not P1 simplices, by dimension (refused in the body's dimension)
_DIM_OF = {"quad": 2, "triangle6": 2, "triangle7": 2, "quad8": 2, "quad9": 2, "polygon": 2,
           "tetra10": 3, "hexahedron": 3, "hexahedron20": 3, "hexahedron27": 3, "wedge": 3, "pyramid": 3,
           "wedge15": 3, "pyramid13": 3, "line3": 1}


def check_file_size(path: Path, key: str) -> None:
    """Refuse, before reading, a file beyond :data:`MAX_FILE_BYTES` or one whose reading would need more memory
    than is available (:data:`READ_BYTES_PER_BYTE` per byte)."""
    from dualfem.numerics.memory import available_bytes

    size = os.stat(path).st_size
    if size > MAX_FILE_BYTES:
        raise InputError(f"{key} {str(path)!r} is {size / 1e9:.2f} GB; the largest mesh file read is "
                         f"{MAX_FILE_BYTES / 1e9:g} GB")
    need, have = READ_BYTES_PER_BYTE * size, available_bytes()
    if need > have:
        raise InputError(f"{key} {str(path)!r} ({size / 1e9:.2f} GB) needs about {need / 1e9:.1f} GB to read; "
                         f"{have / 1e9:.1f} GB are available")


def read_mesh(path: Path, key: str = "mesh_file") -> BodyMesh:
    """The checked :class:`~.body.BodyMesh` of a mesh file (module docstring)."""
    try:
        import meshio
    except ImportError:
        raise MissingDependency("bodies from mesh files need meshio: pip install meshio") from None
    check_file_size(path, key)
    try:
        m = meshio.read(str(path))
    except Exception as exc:                     # noqa: BLE001 - meshio raises many kinds on a bad file
        raise InputError(f"{key} {str(path)!r} cannot be read as a mesh: {type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''}") from None
    source = f"{key} {path.name!r}"
    dims = {P1_TYPES.get(c.type, (_DIM_OF.get(c.type, -1), 0))[0] for c in m.cells}
    dim = max(dims) if dims else -1
    if dim not in (2, 3):
        raise InputError(f"{source}: no triangles or tetrahedra (element types: "
                         f"{', '.join(sorted({c.type for c in m.cells})) or 'none'})")
    other = sorted({c.type for c in m.cells if c.type not in P1_TYPES and _DIM_OF.get(c.type, dim) >= dim - 1})
    if other:
        raise InputError(f"{source}: mixed or unsupported element types {', '.join(other)}; the body must be "
                         f"first-order {'triangles' if dim == 2 else 'tetrahedra'} (and its groups lines"
                         f"{'' if dim == 2 else ' or triangles'}): mesh it with Mesh.ElementOrder = 1, "
                         f"no recombination")
    body_type = "triangle" if dim == 2 else "tetra"
    points = np.asarray(m.points, dtype=float).T
    if dim == 2 and points.shape[0] == 3:
        z = points[2]
        if np.ptp(z) > 1e-9 * max(np.ptp(points[:2], axis=1).max(), 1e-300):
            raise InputError(f"{source}: a triangle mesh that is not flat (z varies): 2D bodies lie in a plane z = "
                             f"constant; a surface in space is not a body")
        points = points[:2]
    if dim == 3 and points.shape[0] != 3:
        raise InputError(f"{source}: tetrahedra need 3 coordinates per node")
    cells = np.hstack([c.data.T for c in m.cells if c.type == body_type]).astype(np.int64)
    return make_body(points, cells, _groups(m, dim), source)


def _groups(m, dim: int) -> dict[str, Group]:
    """Named groups: gmsh physical groups (cell data ``gmsh:physical`` and the names in ``field_data``), else
    the file's cell sets."""
    out: dict[str, list[np.ndarray]] = {}
    kinds: dict[str, int] = {}
    phys = m.cell_data.get("gmsh:physical")
    if phys is not None:
        names = {(int(v[1]), int(v[0])): k for k, v in (m.field_data or {}).items() if np.size(v) >= 2}
        for block, tags in zip(m.cells, phys):
            if block.type not in P1_TYPES:
                continue
            d = P1_TYPES[block.type][0]
            for tag in np.unique(tags):
                name = names.get((d, int(tag)), str(int(tag)))
                out.setdefault(name, []).append(block.data[np.asarray(tags) == tag].T)
                kinds[name] = d
    else:
        for name, sets in (m.cell_sets or {}).items():
            if name.startswith("gmsh:"):
                continue
            for block, idx in zip(m.cells, sets):
                if block.type in P1_TYPES and idx is not None and np.size(idx):
                    out.setdefault(name, []).append(block.data[np.asarray(idx, dtype=np.int64)].T)
                    kinds[name] = P1_TYPES[block.type][0]
    groups = {}
    for name, blocks in out.items():
        if len({b.shape[0] for b in blocks}) != 1:
            continue                                  # a group of several dimensions: not usable as one
        groups[name] = Group(kinds[name], np.hstack(blocks).astype(np.int64))
    return groups
