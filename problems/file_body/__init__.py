"""Bodies from mesh and CAD files, 2D (triangles) and 3D (tetrahedra), with defects as named groups.

A scene file with ``mesh_file`` or ``geometry_file`` (and no ``problem``) is a ``file_body`` scene; a relative
path is read from the scene file's folder. Keys:

* ``mesh_file = "part.msh"``: gmsh MSH 2 or 4, or any mesh meshio reads with cell sets (:mod:`.read`); or
  ``geometry_file = "part.geo"`` (``.step``, ``.brep``) meshed by gmsh with ``mesh_size`` and ``tip_size``
  (:mod:`.geometry`). One of the two. ``dim`` (0: the file's) must match the file when given.
* ``[[defects]]`` tables ``{group, delta, face_pressure}``: ``group`` names a curve (2D) or surface (3D) of the
  file embedded in the body; nodes on both sides of it are doubled, its tips/front inside the body are not,
  its mouth on the boundary is (an edge crack) (:mod:`.cut`). ``defects = []`` or none: an uncracked body.
* supports and loads (required: there is no default load): ``[[boundary]]`` tables ``{group, support,
  traction}``, ``body_force``, ``remote_stress`` (on the outer boundary), ``load_scale`` (:mod:`.supports`).
* ``E``, ``nu``, ``plane`` (2D: ``strain`` or ``stress``), ``delta`` (each defect's default).

The QP is the box scenes' (:mod:`dualfem.problems.thin_defect`, :mod:`dualfem.problems.three_d`): the same
stiffness assembly, the same interface term and B (:mod:`dualfem.problems._interface`), the same typed parts
(``geometry``: nodes, triangles or tetrahedra, node_dofs; ``interface``: an InterfacePart with, in 2D, the
tangents, the arc length ``s`` and the tips as ``front``, in 3D the front and the defect triangles as ``faces``).
Units: those of the file's coordinates and of E.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from dualfem.core.elasticity import PLANES, lame
from dualfem.core.io import check_input_path
from dualfem.errors import InputError, check_int, check_open_interval, check_positive
from dualfem.numerics.linalg import freeze
from dualfem.problem import Problem
from dualfem.qp import QP, GeometryPart, MaterialPart, UnitsPart
from dualfem.registry import register_problem

from .. import _boundary as bd
from .._interface import delta_free_part, interface, local_unknowns, with_delta
from ..adaptive import Adaptive
from ..adaptive import check_keys as check_adaptive
from . import geometry as geo
from . import supports as sup
from .body import BodyMesh
from .cut import FileCut, cut, embedded
from .read import read_mesh

#: smallest delta * E / (body size) accepted (as the box scenes)
MIN_DELTA_E_OVER_L = 1e-12
DEFECT_KEYS = ("group", "delta", "face_pressure")
#: the smallest tip_size, relative to the body's largest extent (the refinement around 3D fronts grows like 1/tip)
MIN_TIP_SIZE = 1e-4
_CACHE: dict[tuple, BodyMesh] = {}          # the last bodies read or meshed (a sweep re-validates its scene)


def _cached(key: tuple, make) -> BodyMesh:
    if key not in _CACHE:
        while len(_CACHE) >= 2:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = make()
    return _CACHE[key]


@register_problem
class FileBody(Adaptive, Problem):
    """An elastic body read from a mesh file or meshed from a geometry file, defects as named groups."""

    name = "file_body"
    description = "2D/3D elastic body from a mesh (.msh, meshio) or geometry (.geo, .step, .brep) file"
    dim = 2                      # a class needs one: the scene's own is the file's (size_estimate's third entry)
    claim_keys = ("mesh_file", "geometry_file")
    path_keys = ("mesh_file", "geometry_file")
    requires = ("meshio",)
    defaults = {
        "mesh_file": "",
        "geometry_file": "",
        "dim": 0,
        "delta": 1e-5,
        "E": 69000.0,
        "nu": 0.3,
        "plane": "strain",
        "load_scale": 1.0,
        "mesh_size": 0.0,
        "tip_size": 0.0,
        "defects": None,
        "boundary": (),
        "body_force": "",
        "remote_stress": "",
        "refine": "none",
        "target_error": None,
        "max_unknowns": None,
    }
    update_keys = ("delta", "load_scale", "boundary", "body_force", "remote_stress")

    # ------------------------------------------------------------ validation
    def validate(self) -> None:
        p = self.params
        p["delta"] = check_positive("delta", p["delta"])
        p["E"] = check_positive("E", p["E"])
        p["nu"] = check_open_interval("nu", p["nu"], -1.0, 0.5)
        p["mesh_size"] = check_positive("mesh_size", p["mesh_size"], allow_zero=True)
        p["tip_size"] = check_positive("tip_size", p["tip_size"], allow_zero=True)
        p["dim"] = check_int("dim", p["dim"], 0, 3)
        ls = p["load_scale"]
        if isinstance(ls, bool) or not isinstance(ls, (int, float)) or not np.isfinite(ls):
            raise InputError(f"load_scale must be a finite number, got {ls!r}")
        if p["plane"] not in PLANES:
            raise InputError(f"plane must be one of {', '.join(PLANES)}, got {p['plane']!r}")
        self._tables = self._defect_tables()
        self._path, self._kind = self._file()
        if self._kind == "mesh_file":
            self._body: BodyMesh | None = self._read()
            self._geo = None
            self._dim, groups = self._body.dim, {n: g.dim for n, g in self._body.groups.items()}
            lo, hi = self._body.points.min(axis=1), self._body.points.max(axis=1)
            self._box = tuple(float(x) for x in hi - lo)
        else:
            self._body = None
            self._geo = geo.inspect(self._path)
            self._dim, groups, self._box = self._geo.dim, self._geo.groups, self._geo.box
            self._check_count()
            tip, top = p["tip_size"], p["mesh_size"] or max(self._box)
            if tip and not MIN_TIP_SIZE * max(self._box) <= tip <= top:
                raise InputError(f"tip_size must be 0 or in [{MIN_TIP_SIZE * max(self._box):.3g}, {top:g}] "
                                 f"({MIN_TIP_SIZE:g} x the body's size, up to mesh_size), got {tip:g}")
        if self._kind == "mesh_file" and p["refine"] == "adaptive":
            raise InputError("refine = \"adaptive\" re-meshes the body with gmsh: it needs geometry_file (a "
                             "mesh_file cannot be re-meshed)")
        p["refine"], p["target_error"], p["max_unknowns"] = check_adaptive(
            p["refine"], p["target_error"], p["max_unknowns"], "gmsh")
        if p["dim"] not in (0, self._dim):
            raise InputError(f"dim = {p['dim']} but {self._kind} {self._path.name!r} holds a {self._dim}D body")
        self._check_groups(groups)
        self._loads = sup.parse(p, self._dim, self._box)
        for k, s in enumerate(self._loads.sides):
            self._check_group(groups, s.group, f"boundary[{k}].group", self._dim - 1)
        size = max(self._box)
        self._pressure = []
        for i, t in enumerate(self._tables):
            if t["delta"] * p["E"] / size < MIN_DELTA_E_OVER_L:
                raise InputError(f"delta of defect {i} ({t['delta']:g}) is too small for E = {p['E']:g} and the "
                                 f"body size {size:g}: delta * E / size must be >= {MIN_DELTA_E_OVER_L:g}")
            fp = t.get("face_pressure")
            self._pressure.append(None if fp is None else
                                  bd.parse_scalar(fp, f"defects[{i}].face_pressure", self._dim, self._box))

    def _defect_tables(self) -> list[dict]:
        tables = self.params["defects"]
        if isinstance(tables, str) and tables.strip()[:1] in "[{":
            try:
                tables = json.loads(tables)
            except ValueError:
                raise InputError(f"defects must be a list of tables (from --set: JSON), got {tables!r}") from None
        if tables is None:
            return []
        if not isinstance(tables, (list, tuple)):
            raise InputError(f"defects must be a list of [[defects]] tables with group = \"...\", got {tables!r}")
        out = []
        for i, t in enumerate(tables):
            if not isinstance(t, dict):
                raise InputError(f"defects[{i}] must be a table with group (and delta, face_pressure), got {t!r}")
            unknown = sorted(set(t) - set(DEFECT_KEYS))
            if unknown:
                raise InputError(f"defects[{i}]: unknown key {unknown[0]!r} for a body from a file (its defects are "
                                 f"groups of the file); allowed: {', '.join(DEFECT_KEYS)}")
            if not isinstance(t.get("group"), str) or not t["group"]:
                raise InputError(f"defects[{i}].group must name a curve (2D) or surface (3D) of the file, got "
                                 f"{t.get('group')!r}")
            if any(o["group"] == t["group"] for o in out):
                raise InputError(f"defects[{i}].group = {t['group']!r} is given twice")
            delta = check_positive(f"defects[{i}].delta", t.get("delta", self.params["delta"]))
            out.append({**t, "delta": delta})
        return out

    def _file(self) -> tuple[Path, str]:
        p = self.params
        given = [k for k in ("mesh_file", "geometry_file") if isinstance(p[k], str) and p[k].strip()]
        for k in ("mesh_file", "geometry_file"):
            if not isinstance(p[k], str):
                raise InputError(f"{k} must be a path (a string), got {p[k]!r}")
        if len(given) != 1:
            raise InputError("give one of mesh_file (a mesh: .msh, or any format meshio reads) or geometry_file "
                             f"(.geo, .step, .brep), {'not both' if given else 'neither is given'}")
        key = given[0]
        path = check_input_path(Path(p[key]).expanduser(), key)
        if key == "geometry_file" and path.suffix.lower() not in geo.SUFFIXES:
            raise InputError(f"geometry_file {path.name!r}: the suffix must be one of {', '.join(geo.SUFFIXES)} "
                             f"(a mesh is a mesh_file)")
        return path, key

    def _read(self) -> BodyMesh:
        st = os.stat(self._path)
        return _cached(("mesh", str(self._path.resolve()), st.st_mtime_ns, st.st_size),
                       lambda: read_mesh(self._path))

    def _check_count(self) -> None:
        """Refuse a geometry whose mesh would exceed the box scenes' limits (estimate before meshing)."""
        from dualfem.problems._defect_geometry import MAX_TRIANGLES
        from dualfem.problems.three_d.mesh import MAX_TETRAHEDRA

        count, h = geo.element_estimate(self._geo, self.params["mesh_size"])
        limit = MAX_TRIANGLES if self._geo.dim == 2 else MAX_TETRAHEDRA
        if count > limit:
            raise InputError(f"geometry_file {self._path.name!r} with element size {h:g} gives about {count:.3g} "
                             f"{'triangles' if self._geo.dim == 2 else 'tetrahedra'} (limit {limit:,}) in its "
                             f"{' x '.join(f'{b:g}' for b in self._box)} bounding box: increase mesh_size")

    def _check_group(self, groups: dict[str, int], name: str, key: str, want: int) -> None:
        if name not in groups:
            src = f"{self._kind} {self._path.name!r}"
            listed = ", ".join(f"{n!r} ({d}D)" for n, d in sorted(groups.items())) or "none"
            raise InputError(f"{key} = {name!r} is not a group of {src}; its groups: {listed}")
        if groups[name] != want:
            raise InputError(f"{key} = {name!r} is a group of {groups[name]}D elements; a "
                             f"{'curve (1D)' if want == 1 else 'surface (2D)'} is needed here")

    def _check_groups(self, groups: dict[str, int]) -> None:
        for i, t in enumerate(self._tables):
            self._check_group(groups, t["group"], f"defects[{i}].group", self._dim - 1)

    def size_estimate(self) -> tuple[int, str, int]:
        """(unknowns, label, dim) before assembly: from the nodes read, or from the geometry's element estimate."""
        if self._body is not None:
            n = self._body.points.shape[1]
            return int(1.05 * self._dim * n) + 3, f"{self._path.name}: {n:,} nodes", self._dim
        count, h = geo.element_estimate(self._geo, self.params["mesh_size"])
        nodes = count / (2 if self._dim == 2 else 5.5)
        return int(1.2 * self._dim * nodes) + 3, f"{self._path.name} meshed at size {h:g}", self._dim

    def with_params(self, **changes) -> FileBody:
        new = type(self)(**{**self.params, **changes})
        if set(changes) <= set(self.update_keys) and new._support_key() == self._support_key():
            new.shared = self.shared
        return new

    @property
    def mesh_size(self) -> float:
        """The largest element size: ``mesh_size``, or (0) the body's largest side."""
        return float(self.params["mesh_size"] or max(self._box))

    def extent(self) -> float:
        return float(max(self._box))

    def _support_key(self) -> tuple:
        return tuple(sorted((s.group, s.support) for s in self._loads.sides if s.support != "free"))

    # ------------------------------------------------------------------ mesh
    def body(self) -> BodyMesh:
        """The uncut body mesh (read, or meshed once per instance family)."""
        if self._body is not None:
            return self._body
        data = self.shared.data
        if data.get("body") is None and self._size_view is not None:
            p = self.params
            data["body"] = geo.mesh_geometry(self._path, p["mesh_size"], p["tip_size"],
                                             [t["group"] for t in self._tables], self._size_view)
        if data.get("body") is None:
            p = self.params
            st = os.stat(self._path)
            key = ("geo", str(self._path.resolve()), st.st_mtime_ns, p["mesh_size"], p["tip_size"],
                   tuple(t["group"] for t in self._tables))
            data["body"] = _cached(key, lambda: geo.mesh_geometry(self._path, p["mesh_size"], p["tip_size"],
                                                                  [t["group"] for t in self._tables]))
        return data["body"]

    def cut(self) -> tuple[FileCut, sup.Boundary]:
        """(the doubled mesh, the uncut mesh's boundary facets), once per :class:`~dualfem.core.problem.Shared`."""
        data = self.shared.data
        self.adapt_mesh()
        if data.get("cut") is None:
            body = self.body()
            facets = []
            for i, t in enumerate(self._tables):
                g = body.group(t["group"], f"defects[{i}].group")
                what = f"defects[{i}] (group {t['group']!r})"
                embedded(body, g.elements if g.dim == body.dim - 1 else np.zeros((body.dim, 0), np.int64), what)
                facets.append(g.elements)
            data["cut"] = (cut(body, facets, [t["group"] for t in self._tables]), sup.boundary(body))
        return data["cut"]

    # -------------------------------------------------------------- assembly
    def _delta_free(self) -> dict:
        a = self.shared.data.get("delta_free")
        if a is not None:
            return a
        p = self.params
        c, b = self.cut()
        body = self.body()
        mask = sup.support_mask(self._loads, body, b, c.points, c.cells)
        on_defect = np.zeros(c.points.shape[1], bool)
        on_defect[np.r_[c.lower, c.upper]] = True
        if mask[:, on_defect].any():
            raise InputError("a supported group touches a defect's doubled nodes (an edge crack's mouth): the "
                             "defect's faces must be free there; shorten the support or the crack")
        free = bd.free_modes_of(mask, c.points)
        mask = bd.complete_supports(mask, c.points, exclude=on_defect)
        node_dofs = bd.dof_numbering(mask)
        n = int(node_dofs.max()) + 1
        lam, mu = lame(p["E"], p["nu"], p["plane"] if self._dim == 2 else "strain")
        if self._dim == 2:
            from dualfem.problems.thin_defect.assemble import stiffness
            extra = {"tangents": c.tangents.T[:, None, :], "front": c.front, "front_id": c.front_id, "s": c.s}
        else:
            from dualfem.problems.three_d.assemble import stiffness
            extra = {"front": c.front, "front_id": c.front_id, "faces": c.faces.T}
        K_el = stiffness(c.points, c.cells, lam, mu, node_dofs, n)
        local = local_unknowns(node_dofs, c.lower, c.upper)
        part = delta_free_part(node_dofs, c, np.ascontiguousarray(c.normals.T), **extra)
        a = {"n": n, "K_el": K_el, "local": local, "node_dofs": node_dofs, "interface": part, "free_modes": free}
        freeze(K_el.data, K_el.indices, K_el.indptr, local, node_dofs)
        self.shared.data["delta_free"] = a
        self.shared.assemblies += 1
        return a

    def nodal_load(self) -> np.ndarray:
        """Nodal forces (dim, n_nodes): the groups' tractions, remote stress, body force, face pressures, times
        ``load_scale``; InputError when the supports leave rigid motions free and the loads do not balance."""
        c, b = self.cut()
        scale = float(self.params["load_scale"])
        F = sup.nodal_forces(self._loads, self.body(), b, c.points, c.cells, scale)
        if any(f is not None for f in self._pressure):
            pressure = np.zeros(c.lower.size)
            for k, f in enumerate(self._pressure):
                j = np.flatnonzero(c.defect_id == k)
                if f is not None and j.size:
                    with np.errstate(all="ignore"):
                        pressure[j] = f(c.points[:, c.lower[j]])[0]
            if not np.all(np.isfinite(pressure)):
                raise InputError("face_pressure gives NaN or infinite values on a defect; it must be finite there")
            F += bd.face_pressure_forces(c.upper, c.lower, c.normals, c.weights, scale * pressure, c.points.shape[1])
        bd.check_balance_of(self._delta_free()["free_modes"], c.points, F)
        return F

    def build(self) -> QP:
        """K (elastic + interface), F (the loads), B (normal jumps) of the body; the delta-free part is reused
        across :meth:`with_params` for new ``update_keys`` with the same supports."""
        p = self.params
        a = self._delta_free()
        c, _ = self.cut()
        iface, coef = with_delta(a["interface"], [t["delta"] for t in self._tables])
        K_par, B, J = interface(a["node_dofs"], c.lower, c.upper, iface.normals.T, coef, a["n"])
        K = (a["K_el"] + K_par).tocsc()
        nd = a["node_dofs"]
        Fn = self.nodal_load()
        F = np.zeros(a["n"])
        F[nd[nd >= 0]] = Fn[nd >= 0]
        self.jump_operators = J
        params = {k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in p.items()
                  if k not in ("defects", "boundary", "body_force", "remote_stress")}
        self.later_params(params, p, FileBody.defaults)
        params["defects"] = "; ".join(f"{t['group']} delta {t['delta']:g}" for t in self._tables)
        params["loads"] = self._loads.label()
        geometry = GeometryPart(self._dim, c.points, c.cells, nd)
        return QP(K=K, F=F, B=B, weights=iface.weights.copy(), K_fixed=a["K_el"], local_dofs=a["local"],
                  name=f"file_body[{self._path.name}]", params=params, geometry=geometry,
                  interface=_with_weights(iface),
                  units=UnitsPart(E=float(p["E"]), length=float(max(self._box))),
                  material=MaterialPart(float(p["E"]), float(p["nu"]),
                                        str(p["plane"]) if self._dim == 2 else "strain"))


def _with_weights(iface):
    """The interface part with its own copy of the weights (each QP its own, as the QP's ``weights``)."""
    import dataclasses

    return dataclasses.replace(iface, weights=iface.weights.copy())
