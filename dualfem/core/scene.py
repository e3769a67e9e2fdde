"""Resolve a SCENE argument (built-in preset name or TOML file) plus ``--set`` overrides."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.problem import Problem
from dualfem.core.registry import get_problem, problems

#: the scene the framework uses when it needs one and none is given (probes, crafted test files,
#: the default of a study): a preset of the thin_defect problem plugin (the paper's f2 load). The
#: one place the framework names a scene; report studies reproducing the paper name the paper's
#: loads in :mod:`dualfem.experiments.paper`.
DEFAULT_SCENE = "f2"


def presets() -> dict[str, tuple[str, dict[str, Any]]]:
    """Built-in scene names -> (problem name, parameters)."""
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    for pname, cls in problems().items():
        for sname, params in cls.presets.items():
            out[sname] = (pname, dict(params))
    return out


def library() -> dict[str, Path]:
    """The scene library (the repository's ``scenes/`` folder, installed as ``dualfem.scenes``): name -> file."""
    import importlib.resources

    try:
        root = importlib.resources.files("dualfem.scenes")
    except ModuleNotFoundError:
        return {}
    return {Path(str(p)).stem: Path(str(p)) for p in sorted(root.iterdir(), key=lambda p: p.name)
            if p.name.endswith(".toml")}


def describe(path: Path) -> str:
    """The first comment line of a scene file (its one-line description)."""
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
    return ""


def parse_set(items: list[str] | None, flag: str = "--set") -> dict[str, str]:
    """Parse ``KEY=VALUE`` strings (from ``--set`` or ``-p``) into a dict; InputError if malformed."""
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"{flag} expects KEY=VALUE, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def _check_toml_types(spec: str, defaults: dict[str, Any], data: dict[str, Any]) -> None:
    """Numbers in a scene file are TOML numbers: a boolean or a string for a numeric key is refused."""
    for k, v in data.items():
        d = defaults.get(k)
        if isinstance(d, (int, float)) and not isinstance(d, bool) and \
                (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise InputError(f"scene key {k!r} in {spec!r} must be a number, got {v!r} ({type(v).__name__})")


def load_scene(spec: str, overrides: dict[str, Any] | None = None) -> Problem:
    """Return the problem instance for a preset name, a ``.toml`` scene file or a ``.npz``/``.mat`` QP file.

    A TOML scene file holds scene keys at top level; ``problem = "NAME"`` picks the problem
    plugin (default ``thin_defect``) and ``scene = "f2"`` starts from a built-in preset.
    """
    overrides = dict(overrides or {})
    pre = presets()
    lib = library()
    if spec in lib and spec not in pre and not Path(spec).exists():
        spec = str(lib[spec])
    if spec in pre:
        pname, params = pre[spec]
    elif Path(spec).suffix in (".npz", ".mat"):
        # a QP file (generic ``min 1/2 x'Px + q'x s.t. Gx >= h`` or a ``dualfem export``): problems/generic_qp.py
        pname, params = "qp_file", {"path": spec}
    elif spec.endswith(".toml") or Path(spec).is_file():
        path = Path(spec)
        if not path.is_file():
            raise InputError(f"scene file {spec!r} does not exist")
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"malformed TOML in scene file {spec!r}: {exc}") from None
        except UnicodeDecodeError:
            raise InputError(f"scene file {spec!r} is not UTF-8 text") from None
        base = data.pop("scene", None)
        if base is not None:
            if base not in pre:
                raise InputError(f"unknown base scene {base!r} in {spec!r}; "
                                 f"built-in scenes: {', '.join(sorted(pre))}")
            pname, params = pre[base]
        else:
            pname, params = "thin_defect", {}
        pname = data.pop("problem", pname)
        _check_toml_types(spec, get_problem(pname).defaults, data)
        params.update(data)
    else:
        raise InputError(f"unknown scene {spec!r}; use a built-in scene ({', '.join(sorted(pre))}), a scene of the "
                         f"library ({', '.join(sorted(lib)) or 'none installed'}) or a path to a .toml scene file "
                         f"or a .npz/.mat QP file")
    params.update(overrides)
    return get_problem(pname)(**params)
