"""The problem plugin contract.

A problem plugin is a subclass of :class:`Problem` declaring ``name``, ``defaults`` (every scene
parameter with its default), optionally ``presets`` (named scenes, e.g. the paper's ``f1``),
and implementing :meth:`Problem.build` returning a :class:`~dualfem.qp.QP`. Problems return plain
scipy.sparse / numpy data and know nothing of solvers.

Reuse across builds is owned by the instance, never by the module: a problem may keep derived data
(e.g. its delta-free assembly) in ``self.shared`` and declare in ``update_keys`` the scene keys
that leave it valid; :meth:`Problem.with_params` then makes the instance for new values of those
keys sharing it (what :class:`dualfem.workspace.Workspace` uses for a sweep over delta).
"""
from __future__ import annotations

from typing import Any, ClassVar

from dualfem.core.errors import InputError, MissingDependency, missing_module
from dualfem.core.qp import QP
from dualfem.core.solver import _coerce
from dualfem.core.units import UnitMap


class Shared:
    """Derived data a problem instance reuses across its builds and shares with the instances
    :meth:`Problem.with_params` derives from it: ``data`` (problem-specific) and ``assemblies`` (how many
    times the problem computed it: a sweep that reuses it keeps this at 1)."""

    __slots__ = ("data", "assemblies")

    def __init__(self) -> None:
        self.data: dict[str, Any] = {}
        self.assemblies = 0


class Problem:
    """Base class of problem plugins."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    presets: ClassVar[dict[str, dict[str, Any]]] = {}
    requires: ClassVar[tuple[str, ...]] = ()     # importable modules build() needs
    extra: ClassVar[str | None] = None           # the pyproject extra providing them
    #: scene keys whose change keeps ``self.shared`` valid (e.g. delta and the load of a thin-defect
    #: scene: they leave the mesh and the delta-free stiffness K_fixed as they are)
    update_keys: ClassVar[tuple[str, ...]] = ()
    #: the spatial dimension of the problem's bodies: 2 (plane) or 3
    dim: ClassVar[int] = 2
    #: True: this problem reads the scene files of its :attr:`dim` that name no ``problem`` (nor a base
    #: ``scene``): the framework finds it by :func:`dualfem.core.registry.problem_for_dim`. Declare it on
    #: the class that means it: a subclass of such a problem sets it back to False.
    scene_default: ClassVar[bool] = False
    #: scene keys that pick this problem for a scene file naming no ``problem`` (nor a base ``scene``), before
    #: its ``dim`` does (e.g. ``mesh_file``: a body read from a file); :func:`dualfem.core.registry.problem_for_keys`
    claim_keys: ClassVar[tuple[str, ...]] = ()
    #: how the scene's parameters change with the unit system (the stress grid's ``units`` axis), or
    #: None: the units axis does not apply to this problem (:class:`dualfem.core.units.UnitMap`)
    unit_map: ClassVar[UnitMap | None] = None
    #: scene keys naming files (e.g. ``defects_file``): in a scene file a relative path is relative to the
    #: scene file's folder (:func:`dualfem.core.scene.load_scene` resolves it); from ``--set``, to the
    #: working directory
    path_keys: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def missing(cls) -> str | None:
        """Return an install hint if a module ``build()`` needs is missing, else None."""
        return missing_module(f"problem {cls.name!r}", cls.requires, cls.extra)

    def __init__(self, **params: Any) -> None:
        reason = self.missing()
        if reason:
            raise MissingDependency(reason)
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise InputError(f"unknown scene key {unknown[0]!r} for problem {self.name!r}; "
                             f"allowed: {', '.join(sorted(self.defaults))}")
        #: the keys the scene gave (a preset's, a scene file's, ``--set``'s), beside the defaults
        self.given: frozenset[str] = frozenset(params)
        merged = dict(self.defaults)
        for k, v in params.items():
            d = self.defaults[k]
            merged[k] = _coerce(k, v, d, self.name, owner="problem") if isinstance(d, (int, float)) else v
        self.params: dict[str, Any] = merged
        self.shared = Shared()
        self.validate()

    def with_params(self, **changes: Any) -> Problem:
        """The same scene with ``changes`` applied (validated); when every changed key is one of
        :attr:`update_keys` the new instance shares this one's derived data (:class:`Shared`: e.g. the
        delta-free assembly), otherwise it starts afresh."""
        new = type(self)(**{**self.params, **changes})
        if set(changes) <= set(self.update_keys):
            new.shared = self.shared
        return new

    def validate(self) -> None:
        """Check ``self.params``; raise InputError naming the parameter and its range."""

    def size_estimate(self) -> tuple[int, str] | None:
        """(estimated number of unknowns, a label such as "N=512") before assembly, or None if unknown.

        Used to refuse, before any allocation, a scene that cannot fit in memory."""
        return None

    def build(self) -> QP:  # pragma: no cover - abstract
        """Assemble the QP of this scene."""
        raise NotImplementedError
