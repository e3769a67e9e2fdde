"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.scene`."""
from dualfem._facade import moved
from dualfem.core.scene import (
    DEFAULT_SCENE,
    DIM_PROBLEMS,
    PresetConflictWarning,
    build_qp,
    describe,
    library,
    load_scene,
    parse_set,
    preset_conflicts,
    presets,
    scene_dim,
)

__all__ = [
    "DEFAULT_SCENE", "DIM_PROBLEMS", "PresetConflictWarning", "build_qp", "describe", "library", "load_scene",
    "parse_set", "preset_conflicts", "presets", "scene_dim",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
__getattr__ = moved(__name__, {
    "InputError": "dualfem.errors", "Problem": "dualfem.problem", "QP": "dualfem.qp", "builtin_names":
    "dualfem.registry", "get_problem": "dualfem.registry", "problems": "dualfem.registry",
})
