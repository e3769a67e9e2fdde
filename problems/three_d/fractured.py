"""A 3D box with many random disk-shaped cracks: the ``fractured`` scene with ``dim = 3``.

``dualfem solve fractured --set dim=3`` or a scene file with ``problem = "fractured"`` and ``dim = 3``:
the 3D body of :mod:`dualfem.problems.three_d` (its keys: ``width``, ``depth``, ``height``, ``E``,
``nu``, ``delta`` (every disk), ``load``/``load_scale`` (the top traction of the legacy clamped-base
scene), ``[[boundary]]``, ``body_force``, ``remote_stress``, ``mesh_size``, ``tip_size``,
``surface_size``, ``N``, ``rotate_deg``, ``rotate_axis``; ``defects`` is not a key here) with its defects
drawn by :func:`.disks.place_disks`. Keys of this problem (lengths in the body's unit, angles in degrees):

* ``cracks`` (default 50): how many disks, an integer in [1, 20000] (the mesh size guard,
  :func:`.mesh.check_size`, refuses a mesh of more than 4 million tetrahedra before meshing).
* ``crack_radius`` (default 0.06): a number or a range ``[min, max]``.
* ``crack_normal`` (default [0, 0, 1]) and ``crack_normal_spread`` (default 90): each disk's "+" normal is
  uniform on the cone of directions within ``crack_normal_spread`` degrees (in [0, 90]) of ``crack_normal``:
  0 = parallel disks, 90 = any orientation.
* ``min_gap`` (default 0 = 2 x the element size near the cracks, ``tip_size`` or else ``mesh_size``): the
  least distance between two disks and between a disk and the body's boundary; 0 or >= that element size
  (closer disks leave no room for a tetrahedron between them).
* ``seed`` (default 0), ``region`` (default the whole body: ``[[x0, y0, z0], [x1, y1, z1]]``).
* ``face_pressure`` (default none): a pressure on both faces of every disk (a number or an expression in
  x, y, z; > 0 pushes the faces apart).
* ``mesh_size`` = 0.08, ``tip_size`` = 0.03 by default.

From the command line a range, a vector or the region is one value: ``--set crack_radius=[0.03,0.06]``,
``--set crack_normal=[1,0,1]``, ``--set region=[[0,0,0.2],[1,1,0.8]]``.

The mesh: gmsh's OCC kernel, one ``fragment`` of the box with all disks (as the three_d scenes), the
surfaces by Frontal-Delaunay and the volume by gmsh's HXT algorithm (``Mesh.Algorithm3D = 10``, one
thread: the same arrays on every run): at 200 disks and 310 k tetrahedra 2.5 s instead of 18.5 s with
the Delaunay algorithm of the other 3D scenes, with a better worst element (minimum normalised volume
ratio 0.25 instead of 0.17) and the same defect triangles. Same keys, same disks, same mesh, same QP.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from dualfem.errors import InputError, check_int, check_positive
from dualfem.qp import QP

from .. import _boundary as bd
from .. import _friction_keys as fk
from . import ThreeD
from .disks import MAX_DISKS, parse_normal, parse_radius, parse_region, place_disks
from .geometry import Surface, _frame
from .mesh import check_size

#: default min_gap in element sizes near the cracks; the smallest accepted
GAP_IN_ELEMENTS = 2.0
MIN_GAP_IN_ELEMENTS = 1.0
#: crack_radius when not given
DEFAULT_RADIUS = 0.06
_OWN = ("cracks", "crack_radius", "crack_normal", "crack_normal_spread", "min_gap", "seed", "region", "face_pressure")


class Fractured3D(ThreeD):
    """A box with many random non-intersecting disks (see the module docstring). Reached through the
    registered ``fractured`` problem with ``dim = 3`` (:class:`dualfem.problems.fractured.Fractured`)."""

    name = "fractured"
    description = "3D elastic box with many random non-intersecting disk cracks (gmsh tetrahedra, HXT)"
    dim = 3
    scene_default = False
    defaults = {
        **{k: v for k, v in ThreeD.defaults.items() if k != "defects"},
        "mesh_size": 0.08,
        "tip_size": 0.03,
        "cracks": 50,
        "crack_radius": None,        # None: DEFAULT_RADIUS (a non-number default: a range is allowed)
        "crack_normal": (0.0, 0.0, 1.0),
        "crack_normal_spread": 90.0,
        "min_gap": 0.0,
        "seed": 0,
        "region": None,
        "face_pressure": None,
    }
    presets = {}
    update_keys = (*ThreeD.update_keys, "face_pressure")
    #: gmsh options over those of :mod:`.mesh` (HXT for the volume; see the module docstring)
    gmsh_options = {"Mesh.Algorithm3D": 10}

    def validate(self) -> None:
        p = self.params
        self._user = dict(p)                      # what with_params starts from
        own = {k: p.pop(k) for k in _OWN}
        friction = {k: p.pop(k) for k in fk.KEYS}  # they act on the disks, placed below
        p["defects"] = []                         # the body, its loads and sizes checked by three_d, uncracked
        super().validate()
        p.update(friction)
        n = check_int("cracks", own["cracks"], 1, MAX_DISKS)
        radius = parse_radius(DEFAULT_RADIUS if own["crack_radius"] is None else own["crack_radius"])
        axis, spread = parse_normal(own["crack_normal"], own["crack_normal_spread"])
        finest = self.tip_size or self.mesh_size
        gap = check_positive("min_gap", own["min_gap"], allow_zero=True) or GAP_IN_ELEMENTS * finest
        if gap < MIN_GAP_IN_ELEMENTS * finest:
            raise InputError(f"min_gap must be 0 (the default: {GAP_IN_ELEMENTS:g} x the element size near the cracks) "
                             f"or >= the element size near the cracks (tip_size, else mesh_size) = {finest:g}, "
                             f"got {own['min_gap']!r}")
        box = self.box
        region = parse_region(own["region"], box)
        # the mesh size guard first (the disks' fronts at their smallest radius), then the placement
        front = 2 * np.pi * radius[0] * n
        check_size(box, self.mesh_size, self.tip_size, front, self._size_label(), self.surface_size,
                   np.pi * radius[0] ** 2 * n)
        C, N, R = place_disks(n, radius, axis, spread, gap, own["seed"], region, box)
        check_size(box, self.mesh_size, self.tip_size, float(2 * np.pi * R.sum()), self._size_label(),
                   self.surface_size, float(np.pi * (R ** 2).sum()))
        fp = own["face_pressure"]
        if isinstance(fp, str) and not fp.strip():
            fp = None
        self._surfaces = [Surface("disk", p["delta"], c, nn, *_frame(nn), a=float(r), b=float(r), face_pressure=fp)
                          for c, nn, r in zip(C, N, R)]
        pressure = None if fp is None else bd.parse_scalar(fp, "face_pressure", 3, box)
        self._face_pressure = [pressure] * n
        self.disks = (C, N, R)                     # centres (n, 3), unit "+" normals (n, 3), radii (n,)
        self._friction = fk.parse_friction(p, [{} for _ in range(n)], 3, box)     # the top-level keys, every disk
        # the values used (QP.params shows them)
        p.update(cracks=n, crack_radius=radius[0] if radius[0] == radius[1] else list(radius),
                 crack_normal=tuple(float(c) for c in axis), crack_normal_spread=spread, min_gap=gap,
                 seed=int(own["seed"]), region=region.tolist(), face_pressure=fp)

    def with_params(self, **changes: Any) -> Fractured3D:
        """As :meth:`ThreeD.with_params`, from this scene's own keys."""
        new = type(self)(**{**self._user, **changes})
        if set(changes) <= set(self.update_keys):
            if new._support_key() == self._support_key():
                new.shared = self.shared
            else:
                new.shared.data.update({k: self.shared.data[k] for k in ("cut", "sides") if k in self.shared.data})
                new.shared.assemblies = self.shared.assemblies
        return new

    def build(self) -> QP:
        qp = super().build()
        qp.params.pop("defects", None)            # provenance: the keys (cracks, seed, ...), not 500 disks as text
        if self.params["face_pressure"] is None:
            qp.params.pop("face_pressure", None)
        qp.name = qp.name.replace("three_d", "fractured", 1)
        return qp

    def defect_tables(self) -> list[dict]:
        """The disks as 3D ``[[defects]]`` tables (shape, center, normal, radius)."""
        C, N, R = self.disks
        return [{"shape": "disk", "center": c.tolist(), "normal": n.tolist(), "radius": float(r)}
                for c, n, r in zip(C, N, R)]
