"""The thin-defect scene of Zhiltsov & Maksimova (2023) as a QP, for any defect geometry.

Body: the rectangle (0, width) x (0, height) (unit square by default), isotropic linear
elasticity (E, nu; ``plane = "strain"`` by default, ``"stress"`` supported: the paper does not
say which it used). Supports and loads: by default (the paper's scenes) clamped on the bottom side
x2 = 0, a traction ``load`` on the top side x2 = height (:mod:`dualfem.problems.loads`), other sides
free; with any of the keys ``boundary`` (``[[boundary]]`` tables: ``side`` = left | right | bottom |
top, ``support`` = clamp | roller | free, ``traction`` = [t1, t2] of numbers or expressions in x, y),
``body_force`` ([b1, b2], force per volume) or ``remote_stress`` ([[s11, s12], [s12, s22]]: the
traction sigma.n on every side without a support; no support at all = only the rigid-body motions
removed) the scene's own supports and loads instead, and ``load`` is not used
(:mod:`dualfem.problems._boundary`, docs/loads.md). Each ``[[defects]]`` table may carry a
``face_pressure`` (a number or an expression in x, y; > 0 pushes the faces apart, the "+" copy of
node j gets +p_j w_j nu_j). ``load_scale`` multiplies every load. Tractions are forces per area on
the body's outer surface, in the reference frame (before ``rotate_deg``).

Defects: polylines (or splines, gmsh mesh only) strictly inside the body; the normal nu of a
defect is its tangent, from its first to its last point, turned by +90 degrees (so for the
default horizontal defect nu = (0, 1) and the "+" face is the upper one); see :mod:`.cut`.
Energy (paper, section 1), one term per defect d:

    Pi(v) = 1/2 a(v, v) - (f, v) + sum_d 1/(2 delta_d) int_gamma_d |[v]|^2,   [v_nu] >= 0 on every gamma_d.

Scene keys beyond the paper's: ``mesh`` = ``"structured"`` (default: N x N squares cut by their
(1, 1) diagonal, the paper's scenes; defect vertices must be grid nodes and its segments run
along grid edges) or ``"gmsh"`` (unstructured, defects embedded; :mod:`dualfem.problems.gmsh_mesh`),
``mesh_size`` (gmsh target element size; 0 = min(width, height) / N), ``tip_size`` (gmsh size
at the defect tips; 0 = mesh_size), ``rotate_deg`` (rigid counter-clockwise rotation of the whole
scene about the body's centre: body, defects, loads and supports; the mesh is generated once in
the reference frame and rotated; the supported and loaded sides are those of the reference frame;
a roller on a rotated body is refused),
``size_growth`` (gmsh: the element size's slope away from a tip, in [0.01, 1], default 0.3: a refinement
study that shrinks ``tip_size`` should shrink it too, docs/fractured.md),
and ``defects`` (TOML ``[[defects]]`` tables: ``points`` = [[x, y], ...] in the reference frame,
``curve`` = "polyline" | "spline", optional ``delta`` and ``face_pressure``) or ``defects_file`` (the same
defects in a CSV or JSON file, relative to the scene file: :mod:`dualfem.problems.defects_file`). Without
either the single segment ``defect = [[x1, y1], [x2, y2]]`` is used; ``defects = []`` is an uncracked body
(a QP without constraints). How many defects a scene holds is bounded by the mesh they need (the gmsh
triangle estimate, checked before meshing), not by a count.

Load model: a scene without ``boundary``, ``body_force`` and ``remote_stress`` is the paper's (bottom
clamped, ``load`` on top); one whose only load is a defect's ``face_pressure`` must say so: give those
keys, or ``load`` explicitly for the paper's model (docs/loads.md). Otherwise it is refused.

P1 elements by default (``element = "P2"`` or ``"P2-quarter-point"``: quadratic triangles, :mod:`.element`);
nodes strictly inside a defect are doubled (tips not); the P1 interface integral uses the trapezoid rule.
Units are whatever the inputs use (paper: MPa and a unit length). The QP and
its multiplier convention are described in :mod:`dualfem.qp`. ``QP.maps``: ``nodes`` (2, n),
``triangles`` (3, nt), ``node_dofs`` (2, n; -1 = fixed: clamped, a roller's normal component or a
rigid-body removal), per constrained defect node j (row j of B) ``defect_lower``/``defect_upper``
(node ids of the - / + copies), ``defect_id``,
``defect_s`` (arc length from the defect's first point), ``defect_normals``/``defect_tangents``
(2, m); ``defect_tips`` (first and last node of each defect, flat); and, for a single straight
defect, ``normal`` and ``tangent`` (2,).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.elasticity import PLANES, lame  # noqa: F401  (re-exported)
from dualfem.errors import InputError
from dualfem.numerics.linalg import freeze
from dualfem.problem import Problem, UnitMap
from dualfem.qp import QP, GeometryPart, MaterialPart, UnitsPart
from dualfem.registry import register_problem

from .. import _boundary as bd
from .. import _friction_keys as fk
from .._interface import delta_free_part, interface, local_unknowns, with_delta
from ..adaptive import Adaptive
from . import element
from .assemble import boundary_edges_on, free_dofs, stiffness, traction_vector
from .checks import MESHES, MIN_DELTA_E_OVER_L, SceneChecks, _load_label, _same_load  # noqa: F401  (re-exported)
from .cut import Cut, cut
from .geometry import defects_label
from .interface_sum import InterfaceSum
from .mesh import rotate, rotation, structured_defect_nodes, structured_mesh


@register_problem
class ThinDefect(SceneChecks, Adaptive, Problem):
    """Elastic rectangle with thin defects (fracture parameter delta), structured or gmsh mesh."""

    name = "thin_defect"
    description = "2D elastic body with thin defects (Zhiltsov & Maksimova 2023)"
    dim = 2
    scene_default = True        # a 2D scene file naming no problem is a thin-defect scene
    #: the stress grid's units axis: E, load_scale and tractions are stresses, delta a length per stress
    unit_map = UnitMap({"E": "stress", "width": "length", "height": "length", "load_scale": "stress",
                        "delta": "length/stress", "mesh_size": "length_if_set", "tip_size": "length_if_set",
                        "defect": "points", "defects": "defect_tables", "body_force": "body_force",
                        "boundary": "traction_tables", "load": "stress_field", "defects_file": "file",
                        "friction_bound": "stress_value"},
                       scaling_names=("f1", "f2", "f3"))   # the paper's loads scale with width by themselves
    defaults = {
        "N": 64,
        "delta": 1e-5,
        "E": 69000.0,
        "nu": 0.3,
        "plane": "strain",
        "load": "f2",
        "load_scale": 1.0,
        "defect": ((0.25, 0.5), (0.75, 0.5)),
        "width": 1.0,
        "height": 1.0,
        "mesh": "structured",
        "mesh_size": 0.0,
        "tip_size": 0.0,
        "rotate_deg": 0.0,
        "defects": None,
        "boundary": (),
        "body_force": None,
        "remote_stress": None,
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
    presets = {"f1": {"load": "f1"}, "f2": {"load": "f2"}, "f3": {"load": "f3"}}
    #: keys that keep the mesh and K_el: ``with_params`` / a Workspace's ``update`` reuse the delta-free assembly
    #: (``boundary`` only while the supports stay the same: :meth:`with_params`)
    update_keys = ("delta", "load", "load_scale", "boundary", "body_force", "remote_stress")

    def _support_key(self) -> tuple | None:
        """What the fixed unknowns depend on beyond the mesh: None (the legacy bottom clamp) or the supports."""
        return None if self._loads is None else \
            tuple(sorted((s.side, s.support) for s in self._loads.sides if s.support != "free"))

    def _shares_with(self, new: ThinDefect, changes: dict) -> bool:
        """Whether ``new`` (this scene with ``changes``) may reuse this one's delta-free assembly: only
        :attr:`update_keys` changed and the supports (hence the fixed unknowns) are the same."""
        return set(changes) <= set(self.update_keys) and new._support_key() == self._support_key()

    def with_params(self, **changes) -> ThinDefect:
        new = type(self)(**{**self.params, **changes})
        if self._shares_with(new, changes):
            new.shared = self.shared
        return new

    def size_estimate(self) -> tuple[int, str]:
        """Unknowns before assembly: 2 per grid node (structured), or from the gmsh element size."""
        p = self.params
        if p["mesh"] == "structured":     # P2: a node per vertex and per edge (about 3 per vertex)
            return 2 * (p["N"] + 1) ** 2 * (1 if p["element"] == "P1" else 4), f"N={p['N']}"
        if p["refine"] == "adaptive":
            return int(p["max_unknowns"]), f"refine='adaptive', max_unknowns={p['max_unknowns']}"
        from dualfem.problems.gmsh_mesh import estimate_triangles

        h = p["mesh_size"] or min(p["width"], p["height"]) / p["N"]
        tip = p["tip_size"] if 0 < p["tip_size"] < h else None
        tri = estimate_triangles(p["width"], p["height"], h, tip, 2 * len(getattr(self, "_defects", ())),
                                 p["size_growth"])
        nodes = 1.2 * tri / 2 + 1          # about 2 triangles per node, 20 % margin (doubled defect nodes)
        nodes *= 1 if p["element"] == "P1" else 4
        return int(2 * nodes), f"mesh_size={h:g}" + (f", tip_size={tip:g}" if tip else "")

    def size_of_mesh(self) -> int:
        """The unknowns of the mesh before supports are removed (the adaptive loop's budget): P2 counts the edges."""
        return super().size_of_mesh() if self.params["element"] == "P1" else element.size_of_mesh(self)

    # ----------------------------------------------------------------- mesh
    def _gmsh_options(self) -> dict:
        """Keyword arguments of :func:`dualfem.problems.gmsh_mesh.mesh_with_defects` beyond the geometry
        (its defaults here: Frontal-Delaunay, the scene files' meshes)."""
        return {}

    def _reference_mesh(self) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """(nodes, triangles, ordered node ids of each defect) in the reference (unrotated) frame."""
        p = self.params
        N, W, H = p["N"], p["width"], p["height"]
        if p["mesh"] == "structured":
            pts, tri = structured_mesh(N, W, H)
            return pts, tri, [structured_defect_nodes(N, W, H, d["points"]) for d in self._defects]
        from dualfem.problems.gmsh_mesh import mesh_with_defects

        h = p["mesh_size"] or min(W, H) / N
        dm = mesh_with_defects(W, H, [{"points": d["points"], "curve": d["curve"]} for d in self._defects],
                               h, p["tip_size"] or None, size_growth=p["size_growth"],
                               size_view=self._size_view, **self._gmsh_options())
        pts, tri = np.asarray(dm.points, dtype=float), np.asarray(dm.triangles, dtype=np.int32)
        if np.bincount(tri.ravel(), minlength=pts.shape[1]).min() == 0:
            raise RuntimeError("the gmsh mesh has nodes in no triangle (problems/gmsh_mesh.py must drop them)")
        return pts, tri, [np.asarray(n, dtype=np.int64) for n in dm.defect_nodes]

    def cut(self) -> tuple[Cut, np.ndarray]:
        """The doubled mesh in the reference frame, and its node coordinates after ``rotate_deg`` (kept in
        ``self.shared``: computed once for this instance and those ``with_params`` derives from it)."""
        shared = self.shared.data
        self.adapt_mesh()
        if shared.get("cut") is None:
            pts, tri, dn = self._reference_mesh()
            p = self.params
            label = f"N={p['N']}" if p["mesh"] == "structured" else f"mesh_size={p['mesh_size'] or 'width/N'}"
            c = cut(pts, tri, dn, label)
            centre = np.array([p["width"], p["height"]]) / 2
            shared["cut"] = (c, rotate(c.points, float(p["rotate_deg"]), centre))
        return shared["cut"]

    def mesh(self):
        """(scikit-fem MeshTri of the doubled, rotated mesh, the Cut)."""
        from skfem import MeshTri

        c, pts = self.cut()
        return MeshTri(pts, c.triangles), c

    def basis(self):
        """P1 vector basis on the doubled mesh (scikit-fem; its DOF 2 i + c is component c of node i)."""
        from skfem import Basis, ElementTriP1, ElementVector

        return Basis(self.mesh()[0], ElementVector(ElementTriP1()))

    # ------------------------------------------------------------- assembly
    def _sides(self, c: Cut) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        tol = 1e-9 * max(p["width"], p["height"])
        y = c.points[1]
        return np.flatnonzero(np.abs(y) <= tol), np.abs(y - p["height"]) <= tol

    def _box_sides(self) -> dict[str, np.ndarray]:
        """Boundary edges per side of the doubled mesh (reference frame), computed once per Shared."""
        shared = self.shared.data
        if shared.get("box_sides") is None:
            c, _ = self.cut()
            shared["box_sides"] = bd.box_sides(c.points, c.triangles, (self.params["width"], self.params["height"]))
        return shared["box_sides"]

    def nodal_load(self) -> np.ndarray:
        """Nodal forces (2, nnodes) of every load (the legacy top traction ``load``, or the ``[[boundary]]``
        tractions, ``remote_stress`` and ``body_force``; the defects' ``face_pressure``), times
        ``load_scale``, in the rotated frame."""
        p = self.params
        if p["element"] != "P1":
            return element.nodal_load(self, self._delta_free())
        c, pts = self.cut()
        R = rotation(float(p["rotate_deg"]))
        if self._loads is None:
            Fn = self._top_traction()
        else:
            Fn = bd.nodal_forces(self._loads, c.points, c.triangles, self._box_sides(), float(p["load_scale"]))
            Fn = Fn if p["rotate_deg"] == 0 else R @ Fn
        if any(d.get("face_pressure") is not None for d in self._defects):
            Fn = Fn + bd.face_pressure_forces(c.upper, c.lower, R @ c.normals, c.weights,
                                           float(p["load_scale"]) * self._pressures(c), pts.shape[1])
        if self._loads is not None:
            bd.check_balance(self._loads, pts, self._box_sides(), Fn)
        return Fn

    def _pressures(self, c: Cut) -> np.ndarray:
        """The face pressure (m,) at each constrained defect node (0 on defects without one), evaluated at
        the nodes' reference coordinates; InputError when not finite there."""
        out = np.zeros(c.lower.size)
        fields: dict[int, tuple] = {}
        for k, d in enumerate(self._defects):
            f = d.get("face_pressure")
            if f is not None:
                fields.setdefault(id(f), (f, []))[1].append(k)
        for f, ks in fields.values():
            sel = np.flatnonzero(np.isin(c.defect_id, ks))
            with np.errstate(all="ignore"):
                val = f(c.points[:, c.lower[sel]])[0]
            if not np.all(np.isfinite(val)):
                raise InputError(f"{f.key} = {f.values[0]!r} gives NaN or infinite values on its defect; it must "
                                 f"be finite there")
            out[sel] = val
        return out

    def _top_traction(self) -> np.ndarray:
        """Nodal forces (2, nnodes) of the legacy top traction ``load``, in the rotated frame."""
        p = self.params
        c, _ = self.cut()
        edges = boundary_edges_on(c.points, c.triangles, self._sides(c)[1])
        with np.errstate(all="ignore"):
            try:
                Fn = traction_vector(c.points, edges, self._traction, float(p["load_scale"]))
            except InputError:
                raise
            except Exception as exc:  # a user-given load function that breaks
                raise InputError(f"load {_load_label(p['load'])} cannot be evaluated on the top side: "
                                 f"{type(exc).__name__}: {exc}") from None
        if not np.all(np.isfinite(Fn)):
            raise InputError(f"load {_load_label(p['load'])} gives NaN or infinite values on the top side "
                             f"(x2 = {p['height']:g}, 0 <= x1 <= {p['width']:g}); it must be finite there")
        return Fn if p["rotate_deg"] == 0 else rotation(float(p["rotate_deg"])) @ Fn

    def assemble(self):
        """Elastic stiffness and top-traction load on all DOFs (before boundary conditions).

        Returns ``(K_all, F_all, basis)``; DOF 2 i + c is component c of node i (``basis.nodal_dofs``).
        """
        c, pts = self.cut()
        nn = pts.shape[1]
        nd = np.arange(2 * nn).reshape(nn, 2).T
        lam, mu = lame(self.params["E"], self.params["nu"], self.params["plane"])
        K_all = stiffness(pts, c.triangles, lam, mu, nd, 2 * nn)
        return K_all, self.nodal_load().T.ravel(), self.basis()

    def _delta_free(self) -> dict:
        """Mesh, DOF maps and elastic stiffness K_el: everything that depends neither on delta nor on the load.

        Computed once per :class:`~dualfem.core.problem.Shared` (this instance and those
        :meth:`with_params` derives from it for new ``update_keys``), so a sweep over delta or loads
        on one mesh assembles once; its arrays are read-only (they are shared by the QPs built from it).
        """
        shared = self.shared
        a = shared.data.get("delta_free")
        if a is not None:
            return a
        p = self.params
        c, pts = self.cut()
        lam, mu = lame(p["E"], p["nu"], p["plane"])
        if p["element"] != "P1":
            a = element.delta_free(self, lam, mu, rotation(float(p["rotate_deg"])))
            freeze(a["K_el"].data, a["K_el"].indices, a["K_el"].indptr, a["local"], *a["maps"].values())
            shared.data["delta_free"] = a
            shared.assemblies += 1
            return a
        if self._loads is None:
            node_dofs = free_dofs(self._sides(c)[0], pts.shape[1])
        else:
            node_dofs = bd.dof_numbering(bd.fixed_mask(self._loads, pts, self._box_sides()))
        n = int(node_dofs.max()) + 1
        K_el = stiffness(pts, c.triangles, lam, mu, node_dofs, n)
        R = rotation(float(p["rotate_deg"]))
        local = local_unknowns(node_dofs, c.lower, c.upper)
        maps = {"nodes": pts, "triangles": c.triangles, "node_dofs": node_dofs}
        part = delta_free_part(node_dofs, c, (R @ c.normals).T, tangents=(R @ c.tangents).T[:, None, :], front=c.tips,
                               s=c.s)
        a = {"cut": c, "n": n, "K_el": K_el, "local": local, "maps": maps, "interface": part}
        freeze(K_el.data, K_el.indices, K_el.indptr, local, *maps.values())
        shared.data["delta_free"] = a
        shared.assemblies += 1
        return a

    def _load_vector(self, a: dict) -> np.ndarray:
        """F on the free DOFs for this instance's load and load_scale; the last one is remembered in the
        delta-free assembly (a sweep over delta assembles it once). Each QP gets its own copy."""
        p = self.params
        last = a.get("F")
        key = self._loads_key()
        if last is None or not (_same_load(last[0], p["load"]) and last[1] == p["load_scale"] and last[2] == key):
            node_dofs = a["maps"]["node_dofs"]
            Fn = self.nodal_load()
            F = np.zeros(a["n"])
            free = node_dofs >= 0
            F[node_dofs[free]] = Fn[free]
            last = a["F"] = (p["load"], p["load_scale"], key, F)
        return last[3].copy()

    def _loads_key(self) -> tuple:
        """What F depends on beyond ``load`` and ``load_scale``: the new loads and the face pressures."""
        return (None if self._loads is None else self._loads.label(),
                tuple(None if d.get("face_pressure") is None else d["face_pressure"].values for d in self._defects))

    @staticmethod
    def _stiffness(a: dict, coef: np.ndarray) -> tuple:
        """(K = K_el + interface term with coefficients coef, B, J).

        By scipy's sum the first time on a delta-free assembly; the second time (a sweep) that sum
        also plans every later one (:class:`.interface_sum.InterfaceSum`: a copy of the values and
        8 m additions; it keeps a copy of K's pattern and values, so a single solve does not make
        it). B and J do not depend on coef (copies are returned).
        """
        plan = a.get("interface_sum")
        K = plan.matrix(coef) if plan else None
        if K is not None:
            return K, a["B"].copy(), [j.copy() for j in a["J"]]
        maps, c = a["maps"], a["cut"]            # scipy's sum (also on an exact cancellation)
        K_par, B, J = interface(maps["node_dofs"], c.lower, c.upper, a["interface"].normals.T, coef, a["n"])
        K = (a["K_el"] + K_par).tocsc()
        sums = a["stiffness_sums"] = a.get("stiffness_sums", 0) + 1
        if plan is None and sums >= 2:      # plan False: none can be made (an exact cancellation)
            a["interface_sum"] = InterfaceSum.from_sum(K, a["K_el"], maps["node_dofs"], c.lower, c.upper) or False
            a["B"], a["J"] = B.copy(), [j.copy() for j in J]
        return K, B, J

    def _qp_name(self) -> str:
        load = self.params["load"]
        return "thin_defect[loads]" if self._loads is not None else \
            f"thin_defect[{load if isinstance(load, str) else 'custom'}]"

    def build(self) -> QP:
        """Assemble K (elastic + interface/delta), F (top traction), B (normal jumps).

        The delta-free part (mesh, K_el, maps; F per load) is reused from earlier builds of this
        instance and of those :meth:`with_params` derived from it for new ``update_keys`` (delta, load,
        load_scale); the interface term is assembled for this delta.
        """
        p = self.params
        a = self._delta_free()
        c, maps = a["cut"], dict(a["maps"])
        iface, coef = with_delta(a["interface"], [d["delta"] for d in self._defects])
        K, B, J = self._stiffness(a, coef)
        R = rotation(float(p["rotate_deg"]))
        if len(self._defects) == 1 and len(self._defects[0]["points"]) == 2:
            pa, pb = self._defects[0]["points"]
            tau = (pb - pa) / np.linalg.norm(pb - pa)
            maps["normal"], maps["tangent"] = R @ np.array([-tau[1], tau[0]]), R @ tau
        params = {k: (v if isinstance(v, (int, float, str)) else str(np.asarray(v).tolist()))
                  for k, v in p.items() if not callable(v) and k != "defects" and k not in bd.KEYS
                  and k not in fk.KEYS}
        if fk.frictional(self._friction):
            params["friction"] = fk.params_label(self._friction)
        if isinstance(p["defects"], (list, tuple)) and len(p["defects"]):
            params["defects"] = defects_label(self._defects)
        if self._loads is not None:
            params["loads"] = self._loads.label()
        self.later_params(params, p, ThinDefect.defaults)
        if p["element"] == "P1":
            params.pop("element")
        self.jump_operators = J
        geometry = GeometryPart(2, maps.pop("nodes"), maps.pop("triangles"), maps.pop("node_dofs"), p["element"])
        qp = QP(K=K, F=self._load_vector(a), B=B, weights=c.weights, K_fixed=a["K_el"], local_dofs=a["local"],
                name=self._qp_name(),
                params=params, maps=maps, geometry=geometry, interface=iface,
                units=UnitsPart(E=float(p["E"]), length=float(p["width"])),
                material=MaterialPart(float(p["E"]), float(p["nu"]), str(p["plane"])))
        return fk.add_friction(qp, self._friction, c.points[:, c.lower])

