"""ParaView output of a thin-defect solution (VTU and XDMF via meshio).

One unstructured grid holds

* the points: every mesh node, doubled defect nodes included (so the crack opens when the
  mesh is warped), with z = 0;
* point data ``displacement`` (3 components, z = 0: use *Warp By Vector*), and the nodal
  defect fields ``jump_normal``, ``jump_tangent``, ``pressure`` (``pressure`` only when the
  solution has multipliers): 0 away from the defects (``defect_id`` -1 tells those nodes apart), at a
  defect node both copies carry the same value, the tips carry jump 0 and pressure 0 (no constraint
  acts there: the model's closed-form value); no point field holds NaN;
* point data ``defect_id`` (the defect a node lies on, counted from 0 in the order of the
  scene's ``[[defects]]``; -1 elsewhere) and ``normal`` (3 components: the defect's unit normal
  nu at its nodes, pointing to the "+" face, the tips taking their neighbour's; 0 elsewhere:
  use *Glyph* to draw them);
* two cell blocks: the triangles, then the defects' ``line`` cells, defect by defect: its
  upper-face edges followed by its lower-face edges (ordered along it from its first tip); on a P2 QP
  (``geometry.element`` ``"P2"`` or ``"P2-quarter-point"``) the triangles are quadratic ``triangle6`` cells
  (vertices, then the mid-edge nodes, quarter-point nodes where they are:
  :func:`dualfem.numerics.p2.quadratic_cells`), so ParaView interpolates the P2 displacement, and the
  defect lines join consecutive P2 nodes (vertex and mid-edge) along the defect;
* cell data ``von_mises``, ``s11``, ``s22``, ``s12``, ``s33`` (constant per P1 triangle, units
  of E; on P2 those of the vertex values' linear interpolant, a coarser view; NaN on the line
  cells), ``jump_normal``, ``jump_tangent``, ``pressure`` on the line
  cells (mean of the edge's two end nodes, ignoring the tips' undefined pressure; NaN on the
  triangles), ``defect_id`` (-1 on the triangles) and ``face`` (0 triangle, +1 upper face,
  -1 lower face) to threshold them.

Files are written atomically (:func:`dualfem.core.io.atomic_write`). XDMF needs h5py (the
``xdmf`` extra); its heavy data go to a ``.h5`` file next to the ``.xdmf``.
"""
from __future__ import annotations

import importlib.util
import os
import tempfile
from pathlib import Path

import numpy as np

from dualfem.core.errors import InputError, MissingDependency
from dualfem.core.io import atomic_write, check_output_path
from dualfem.core.qpfile import check_maps
from dualfem.post.fields import Post, defect_stretches

SUFFIXES = {"vtu": (".vtu",), "xdmf": (".xdmf", ".xmf")}


def check_path(path: str | os.PathLike, kind: str) -> Path:
    """Validate an output file name of ``kind`` ('vtu' or 'xdmf'); raise InputError /
    MissingDependency before any slow work."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES[kind]:
        opt = "--vtk" if kind == "vtu" else "--xdmf"
        raise InputError(f"{opt} must name a {' or '.join(SUFFIXES[kind])} file, got {str(path)!r}")
    opt = "--vtk" if kind == "vtu" else "--xdmf"
    check_output_path(path, opt)
    h5 = path.with_suffix(".h5")
    if kind == "xdmf" and h5.exists() and not path.exists():
        raise InputError(f"--xdmf {str(path)!r} would overwrite {str(h5)!r}, which is not the data file of an "
                         f"earlier {path.name}: move it or choose another name")
    if importlib.util.find_spec("meshio") is None:
        raise MissingDependency("writing VTK/XDMF needs meshio: pip install meshio")
    if kind == "xdmf" and importlib.util.find_spec("h5py") is None:
        raise MissingDependency("writing XDMF needs h5py: pip install 'dualfem[xdmf]'")
    return path


def check_qp(qp) -> None:
    """Everything the writer reads, validated (InputError naming the array; never an IndexError later):
    a 2-D mesh (``qp.geometry``: nodes (2, n_nodes), triangles, node_dofs with one row per displacement
    component) and the defect maps (:func:`dualfem.core.qpfile.check_maps`)."""
    g = getattr(qp, "geometry", None)
    if g is None:
        raise InputError("--vtk/--xdmf need the mesh of the QP (qp.geometry: nodes, cells, node_dofs): "
                         "solve a scene, or a file exported with its map_ arrays")
    if (g.dim, g.cells.shape[0]) not in ((2, 3), (3, 4), (3, 10)):
        raise InputError(f"--vtk/--xdmf write triangle (2-D) or tetrahedron (3-D, 4 or 10 nodes) meshes; the QP's "
                         f"geometry has "
                         f"dim {g.dim} and cells of {g.cells.shape[0]} nodes")
    if g.node_dofs.shape[0] != g.dim:
        raise InputError(f"--vtk/--xdmf write {g.dim}-D displacements: geometry.node_dofs (map_node_dofs) must have "
                         f"{g.dim} rows (one per component), got shape {g.node_dofs.shape}")
    maps = qp.maps.legacy() if hasattr(qp.maps, "legacy") else qp.maps
    check_maps(maps, qp.m, g.nodes.shape[1], "the QP", dim=g.dim)
    if "defect_upper" in maps and not ("defect_lower" in maps and ("defect_s" in maps or g.dim == 3)):
        raise InputError("the defect maps of the QP need defect_upper, defect_lower and defect_s together")


def to_meshio(qp, sol=None, *, post: Post | None = None, sif=None):
    """The meshio.Mesh described in the module docstring (``sif``: a :class:`dualfem.post.sif.StressIntensity`
    of a 3D solution, written as front point fields; None: none)."""
    import meshio

    check_qp(qp)
    if qp.geometry.dim == 3:
        from dualfem.post.vtk3d import to_meshio3d

        return to_meshio3d(qp, sol, sif=sif)
    p = post if post is not None else Post(qp, sol)
    nodes = p.nodes
    npts = nodes.shape[1]
    points = np.zeros((npts, 3))
    points[:, :2] = nodes.T
    disp = np.zeros((npts, 3))
    disp[:, :2] = p.displacement
    ntri = p.triangles.shape[1]
    cells = [_triangle_cells(qp.geometry, p.triangles)]
    point_data = {"displacement": disp}
    st = p.stress
    cell_data = {k: [np.asarray(st[k], dtype=float)] for k in ("von_mises", "s11", "s22", "s12", "s33")}
    face = [np.zeros(ntri, dtype=np.int32)]
    defect_keys = ("jump_normal", "jump_tangent", "pressure")
    if qp.interface is not None and qp.m:       # (defects = []: an uncracked body, no defect cells)
        d = p.defect
        nodal = {"jump_normal": d["jump_normal"], "jump_tangent": d["jump_tangent"],
                 "pressure": d.get("pressure", np.full(d["s"].size, np.nan))}
        for k, v in nodal.items():
            if k == "pressure" and "pressure" not in d:
                continue
            point_data[k] = _point_field(npts, d["lower"], d["upper"], np.where(d["interior"], v, 0.0))
        point_data["defect_id"] = np.full(npts, -1, dtype=np.int32)
        point_data["normal"] = np.zeros((npts, 3))
        for ids in (d["lower"], d["upper"]):
            point_data["defect_id"][ids] = d["defect_id"]
            point_data["normal"][ids, :2] = d["normal"]
        edges, edge_vals, edge_id, face_e = _defect_edges(d, nodal)
        cells.append(("line", edges))
        for k in cell_data:
            cell_data[k].append(np.full(edges.shape[0], np.nan))
        face.append(face_e)
        for k in defect_keys:
            cell_data[k] = [np.full(ntri, np.nan), edge_vals[k]]
        cell_data["defect_id"] = [np.full(ntri, -1, dtype=np.int32), edge_id]
    cell_data["face"] = face
    return meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data)


def _triangle_cells(g, triangles: np.ndarray) -> tuple[str, np.ndarray]:
    """The triangle cell block: ``triangle`` (P1) or ``triangle6`` (P2: :func:`dualfem.numerics.p2.quadratic_cells`;
    InputError when the QP's nodes are not its P2 nodes)."""
    if getattr(g, "element", "P1") == "P1":
        return "triangle", triangles.T.astype(np.int64)
    from dualfem.numerics.p2 import quadratic_cells

    try:
        return "triangle6", quadratic_cells(g.nodes, triangles).T
    except ValueError as exc:
        raise InputError(f"--vtk/--xdmf: element = {g.element!r}: {exc}") from None


def _defect_edges(d: dict, nodal: dict) -> tuple[np.ndarray, dict, np.ndarray, np.ndarray]:
    """Line cells of every defect (its upper-face edges, then its lower-face edges, defect by
    defect), the nodal values averaged per edge (ignoring NaN), the defect id and face per edge."""

    edges, vals, ids, face = [], {k: [] for k in nodal}, [], []
    for idx in defect_stretches(d):
        k_def = int(d["defect_id"][idx[0]])
        for ends, sign in ((d["upper"][idx], 1), (d["lower"][idx], -1)):
            edges.append(np.stack([ends[:-1], ends[1:]], axis=1))
            ids.append(np.full(idx.size - 1, k_def, dtype=np.int32))
            face.append(np.full(idx.size - 1, sign, dtype=np.int32))
            for k, v in nodal.items():
                vals[k].append(finite_mean(np.stack([v[idx][:-1], v[idx][1:]])))
    return (np.vstack(edges).astype(np.int64), {k: np.concatenate(v) for k, v in vals.items()},
            np.concatenate(ids), np.concatenate(face))


def _point_field(npts: int, lower: np.ndarray, upper: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A defect field as point data: ``v`` on both copies of each defect node, 0 at every other node."""
    arr = np.zeros(npts)
    arr[lower] = v
    arr[upper] = v
    return arr


def finite_mean(a: np.ndarray) -> np.ndarray:
    """Column means of ``a`` over its finite entries (NaN where a column has none): a cell's value from
    its nodes' (an undefined pressure ignored)."""
    with np.errstate(invalid="ignore"):
        cnt = np.sum(np.isfinite(a), axis=0)
        return np.where(cnt > 0, np.nansum(a, axis=0) / np.maximum(cnt, 1), np.nan)


def write_vtu(path: str | os.PathLike, qp, sol=None, *, post: Post | None = None, sif=None) -> Path:
    """Write the solution as a VTU file (binary, zlib-compressed), atomically."""
    import meshio

    path = check_path(path, "vtu")
    mesh = to_meshio(qp, sol, post=post, sif=sif)
    atomic_write(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
    return path


def write_xdmf(path: str | os.PathLike, qp, sol=None, *, post: Post | None = None, sif=None) -> Path:
    """Write the solution as XDMF + HDF5 (``<name>.h5`` beside it).

    Both files are first written under their final names in a temporary directory next to
    ``path`` and then renamed into place, the ``.h5`` first: a reader never sees an ``.xdmf``
    whose data file is missing or incomplete.
    """
    import meshio

    path = check_path(path, "xdmf")
    mesh = to_meshio(qp, sol, post=post, sif=sif)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        tmp = Path(tmpdir) / path.name
        meshio.write(str(tmp), mesh, file_format="xdmf")
        h5 = tmp.with_suffix(".h5")
        if h5.exists():
            os.replace(h5, path.with_suffix(".h5"))
        os.replace(tmp, path)
    finally:
        for f in Path(tmpdir).glob("*"):
            f.unlink()
        os.rmdir(tmpdir)
    return path


def write_outputs(qp, sol, *, vtk: str | None = None, xdmf: str | None = None, sif=None) -> list[Path]:
    """Write the requested files (post-processing is computed once and shared; ``sif``: the stress intensity
    factors of a 3D solution, written as front point fields, when ``dualfem solve --sif`` computed them)."""
    if not (vtk or xdmf):
        return []
    if sol.x is None:
        raise InputError(f"no solution to write (solver status {sol.status}: {sol.message})")
    check_qp(qp)
    post = Post(qp, sol) if qp.geometry.dim == 2 else None
    out = []
    if vtk:
        out.append(write_vtu(vtk, qp, sol, post=post, sif=sif))
    if xdmf:
        out.append(write_xdmf(xdmf, qp, sol, post=post, sif=sif))
    return out
