"""3D elastic bodies with defect surfaces as a QP (the thin-defect model of the 2D scenes, in 3D).

Body: the box (0, width) x (0, depth) x (0, height), isotropic linear elasticity (E, nu; no plane
assumption: the 3D law itself), P1 tetrahedra of a gmsh mesh (``mesh = "gmsh"``, the only mesh in
3D; ``mesh_size``, 0 = min(width, depth, height) / N; ``tip_size`` at the defect fronts, 0 =
mesh_size; ``surface_size`` on the defect surfaces, 0 = no refinement there) with every defect
surface embedded (:mod:`.mesh`). Defects: ``[[defects]]`` tables with ``shape`` = ``disk``,
``ellipse``, ``polygon`` or ``cap`` and an optional per-defect ``delta`` (keys and normals:
:mod:`.geometry`); without tables the disk of radius 0.25 x min(width, depth) at the centre,
normal +z; ``defects = []``: no defect at all, an uncracked box (a QP without constraints);
``defects_file``: the defects in a CSV (disks, ellipses) or JSON file, relative to the scene file
(:mod:`dualfem.problems.defects_file`). How many defects a scene holds is bounded by the mesh they need
(the tetrahedron estimate, checked before meshing), not by a count. ``size_growth`` (in [0.01, 1],
default 0.3): the slope of the element size away from the fronts and surfaces.
Nodes strictly inside a defect are doubled, its front is not (:mod:`.cut`). Energy, one term per defect d:

    Pi(v) = 1/2 a(v, v) - (f, v) + sum_d 1/(2 delta_d) int_gamma_d |[v]|^2,   [v_nu] >= 0 on every gamma_d,

discretised with nodal areas w_j (lumped): K = K_el + sum_j (w_j / delta_j) |u_j^+ - u_j^-|^2 (all
three components), B row j = nu_j . (u_j^+ - u_j^-), the "+" copy on the side nu_j points to.

Supports and loads: without the keys ``boundary``, ``body_force``, ``remote_stress`` the bottom face
z = 0 is clamped and the traction ``load`` x ``load_scale`` acts on the top face z = height
(:mod:`.supports`); with any of them, those keys say it all (:mod:`dualfem.problems._boundary`:
``[[boundary]]`` tables with ``side`` = left, right, front, back, bottom, top, ``support`` and/or
``traction``; ``body_force``; ``remote_stress`` (3 x 3): sigma.n on every side without a support, and
without any support only the rigid-body motions are removed at six components of extreme nodes), all
times ``load_scale``, and ``load`` must keep its default. A scene whose only load is a defect's
``face_pressure`` must name its model: those keys, or ``load`` for the legacy one (docs/loads.md).
A defect's ``face_pressure`` (a number or an expression in x, y, z) pushes both of its faces apart.
``rotate_deg`` / ``rotate_axis``: a rigid rotation of the
whole scene (body, defects, loads, supports) about the box's centre, counter-clockwise about the
axis (right-hand rule); the mesh is made in the reference frame and rotated.

The QP: ``geometry = GeometryPart(3, nodes (3, n_nodes), tetrahedra (4, n_tets), node_dofs (3,
n_nodes))``; ``material = MaterialPart(E, nu, "strain")`` (3D elasticity is plane strain's law
without the reduction: ``plane`` means nothing in 3D and is not a scene key); ``interface`` (an
:class:`~dualfem.core.parts.InterfacePart`): ``upper``/``lower`` (m,) node ids of the "+" / "-" copies of
constrained node j (row j of B), ``defect_id`` (m,), ``normals`` (m, 3) unit "+" normals, ``front`` (k,)
the front nodes of every defect and ``front_id`` (k,) their defects, ``faces``, ``delta``.
"""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from dualfem.core.elasticity import lame
from dualfem.errors import InputError, check_int, check_open_interval, check_positive
from dualfem.numerics.linalg import freeze
from dualfem.problem import Problem
from dualfem.qp import QP, GeometryPart, MaterialPart, UnitsPart
from dualfem.registry import register_problem

from .. import _boundary as bd
from .. import _friction_keys as fk
from .._defect_geometry import check_growth
from .._interface import delta_free_part, interface, local_unknowns, with_delta
from ..adaptive import Adaptive
from ..adaptive import check_keys as check_adaptive
from ..defects_file import file_or_tables
from ..loads import check_load_model
from . import quadratic as p2
from .assemble import free_dofs, stiffness
from .cut import Cut3, cut
from .geometry import Surface, check_apart, parse_defects
from .mesh import check_size, estimate_tetrahedra, mesh_box
from .rotation import rotation_matrix
from .supports import face_on, resolve_load, traction_forces

#: smallest delta * E / max(width, depth, height) accepted (as in 2D: below it a defect is glued)
MIN_DELTA_E_OVER_L = 1e-12
MESHES = ("gmsh",)


def _vector3(key: str, value) -> np.ndarray:
    if isinstance(value, str):
        try:
            value = [float(s) for s in value.strip().strip("[]()").replace(" ", ",").split(",") if s]
        except ValueError:
            raise InputError(f"{key} must be 3 numbers [x, y, z], got {value!r}") from None
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3 \
            or any(isinstance(c, bool) for c in value):
        raise InputError(f"{key} must be 3 numbers [x, y, z], got {value!r}")
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{key} must be 3 numbers [x, y, z], got {value!r}") from None
    if not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise InputError(f"{key} must be a finite non-zero vector [x, y, z], got {value!r}")
    return v


@register_problem
class ThreeD(Adaptive, Problem):
    """Elastic box with defect surfaces (disks, ellipses, polygons, spherical caps), P1 tetrahedra (gmsh)."""

    name = "three_d"
    description = "3D elastic box with defect surfaces (disk, ellipse, polygon, spherical cap), gmsh tetrahedra"
    dim = 3
    scene_default = True        # a scene file with dim = 3 naming no problem is a three_d scene
    requires = ("gmsh",)
    extra = "gmsh"
    defaults = {
        "dim": 3,
        "N": 10,
        "delta": 1e-5,
        "E": 69000.0,
        "nu": 0.3,
        "load": "f2",
        "load_scale": 1.0,
        "width": 1.0,
        "depth": 1.0,
        "height": 1.0,
        "mesh": "gmsh",
        "mesh_size": 0.0,
        "tip_size": 0.0,
        "surface_size": 0.0,
        "rotate_deg": 0.0,
        "rotate_axis": (0.0, 0.0, 1.0),
        "defects": None,
        "boundary": (),
        "body_force": "",
        "remote_stress": "",
        "defects_file": "",
        "size_growth": 0.3,
        "refine": "none",
        "target_error": None,
        "max_unknowns": None,
        "element": "P1",
        **fk.DEFAULTS,
    }
    #: scene keys naming files, relative to the scene file (:attr:`dualfem.problem.Problem.path_keys`)
    path_keys = ("defects_file",)
    presets = {"three_d": {}}
    #: keys a sweep changes without re-meshing (Workspace.update, with_params): the loads change F only, the
    #: supports (``boundary``'s fixed sides) the elastic stiffness too (:meth:`with_params`)
    update_keys = ("delta", "load", "load_scale", "boundary", "body_force", "remote_stress")
    #: gmsh options over :mod:`.mesh`'s fixed ones (a subclass may choose another algorithm)
    gmsh_options: dict = {}

    def _support_key(self) -> tuple | None:
        """What the fixed unknowns depend on beyond the mesh: None (the legacy bottom clamp) or the supports."""
        return None if self._loads is None else \
            tuple(sorted((s.side, s.support) for s in self._loads.sides if s.support != "free"))

    def with_params(self, **changes) -> ThreeD:
        """This scene with ``changes``. Only :attr:`update_keys` changed: the mesh and the cut are reused, and
        with the same supports also the delta-free stiffness (only F and the delta term change); other
        supports re-assemble the stiffness on the same mesh. Any other key starts afresh."""
        new = type(self)(**{**self.params, **changes})
        if set(changes) <= set(self.update_keys):
            if new._support_key() == self._support_key():
                new.shared = self.shared
            else:
                new.shared.data.update({k: self.shared.data[k] for k in ("cut", "sides") if k in self.shared.data})
                new.shared.assemblies = self.shared.assemblies      # counted on: the next build assembles once more
        return new

    # ------------------------------------------------------------ validation
    def validate(self) -> None:
        p = self.params
        if p["dim"] != 3:
            raise InputError(f"dim must be 3 for the three_d problem (2D scenes: thin_defect), got {p['dim']!r}")
        p["N"] = check_int("N", p["N"], 2, 1000)
        p["delta"] = check_positive("delta", p["delta"])
        p["E"] = check_positive("E", p["E"])
        p["nu"] = check_open_interval("nu", p["nu"], -1.0, 0.5)
        for k in ("width", "depth", "height"):
            p[k] = check_positive(k, p[k])
        for k in ("load_scale", "rotate_deg"):
            if isinstance(p[k], bool) or not isinstance(p[k], (int, float)) or not math.isfinite(p[k]):
                raise InputError(f"{k} must be a finite number, got {p[k]!r}")
        if p["mesh"] not in MESHES:
            raise InputError(f"mesh must be {' or '.join(MESHES)} in 3D, got {p['mesh']!r}")
        p["mesh_size"] = check_positive("mesh_size", p["mesh_size"], allow_zero=True)
        p["tip_size"] = check_positive("tip_size", p["tip_size"], allow_zero=True)
        p["surface_size"] = check_positive("surface_size", p["surface_size"], allow_zero=True)
        p["size_growth"] = check_growth(p["size_growth"])
        p["refine"], p["target_error"], p["max_unknowns"] = check_adaptive(p["refine"], p["target_error"],
                                                                          p["max_unknowns"], "gmsh")
        self._axis = _vector3("rotate_axis", p["rotate_axis"])
        p["rotate_axis"] = tuple(float(c) for c in self._axis)
        box = self.box
        h = self.mesh_size
        if h > min(box):
            raise InputError(f"mesh_size must be in (0, min(width, depth, height)] = (0, {min(box):g}], got {h:g}")
        for k in ("tip_size", "surface_size"):
            if p[k] > h:
                raise InputError(f"{k} must be in [0, mesh_size] = [0, {h:g}], got {p[k]:g}")
        tables = p["defects"]
        if isinstance(tables, str) and tables.strip()[:1] in "[{":     # --set defects='[{"shape": ...}]' (JSON)
            try:
                tables = json.loads(tables)
            except ValueError:
                raise InputError(f"defects must be a list of tables (from --set: JSON), got {tables!r}") from None
        tables, where = file_or_tables(p["defects_file"], tables, 3)
        if tables is None:          # not given: the default disk; an empty list is an uncracked body
            tables = [{"shape": "disk", "center": [w / 2 for w in box], "normal": [0.0, 0.0, 1.0],
                       "radius": 0.25 * min(box[0], box[1])}]
        try:
            self._surfaces: list[Surface] = parse_defects(tables, p["delta"], box) \
                if not (isinstance(tables, (list, tuple)) and len(tables) == 0) else []
            check_size(box, h, self.tip_size, sum(s.front_length() for s in self._surfaces), self._size_label(),
                       self.surface_size, sum(s.area() for s in self._surfaces), p["size_growth"])
            check_apart(self._surfaces, min(self.tip_size or h, self.surface_size or h))
        except InputError as exc:
            raise InputError(f"{where}: {exc}" if where else str(exc)) from None
        for i, s in enumerate(self._surfaces):
            ratio = s.delta * p["E"] / max(box)
            if ratio < MIN_DELTA_E_OVER_L:
                raise InputError(f"delta of defect {i} ({s.delta:g}) is too small for E = {p['E']:g} and the box: "
                                 f"delta * E / max(width, depth, height) = {ratio:.1e} must be "
                                 f">= {MIN_DELTA_E_OVER_L:g}")
        self._friction = fk.parse_friction(p, [s.friction for s in self._surfaces], 3, box)
        p["element"] = p2.check_element(p["element"])
        if p["element"] == "P2" and p["refine"] == "adaptive":
            raise InputError("element = 'P2' with refine = 'adaptive': the estimator and the adaptive loop are P1 "
                             "only; use element = 'P1' or refine = 'none'")
        if p["element"] == "P2" and fk.frictional(self._friction):
            raise InputError("element = 'P2' with friction: the friction blocks are P1 only; use element = 'P1' or "
                             "drop the friction keys")
        self._loads = bd.parse_loads(p, 3)
        if self._loads is None:
            check_load_model(self, [s.face_pressure is not None for s in self._surfaces])
            with np.errstate(all="ignore"):
                self._traction = resolve_load(p["load"], p["width"])
        elif p["load"] != self.defaults["load"]:
            raise InputError(f"load ({p['load']!r}) is the top traction of a scene without boundary, body_force "
                             f"and remote_stress; with them give it as [[boundary]] side = 'top', traction = [...]")
        if p["rotate_deg"] and self._loads is not None and any(sd.support == "roller" for sd in self._loads.sides):
            raise InputError("rotate_deg with a roller support: the roller's normal would not be a coordinate axis "
                             "after the rotation; rotate a scene with clamped or free sides only")
        self._face_pressure = [None if s.face_pressure is None else
                               bd.parse_scalar(s.face_pressure, f"defects[{i}].face_pressure", 3, box)
                               for i, s in enumerate(self._surfaces)]

    @property
    def box(self) -> tuple[float, float, float]:
        p = self.params
        return float(p["width"]), float(p["depth"]), float(p["height"])

    @property
    def mesh_size(self) -> float:
        return float(self.params["mesh_size"] or min(self.box) / self.params["N"])

    @property
    def tip_size(self) -> float | None:
        t = float(self.params["tip_size"])
        return t if 0 < t < self.mesh_size else None

    @property
    def surface_size(self) -> float | None:
        t = float(self.params["surface_size"])
        return t if 0 < t < self.mesh_size else None

    def _size_label(self) -> str:
        p = self.params
        return f"mesh_size={self.mesh_size:g}" if p["mesh_size"] else \
            f"mesh_size=0 (min(width, depth, height)/N = {self.mesh_size:g} with N={p['N']})"

    def size_estimate(self) -> tuple[int, str]:
        """Unknowns before meshing: 3 per node, about 5.5 tetrahedra per node (20 % margin for the doubling);
        P2: about :data:`.quadratic.P2_NODES_PER_TET` nodes (vertices and edges) per tetrahedron; adaptive: the
        budget ``max_unknowns``."""
        if self.params["refine"] == "adaptive":
            return int(self.params["max_unknowns"]), f"refine='adaptive', max_unknowns={self.params['max_unknowns']}"
        tets = estimate_tetrahedra(self.box, self.mesh_size, self.tip_size,
                                   sum(s.front_length() for s in self._surfaces), self.surface_size,
                                   sum(s.area() for s in self._surfaces), self.params["size_growth"])
        if self.params["element"] == "P2":
            return int(3 * 1.2 * tets * p2.P2_NODES_PER_TET) + 3, f"element='P2', {self._size_label()}"
        return int(3 * 1.2 * tets / 5.5) + 3, self._size_label()

    # ------------------------------------------------------------------ mesh
    def rotation(self) -> np.ndarray:
        return rotation_matrix(self._axis, float(self.params["rotate_deg"]))

    def cut(self) -> tuple[Cut3, np.ndarray, np.ndarray]:
        """(the doubled mesh in the reference frame, its rotated node coordinates, the uncut mesh's top-face
        triangles); computed once per :class:`~dualfem.core.problem.Shared`."""
        shared = self.shared.data
        self.adapt_mesh()
        if shared.get("cut") is None:
            m = mesh_box(self.box, self._surfaces, self.mesh_size, self.tip_size, self.surface_size,
                         self.params["size_growth"], self._size_view, options=self.gmsh_options)
            c = cut(m.points, m.tets, m.faces, self._surfaces)
            from .assemble import boundary_faces

            tol = 1e-9 * max(self.box)
            top = face_on(m.points, boundary_faces(m.tets), 2, self.box[2], tol)
            centre = np.array(self.box)[:, None] / 2
            shared["cut"] = (c, self.rotation() @ (c.points - centre) + centre, top)
        return shared["cut"]

    def _delta_free(self) -> dict:
        """Mesh, DOF maps, K_el and maps: what depends neither on delta nor on the load (shared, read-only)."""
        a = self.shared.data.get("delta_free")
        if a is not None:
            return a
        p = self.params
        c, pts, _ = self.cut()
        if p["element"] == "P2":
            a = self._delta_free_p2(c)
            self.shared.data["delta_free"] = a
            self.shared.assemblies += 1
            return a
        if self._loads is None:
            fixed = np.zeros((3, pts.shape[1]), bool)
            fixed[:, np.abs(c.points[2]) <= 1e-9 * max(self.box)] = True      # the bottom face, reference frame
        else:
            fixed = bd.fixed_mask(self._loads, pts, self._sides())
        node_dofs = free_dofs(fixed)
        n = int(node_dofs.max()) + 1
        lam, mu = lame(p["E"], p["nu"], "strain")
        K_el = stiffness(pts, c.tets, lam, mu, node_dofs, n)
        local = local_unknowns(node_dofs, c.lower, c.upper)
        R = self.rotation()
        part = delta_free_part(node_dofs, c, np.ascontiguousarray((R @ c.normals).T), front=c.front,
                               front_id=c.front_id, faces=None if c.faces is None else c.faces.T)
        a = {"cut": c, "points": pts, "node_dofs": node_dofs, "n": n, "K_el": K_el, "local": local, "interface": part,
             "pairs": c, "cells": c.tets, "reference": c.points}
        freeze(K_el.data, K_el.indices, K_el.indptr, local, node_dofs, pts)
        self.shared.data["delta_free"] = a
        self.shared.assemblies += 1
        return a

    def _delta_free_p2(self, c: Cut3) -> dict:
        """:meth:`_delta_free` for ``element = "P2"`` (:mod:`.quadratic`): the P2 nodes (the cut's nodes, then
        one per edge), their supports, the P2 stiffness and the defect pairs at vertices and mid-edge nodes."""
        p = self.params
        q, pairs = p2.mesh(c)
        R = self.rotation()
        centre = np.array(self.box)[:, None] / 2
        pts = R @ (q.points - centre) + centre
        if self._loads is None:
            fixed = np.zeros((3, pts.shape[1]), bool)
            fixed[:, np.abs(q.points[2]) <= 1e-9 * max(self.box)] = True      # the bottom face, reference frame
        else:
            fixed = bd.fixed_mask(self._loads, pts, p2.sides(q, self._sides()))
        node_dofs = free_dofs(fixed)
        n = int(node_dofs.max()) + 1
        lam, mu = lame(p["E"], p["nu"], "strain")
        K_el = p2.stiffness(pts, q.cells, lam, mu, node_dofs, n)
        local = local_unknowns(node_dofs, pairs.lower, pairs.upper)
        part = delta_free_part(node_dofs, pairs, np.ascontiguousarray((R @ pairs.normals).T), front=c.front,
                               front_id=c.front_id, faces=None if c.faces is None else c.faces.T)
        freeze(K_el.data, K_el.indices, K_el.indptr, local, node_dofs, pts)
        return {"cut": c, "points": pts, "node_dofs": node_dofs, "n": n, "K_el": K_el, "local": local,
                "interface": part, "pairs": pairs, "cells": q.cells, "reference": q.points, "p2": q}

    def _load_label(self) -> str:
        """The load in the QP's name: the ``load`` key (legacy), else the general keys given."""
        p = self.params
        if self._loads is None:
            return p["load"] if isinstance(p["load"], str) else "custom"
        keys = [k for k in ("boundary", "body_force", "remote_stress") if p[k] not in ("", (), [], None)]
        return "+".join(keys)

    def _sides(self) -> dict[str, np.ndarray]:
        """The boundary triangles (3, k) of each side of the box (reference frame; computed once)."""
        shared = self.shared.data
        if shared.get("sides") is None:
            c, _, _ = self.cut()
            shared["sides"] = bd.box_sides(c.points, c.tets, self.box)
        return shared["sides"]

    def nodal_load(self) -> np.ndarray:
        """Nodal forces (3, n_nodes) in the rotated frame: the top traction ``load`` (legacy) or the keys of
        :mod:`dualfem.problems._boundary`, plus the defects' face pressures, times ``load_scale``."""
        c, pts, top = self.cut()
        scale = float(self.params["load_scale"])
        R = self.rotation()
        q = self._delta_free()["p2"] if self.params["element"] == "P2" else None
        sides = self._sides() if self._loads is None or q is None else p2.sides(q, self._sides())
        if q is not None:           # element = "P2"
            pts = self._delta_free()["points"]
            F = R @ (p2.top_forces(q, top, self._traction, scale) if self._loads is None else
                     p2.nodal_forces(self._loads, q, self._sides(), scale))
        elif self._loads is None:
            F = R @ traction_forces(c.points, top, self._traction, scale)
        else:
            F = R @ bd.nodal_forces(self._loads, c.points, c.tets, sides, scale)
        if any(f is not None for f in self._face_pressure):
            a = self._delta_free()
            pairs, ref = a["pairs"], a["reference"]
            normals = a["interface"].normals.T
            if q is not None:           # P2: the consistent forces (pressure-weighted integrals of the shape functions)
                weights, pressure = p2.face_pressure_weights(q, pairs, c.faces, self._face_pressure), 1.0
            else:
                weights, pressure = pairs.weights, np.zeros(pairs.lower.size)
                for k, f in enumerate(self._face_pressure):
                    j = np.flatnonzero(pairs.defect_id == k)
                    if f is not None and j.size:
                        pressure[j] = f(ref[:, pairs.lower[j]])[0]
            if not np.all(np.isfinite(pressure * weights)):
                raise InputError("face_pressure gives NaN or infinite values on a defect; it must be finite there")
            F += bd.face_pressure_forces(pairs.upper, pairs.lower, normals, weights, scale * pressure, pts.shape[1])
        if self._loads is not None:
            bd.check_balance(self._loads, pts, sides, F)
        return F

    def build(self) -> QP:
        """Assemble K (elastic + interface/delta), F (top traction), B (normal jumps); the delta-free
        part is reused across builds of this instance and those :meth:`with_params` derives for new
        ``update_keys``."""
        p = self.params
        a = self._delta_free()
        c = a["pairs"]
        iface, coef = with_delta(a["interface"], [s.delta for s in self._surfaces])
        K_par, B, _ = interface(a["node_dofs"], c.lower, c.upper, iface.normals.T, coef, a["n"])
        K = (a["K_el"] + K_par).tocsc()
        nd = a["node_dofs"]
        Fn = self.nodal_load()
        F = np.zeros(a["n"])
        F[nd[nd >= 0]] = Fn[nd >= 0]
        params = {k: (v if isinstance(v, (int, float, str)) else str(np.asarray(v).tolist()))
                  for k, v in p.items() if not callable(v) and k != "defects" and k not in fk.KEYS}
        params["defects"] = "; ".join(_label(s) for s in self._surfaces)
        self.later_params(params, p, self.defaults)
        if p["element"] == "P1":
            params.pop("element")           # today's QP key unchanged
        if fk.frictional(self._friction):
            params["friction"] = fk.params_label(self._friction)
        geometry = GeometryPart(3, a["points"], a["cells"], nd, p["element"])
        iface = dataclasses.replace(iface, weights=c.weights.copy())       # each QP its own weights
        qp = QP(K=K, F=F, B=B, weights=iface.weights, K_fixed=a["K_el"], local_dofs=a["local"],
                name=f"three_d[{self._load_label()}]", params=params, geometry=geometry, interface=iface,
                units=UnitsPart(E=float(p["E"]), length=float(p["width"])),
                material=MaterialPart(float(p["E"]), float(p["nu"]), "strain"))
        return fk.add_friction(qp, self._friction, c.points[:, c.lower])


def _label(s: Surface) -> str:
    """One defect as text (``QP.params["defects"]``)."""
    def v(x) -> str:
        return "[" + ", ".join(f"{c:.6g}" for c in x) + "]"

    if s.shape == "polygon":
        return f"polygon {v(s.points.ravel())}"
    if s.shape == "cap":
        return f"cap centre {v(s.center)} axis {v(s.normal)} R {s.R:g} radius {s.a:g}"
    return f"{s.shape} centre {v(s.center)} normal {v(s.normal)} axes {s.a:g}, {s.b:g}"
