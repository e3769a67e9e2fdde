"""Stable import path of the plugin API (docs/plugins.md); the code lives in :mod:`dualfem.core.scene`."""
from dualfem import core as _core
from dualfem._facade import moved
from dualfem.core.scene import (
    DEFAULT_SCENE,
    QP_FILE_PROBLEM,
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
    "DEFAULT_SCENE", "QP_FILE_PROBLEM", "PresetConflictWarning", "build_qp", "describe", "library", "load_scene",
    "parse_set", "preset_conflicts", "presets", "scene_dim",
]

#: names this module re-exported by accident before it had ``__all__`` (deprecated; see dualfem/_facade.py)
_moved = moved(__name__, {
    "InputError": "dualfem.errors", "Problem": "dualfem.problem", "QP": "dualfem.qp", "builtin_names":
    "dualfem.registry", "get_problem": "dualfem.registry", "problems": "dualfem.registry",
})


def __getattr__(name: str):
    """The deprecated names: ``DIM_PROBLEMS`` (deprecated in :mod:`dualfem.core.scene`, which warns) and
    the accidental re-exports above."""
    if name == "DIM_PROBLEMS":
        return getattr(_core.scene, name)
    return _moved(name)
