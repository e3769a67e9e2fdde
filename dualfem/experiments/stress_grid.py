"""The stress grid: which runs ``dualfem stress`` makes (axes delta, r, units, load, nu, N).

The base scene is the paper's f2 (:data:`BASE`) or any scene of any registered problem (a
library scene, a preset or a TOML file: :func:`scene_base`); an axis is made only where it
applies to the scene's problem (:func:`applicable_axes`: delta and r (a map over delta x r) need
the scene key ``delta``, load ``load_scale``, nu ``nu``, the N axis ``N``, the units axis a unit
map the problem declares, ``Problem.unit_map``: :func:`unit_maps`).

For the ``units`` and ``load`` axes the reference does not come from solving the scaled QP at
all: it is the reference of the base scene mapped by the exact physics (a change of units maps
x by the length factor and the nodal forces by stress x length; the QP is positively
homogeneous in the load, so ``x(s F) = s x(F)``). This tests scale invariance without trusting
any solver on the scaled data.
"""
from __future__ import annotations

import hashlib
import json
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualfem.core.scene import DEFAULT_SCENE, QP_FILE_PROBLEM
from dualfem.core.units import scaled_expression as _scaled_expression  # noqa: F401  (tests)
from dualfem.experiments.paper import LOADS, PAPER_SCENE

DELTAS = [1e-12, 1e-9, 1e-6, 1e-3, 1.0, 1e3]


RS = [1e0, 1e3, 1e5, 1e7, 1e9, 1e12]


NUS = [0.0, 0.3, 0.45, 0.49, 0.4999]


LOAD_SCALES = [1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6]


NS = [8, 16, 32, 64, 128, 256, 512, 1024]


#: unit systems relative to the paper's (stress unit MPa, length unit taken as 1 m):
#: name -> (number of new stress units per MPa, number of new length units per m)
UNITS = OrderedDict([("MPa-m", (1.0, 1.0)), ("MPa-mm", (1.0, 1e3)), ("Pa-m", (1e6, 1.0)),
                     ("Pa-mm", (1e6, 1e3)), ("GPa-km", (1e-3, 1e-3))])


AXES = ("delta", "r", "units", "load", "nu", "N")


#: the paper's scene (its load f2, delta = 1e-5, E = 69000 MPa, nu = 0.3, plane strain) at N = 32
BASE = {"load": PAPER_SCENE, "N": 32, "delta": 1e-5, "E": 69000.0, "nu": 0.3, "plane": "strain"}


#: the paper's fixed augmentation parameter r (MPa per unit length)
PAPER_R = 1e7


@dataclass
class Task:
    """One run: a scene, a solver with explicit parameters, and how to obtain its reference."""

    id: str
    axis: str
    coords: dict
    scene: dict
    solver: str
    params: dict
    ref: dict
    time_limit: float
    after: str | None = None          # id of the task that must finish first (N axis)
    ref_ok: bool = True                # False: do not compute a reference (beyond budget)
    scene_name: str = DEFAULT_SCENE    # what ``scene`` (all of its parameters) is given to: load_scene(name, scene)

    def key(self) -> str:
        """Stable identity of the run (used to resume)."""
        return self.id


def _sid(d: dict) -> str:
    return hashlib.sha1(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:10]


def scene_in_units(base: dict, stress: float, length: float, problem: str | None = None) -> dict:
    """The same physics as ``base`` in a unit system ``stress`` times and ``length`` times the scene's
    (see :data:`UNITS`): the unit map the problem declares (``Problem.unit_map``,
    :class:`dualfem.core.units.UnitMap`) applied to ``base`` over the problem's defaults. x maps by
    ``length`` and the nodal forces mu by ``stress * length``. ``problem``: default the problem of
    :data:`~dualfem.core.scene.DEFAULT_SCENE`; InputError for a problem without a unit map.
    """
    from dualfem.core.errors import InputError
    from dualfem.core.registry import get_problem

    problem = problem or _default_problem()
    cls = get_problem(problem)
    if cls.unit_map is None:
        raise InputError(f"the units axis has no unit map for problem {problem!r} (it has: {', '.join(unit_maps())})")
    return cls.unit_map.convert(cls.defaults, base, stress, length)


def unit_maps() -> tuple[str, ...]:
    """The registered problems whose scenes the units axis can convert (they declare a ``unit_map``)."""
    from dualfem.core.registry import problems

    return tuple(sorted(n for n, cls in problems().items() if cls.unit_map is not None))


def _default_problem() -> str:
    """The problem of :data:`~dualfem.core.scene.DEFAULT_SCENE` (a built-in preset)."""
    from dualfem.core.scene import presets

    return presets()[DEFAULT_SCENE][0]


def applicable_axes(problem: str, params: dict) -> tuple[str, ...]:
    """The axes of :data:`AXES` that apply to a scene of ``problem`` with parameters ``params``
    (over the problem's defaults)."""
    from dualfem.core.registry import get_problem

    params = {**get_problem(problem).defaults, **params}
    need = {"delta": "delta", "r": "delta", "load": "load_scale", "nu": "nu", "N": "N"}   # r: a (delta, r) map
    out = []
    for ax in AXES:
        if ax in need and need[ax] not in params:
            continue
        if ax == "units" and get_problem(problem).unit_map is None:
            continue
        out.append(ax)
    return tuple(out)


def scene_problem(spec: str) -> str:
    """The problem name of a scene (a library name, a preset or a TOML file); InputError otherwise."""
    from dualfem.core.scene import load_scene

    return load_scene(spec).name


def scene_base(spec: str) -> dict:
    """Every parameter of a scene of any registered problem (a library name, a preset or a TOML
    file) as plain JSON-able values, to replace :data:`BASE` in :func:`build_grid`; InputError
    otherwise (e.g. a QP file, or a load given as a Python function)."""
    from dualfem.core.errors import InputError
    from dualfem.core.io import jsonable
    from dualfem.core.scene import load_scene

    prob = load_scene(spec)
    if prob.name == QP_FILE_PROBLEM:
        raise InputError(f"--scene {spec!r} is a QP file: the stress grid varies scene parameters, a QP file has none")
    p = {k: v for k, v in prob.params.items() if not callable(v)}
    if len(p) < len(prob.params):
        raise InputError(f"--scene {spec!r}: a load given as a Python function cannot be converted to other units")
    if "defect" in p:
        p["defect"] = np.asarray(p["defect"], dtype=float).tolist()
    if isinstance(p.get("defects"), (list, tuple)):      # None: the single segment ``defect``
        p["defects"] = [dict(t) if isinstance(t, Mapping) else t for t in p["defects"]]
    return jsonable(p)


def _at_n(base: dict, n: int) -> dict:
    """The base scene at mesh size N: a gmsh scene gets mesh_size = min(width, height) / N."""
    scene = {**base, "N": n}
    if base.get("mesh") == "gmsh":
        scene["mesh_size"] = min(float(base.get("width", 1.0)), float(base.get("height", 1.0))) / n
    return scene


def r_set_by_user(params: dict) -> bool:
    """True if a solver's r is the user's (``r_rule`` "fixed": as given, "scaled": in the paper's units),
    not derived from the problem (``r_rule="auto"``); solvers without ``r_rule`` take r as given."""
    return params.get("r_rule", "fixed") in ("fixed", "scaled")


def _plane_strain(problem: str) -> dict:
    """``{"plane": "strain"}`` for a problem with that key (2D), else nothing (3D elasticity as it is)."""
    from dualfem.core.registry import problems as registered

    cls = registered().get(problem)
    return {"plane": "strain"} if cls is None or "plane" in cls.defaults else {}


def build_grid(solver_names: list[str], *, quick: bool, axes: tuple[str, ...] | None = None,
               time_limit: float | None = None, max_n: int | None = None, scene: dict | None = None,
               scene_name: str | None = None) -> list[Task]:
    """All tasks of the stress grid for ``solver_names`` (see the module docstring).

    ``scene_name``: the base scene (a library scene, a preset or a TOML file of any problem), its
    parameters ``scene`` (default :func:`scene_base` of it) instead of the paper's f2
    (:data:`BASE`): its own mesh and load on every axis but N (there: N, and for a gmsh scene
    mesh_size = min(width, height) / N). ``axes``: default every axis that applies to the scene's
    problem; an axis asked for that does not apply is an InputError.
    """
    from dualfem.core.errors import InputError
    from dualfem.core.registry import solvers

    reg = solvers()
    if scene is None and scene_name is not None:
        scene = scene_base(scene_name)
    name = scene_name or DEFAULT_SCENE
    if Path(name).suffix == ".toml" and Path(name).is_file():
        name = str(Path(name).resolve())      # a scene file: found again by a resume from another folder
    problem = scene_problem(name) if scene_name is not None else _default_problem()
    fits = applicable_axes(problem, scene if scene is not None else BASE)
    if axes is None:
        axes = fits
    bad = [a for a in axes if a not in fits]
    if bad:
        raise InputError(f"--axes: axis {bad[0]!r} does not apply to a {problem} scene ({name}); "
                         f"its axes: {', '.join(fits)}")
    tl = float(time_limit if time_limit is not None else (20.0 if quick else 120.0))
    n_small = 16 if quick else 32
    top_base = BASE if scene is None else scene
    base = {**BASE, "N": n_small} if scene is None else dict(scene)   # a given scene keeps its own mesh
    tasks: list[Task] = []

    def add(axis, coords, scene, solver, params=None, ref=None, after=None):
        params = params or {}
        tid = f"{axis}:{solver}:{_sid({'s': scene, 'p': params, 'c': coords})}"
        tasks.append(Task(id=tid, axis=axis, coords=coords, scene=scene, solver=solver, params=params,
                          ref=ref or {"mode": "solve"}, time_limit=tl, after=after, scene_name=name))
        return tid

    # the r axis: solvers with a parameter r that the user sets (as given, or in the paper's units)
    r_solvers = [s for s in solver_names if "r" in reg[s].defaults and r_set_by_user(reg[s].defaults)]
    if "delta" in axes:
        for load in ([base.get("load")] if scene is not None else [PAPER_SCENE] if quick else list(LOADS)):
            for d in DELTAS:
                for s in solver_names:
                    add("delta", {"load": load, "delta": d}, {**base, "load": load, "delta": d}, s)
    if "r" in axes:
        for s in r_solvers:
            for d in DELTAS:
                for r in RS:
                    add("r", {"delta": d, "r": r}, {**base, "delta": d}, s, {"r": r})
    if "units" in axes:
        for uname, (fs, fl) in UNITS.items():
            scene = scene_in_units(base, fs, fl, problem)
            ref = {"mode": "transform", "base": base, "x": fl, "mu": fs * fl}
            for s in solver_names:
                add("units", {"units": uname, "r": "default"}, scene, s, ref=ref)
                if s in r_solvers:  # the paper's fixed number, not converted
                    add("units", {"units": uname, "r": f"{PAPER_R:g} fixed"}, scene, s, {"r": PAPER_R}, ref=ref)
    if "load" in axes:
        for ls in LOAD_SCALES:
            scene = {**base, "load_scale": ls}
            ref = {"mode": "transform", "base": base, "x": ls, "mu": ls}
            for s in solver_names:
                add("load", {"load_scale": ls}, scene, s, ref=ref)
    if "nu" in axes:
        plane = _plane_strain(problem)
        for nu in NUS:
            for s in solver_names:
                add("nu", {"nu": nu}, {**base, "nu": nu, **plane}, s)
    if "N" in axes:
        top = max_n or (128 if quick else 1024)
        prev: dict[str, str] = {}
        for n in [n for n in NS if n <= top]:
            for s in solver_names:
                prev[s] = add("N", {"N": n}, _at_n(top_base, n), s, after=prev.get(s))
    return tasks

