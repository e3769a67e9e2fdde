"""Resolve a SCENE argument (built-in preset name or TOML file) plus ``--set`` overrides."""
from __future__ import annotations

import tomllib
import warnings
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.problem import Problem
from dualfem.core.qp import QP
from dualfem.core.registry import builtin_names, get_problem, problem_dims, problem_for_dim, problems

#: the scene the framework uses when it needs one and none is given (probes, crafted test files,
#: the default of a study): a preset of the thin_defect problem plugin (the paper's f2 load). The
#: one place the framework names a scene; report studies reproducing the paper name the paper's
#: loads in :mod:`dualfem.experiments.paper`.
DEFAULT_SCENE = "f2"
#: the problem plugin that reads a ``.npz``/``.mat`` QP file (problems/generic_qp.py): the one place the
#: framework dispatches a QP file; such a scene has no scene parameters but its path
QP_FILE_PROBLEM = "qp_file"


class PresetConflictWarning(UserWarning):
    """A third-party problem plugin declares a scene name that belongs to a built-in scene (ignored)."""


def presets() -> dict[str, tuple[str, dict[str, Any]]]:
    """Scene names -> (problem name, parameters): every problem plugin's ``presets``.

    Built-in names win: the presets of dualfem's own problem plugins and the scene library's names are
    reserved, so a third-party plugin's preset named ``f2`` (or ``curved``) is ignored, never taking over
    ``dualfem solve f2``; so is a name an earlier third-party plugin took. :func:`preset_conflicts`
    names both sides of each refusal (``dualfem list`` shows them).
    """
    return _presets()[0]


def preset_conflicts() -> list[str]:
    """One message per ignored third-party preset (see :func:`presets`), naming both plugins."""
    return _presets()[1]


def _presets() -> tuple[dict[str, tuple[str, dict[str, Any]]], list[str]]:
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    owner: dict[str, str] = {}
    conflicts: list[str] = []
    reg = problems()
    builtin = builtin_names("problem")
    lib = library()
    for pname, cls in sorted(reg.items(), key=lambda kv: kv[0] not in builtin):   # built-ins first (stable)
        who = f"problem plugin {pname!r} ({cls.__module__}.{cls.__qualname__})"
        items = cls.presets.items() if isinstance(cls.presets, dict) else ()
        for sname, params in items:
            if not isinstance(sname, str) or not isinstance(params, dict):
                conflicts.append(f"{who} declares the preset {sname!r} with {type(params).__name__} parameters "
                                 f"(a dict of scene parameters is needed): ignored")
                continue
            if pname not in builtin and (sname in out or sname in lib):
                taken = owner.get(sname) or f"the scene library's {sname!r} ({lib[sname]})"
                conflicts.append(f"{who} may not take the scene name {sname!r} of {taken}: its preset is "
                                 f"ignored ('dualfem solve {sname}' runs the built-in); choose another name")
                continue
            if sname in out:
                continue
            out[sname] = (pname, dict(params))
            owner[sname] = f"the {'built-in ' if pname in builtin else ''}{who}"
    return out, conflicts


def library(dim: int | None = None) -> dict[str, Path]:
    """The scene library (the repository's ``scenes/`` folder, installed as ``dualfem.scenes``): name -> file;
    with ``dim``, only the scenes of that dimension (a file's ``dim`` key, default 2)."""
    import importlib.resources

    try:
        root = importlib.resources.files("dualfem.scenes")
    except ModuleNotFoundError:
        return {}
    out = {Path(str(p)).stem: Path(str(p)) for p in sorted(root.iterdir(), key=lambda p: p.name)
           if p.name.endswith(".toml")}
    return out if dim is None else {k: p for k, p in out.items() if scene_dim(p) == dim}


def scene_dim(path: Path) -> int:
    """The ``dim`` key of a scene file (2 when absent or unreadable)."""
    try:
        d = tomllib.loads(path.read_text(encoding="utf-8")).get("dim", 2)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return 2
    return d if isinstance(d, int) and not isinstance(d, bool) else 2


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
    pre, conflicts = _presets()
    lib = library()
    for msg in conflicts:
        if f"scene name {spec!r} " in msg:
            warnings.warn(msg, PresetConflictWarning, stacklevel=2)
    if spec in lib and spec not in pre and not Path(spec).exists():
        spec = str(lib[spec])
    if spec in pre:
        pname, params = pre[spec]
    elif Path(spec).suffix in (".npz", ".mat"):
        # a QP file (qpsolvers' P, q, G, h: G x <= h, or dualfem's K, F, B: an export): problems/generic_qp.py
        pname, params = QP_FILE_PROBLEM, {"path": spec}
    elif spec.endswith(".toml") or Path(spec).exists():
        from dualfem.core.io import check_input_path

        path = check_input_path(spec, "scene file")
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
            # the dimension picks the problem (--set dim=3 over the file's dim)
            pname, params = _dim_problem(overrides.get("dim", data.get("dim", 2)), spec), {}
        pname = data.pop("problem", pname)
        _check_toml_types(spec, get_problem(pname).defaults, data)
        _resolve_paths(data, get_problem(pname).path_keys, path.parent)
        params.update(data)
    else:
        raise InputError(f"unknown scene {spec!r}; use a built-in scene ({', '.join(sorted(pre))}), a scene of the "
                         f"library ({', '.join(sorted(lib)) or 'none installed'}) or a path to a .toml scene file "
                         f"or a .npz/.mat QP file")
    params.update(overrides)
    if "dim" in params and "dim" not in get_problem(pname).defaults:
        _drop_dim(params, spec, pname)
    cls = get_problem(pname)
    from dualfem.core.quiet import plugin_output

    with plugin_output():              # a problem plugin printing in __init__ must not corrupt --json
        if pname in builtin_names("problem"):
            return cls(**params)
        try:
            return cls(**params)
        except InputError:
            raise
        except BaseException as exc:   # noqa: BLE001 - a third-party plugin's bug (even SystemExit): say so
            if type(exc) is KeyboardInterrupt:     # a real Ctrl-C still stops
                raise
            raise InputError(f"problem plugin {pname!r} ({cls.__module__}.{cls.__qualname__}) failed to "
                             f"create the scene: {type(exc).__name__}: {exc}") from None


def _resolve_paths(data: dict[str, Any], keys: tuple[str, ...], folder: Path) -> None:
    """The file keys (``Problem.path_keys``) of a scene file: a relative path made relative to the scene
    file's folder (so a scene and its data files move together)."""
    for k in keys:
        v = data.get(k)
        if isinstance(v, str) and v.strip() and not Path(v).is_absolute():
            data[k] = str(folder / v)


def _dim(dim: Any, where: str) -> int:
    """``dim`` as an integer that is a dimension of a problem (:func:`~dualfem.core.registry.problem_dims`);
    InputError for another value."""
    try:
        d = int(dim) if float(dim) == int(float(dim)) and not isinstance(dim, bool) else None
    except (TypeError, ValueError, OverflowError):
        d = None
    dims = problem_dims()
    if d not in dims:
        raise InputError(f"dim in {where!r} must be one of {', '.join(map(str, dims))}, got {dim!r}")
    return d


def _dim_problem(dim: Any, where: str) -> str:
    """The problem plugin of a scene file of dimension ``dim`` naming no problem: the problem declaring
    ``scene_default`` for that ``Problem.dim`` (:func:`~dualfem.core.registry.problem_for_dim`)."""
    return problem_for_dim(_dim(dim, where))


def _drop_dim(params: dict[str, Any], where: str, pname: str) -> None:
    """A problem without a ``dim`` key has the dimension it declares (``Problem.dim``): that ``dim`` is
    accepted (and dropped), any other value refused."""
    dim = params.pop("dim")
    own = get_problem(pname).dim
    if _dim(dim, where) != own:
        raise InputError(f"dim = {dim!r} in {where!r}: this scene's problem is {own}D; a scene of another "
                         f"dimension is a scene file with that dim (without 'scene = ...') or a library scene "
                         f"of it, e.g. 'dualfem solve {problem_for_dim(_dim(dim, where))}'")


def __getattr__(name: str) -> Any:
    """``DIM_PROBLEMS`` (deprecated): the dimension -> problem map, now the problems' own declarations."""
    if name == "DIM_PROBLEMS":
        warnings.warn("dualfem.scene.DIM_PROBLEMS is deprecated (removed in the next release): the problems "
                      "declare Problem.dim and scene_default; use dualfem.registry.problem_for_dim(dim)",
                      DeprecationWarning, stacklevel=2)
        return {d: problem_for_dim(d) for d in problem_dims()}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_qp(problem: Problem) -> QP:
    """``problem.build()``, contained: a problem plugin's prints go to stderr (``--json`` stays one
    object); a third-party plugin that raises (anything but a real Ctrl-C) or returns something else
    than a :class:`~dualfem.core.qp.QP` is refused with an InputError naming it."""
    from dualfem.core.quiet import plugin_output

    name = getattr(problem, "name", type(problem).__name__)
    who = f"problem plugin {name!r} ({type(problem).__module__}.{type(problem).__qualname__})"
    with plugin_output():
        if name in builtin_names("problem"):
            qp = problem.build()
        else:
            try:
                qp = problem.build()
            except InputError:
                raise
            except BaseException as exc:   # noqa: BLE001 - a third-party plugin's bug (even SystemExit)
                if type(exc) is KeyboardInterrupt:
                    raise
                raise InputError(f"{who} failed to build the QP: {type(exc).__name__}: {exc}") from None
    if not isinstance(qp, QP):
        raise InputError(f"{who}: build() returned {type(qp).__name__}, not a dualfem QP")
    return qp
