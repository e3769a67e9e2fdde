"""Checks of a 2D thin-defect scene's keys (:class:`SceneChecks`, mixed into
:class:`dualfem.problems.thin_defect.ThinDefect` and the ``fractured`` problem built on it).

``validate`` reads the defects (``defects``, ``defects_file`` or the single ``defect``) after every other key
is checked and the gmsh mesh's size bounded (:meth:`SceneChecks._check_keys`), then each defect's delta against
E and the body size and the load model (:meth:`SceneChecks._check_defects_and_load`): one InputError naming the
key and its allowed range, before anything is meshed or allocated.
"""
from __future__ import annotations

import numpy as np

from dualfem.core.elasticity import PLANES
from dualfem.errors import InputError, check_int, check_open_interval, check_positive

from .. import _boundary as bd
from .. import _friction_keys as fk
from .._defect_geometry import check_growth
from ..adaptive import check_keys as check_adaptive
from ..loads import check_load_model, resolve_load
from . import element
from .geometry import parse_defect, parse_defects, read_file_tables

MESHES = ("structured", "gmsh")
#: smallest delta * E / max(width, height) accepted (dimensionless; see ThinDefect.validate)
MIN_DELTA_E_OVER_L = 1e-12


def _same_load(a, b) -> bool:
    """The same load: the same preset name, or the very same function object."""
    return a is b or (isinstance(a, str) and isinstance(b, str) and a == b)


def _load_label(load) -> str:
    return repr(load) if isinstance(load, str) else getattr(load, "__name__", "function")




class SceneChecks:
    """The key checks of a 2D thin-defect scene (module docstring); ``self.params`` and ``self.defaults`` are
    the problem's."""

    def validate(self) -> None:
        p = self.params
        tables, where = read_file_tables(p["defects_file"], p["defects"])   # a file's size and rows, then its tables
        # the size is the first thing to know: before the defects are parsed
        self._check_keys(len(tables) if isinstance(tables, (list, tuple)) and len(tables) else 1)
        p["defect"] = parse_defect(p["defect"])
        default_defect = np.asarray(self.defaults["defect"], dtype=float)
        if tables is not None and not np.array_equal(p["defect"], default_defect):
            raise InputError(f"give either defect = [[x1, y1], [x2, y2]] or {where}, not both")
        try:
            self._defects = parse_defects(tables, p["defect"], p["delta"], p["width"], p["height"], p["mesh"])
        except InputError as exc:
            raise InputError(f"{where}: {exc}" if p["defects_file"] else str(exc)) from None
        self._check_defects_and_load()

    def _check_keys(self, n_defects: int) -> None:
        """Every key but the defects; with a gmsh mesh every size-driving key (mesh_size, tip_size, N, width,
        height) is bounded for ``n_defects`` defects (2 tips each) before any defect is parsed or placed."""
        p = self.params
        p["N"] = check_int("N", p["N"], 2, 4096)
        p["element"] = element.check_element(p["element"])
        p["delta"] = check_positive("delta", p["delta"])
        p["E"] = check_positive("E", p["E"])
        p["nu"] = check_open_interval("nu", p["nu"], -1.0, 0.5)
        p["width"] = check_positive("width", p["width"])
        p["height"] = check_positive("height", p["height"])
        ls = p["load_scale"]
        if not isinstance(ls, (int, float)) or not np.isfinite(ls):
            raise InputError(f"load_scale must be a finite number, got {ls!r}")
        if p["plane"] not in PLANES:
            raise InputError(f"plane must be one of {', '.join(PLANES)}, got {p['plane']!r}")
        if p["mesh"] not in MESHES:
            raise InputError(f"mesh must be one of {', '.join(MESHES)}, got {p['mesh']!r}")
        p["mesh_size"] = check_positive("mesh_size", p["mesh_size"], allow_zero=True)
        p["tip_size"] = check_positive("tip_size", p["tip_size"], allow_zero=True)
        p["size_growth"] = check_growth(p["size_growth"])
        p["refine"], p["target_error"], p["max_unknowns"] = check_adaptive(p["refine"], p["target_error"],
                                                                          p["max_unknowns"], p["mesh"])
        rot = p["rotate_deg"]
        if not isinstance(rot, (int, float)) or not np.isfinite(rot):
            raise InputError(f"rotate_deg must be a finite number (degrees), got {rot!r}")
        if p["mesh"] == "gmsh":
            from dualfem.problems.gmsh_mesh import check_size

            h = p["mesh_size"] or min(p["width"], p["height"]) / p["N"]
            label = f"mesh_size={h:g}" if p["mesh_size"] else \
                f"mesh_size=0 (min(width, height)/N = {h:g} with N={p['N']})"
            tip = p["tip_size"] if 0 < p["tip_size"] < h else None
            check_size(p["width"], p["height"], h, tip, 2 * n_defects, label, p["size_growth"])

    def _check_defects_and_load(self) -> None:
        """Each defect's delta against E and the body size; the loads: ``[[boundary]]``, ``body_force``,
        ``remote_stress`` (:mod:`dualfem.problems._boundary`; ``self._loads``, None without them: the legacy
        bottom clamp and top traction ``load``, resolved into ``self._traction``)."""
        p = self.params
        for i, d in enumerate(self._defects):
            # the interface stiffness ~ 1/delta must not swamp the elastic stiffness ~ E beyond double
            # precision (at 1e-12 the elasticity still keeps 4 digits at N = 4096); scale-free
            ratio = d["delta"] * p["E"] / max(p["width"], p["height"])
            if ratio < MIN_DELTA_E_OVER_L:
                raise InputError(f"delta of defect {i} ({d['delta']:g}) is too small for E = {p['E']:g} and the body "
                                 f"size: delta * E / max(width, height) = {ratio:.1e} must be "
                                 f">= {MIN_DELTA_E_OVER_L:g} "
                                 f"(below it the defect is glued to double precision)")
        self._friction = fk.parse_friction(p, [d.get("friction", {}) for d in self._defects], 2,
                                           (p["width"], p["height"]))
        self._loads: bd.LoadSpec | None = bd.parse_loads(p, 2)
        self._traction = None
        if self._loads is None:
            check_load_model(self, [d.get("face_pressure") is not None for d in self._defects])
            with np.errstate(all="ignore"):  # a NaN-producing expression is refused below, without warnings
                self._traction = resolve_load(p["load"], p["width"])
            return
        default = type(self).defaults["load"]
        if not _same_load(p["load"], default):
            raise InputError(f"load = {_load_label(p['load'])} (the top traction of a scene without supports and "
                             f"loads of its own) cannot be combined with {', '.join(bd.KEYS)}: give the top "
                             f"traction as a [[boundary]] table (side = 'top', traction = [t1, t2]) and leave load "
                             f"at its default {default!r} (no preset scene that sets it, such as f1 or f3)")
        rollers = [s.side for s in self._loads.sides if s.support == "roller"]
        if rollers and float(p["rotate_deg"]) != 0.0:
            raise InputError(f"boundary: a roller support (side {rollers[0]}) fixes the normal component of a side, "
                             f"which on a body rotated by rotate_deg = {p['rotate_deg']:g} is not a component of "
                             f"the unknowns; use rotate_deg = 0 or a clamp")
