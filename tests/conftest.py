"""Shared fixtures: small scenes built once per session."""
from __future__ import annotations

import functools

import pytest

from dualfem.core import registry
from dualfem.core.scene import load_scene


@functools.cache
def _scene(name: str, N: int, delta: float, plane: str = "strain"):
    problem = load_scene(name, {"N": N, "delta": delta, "plane": plane})
    return problem, problem.build()


@pytest.fixture
def scene():
    """``scene(name, N, delta) -> (problem, qp)``, cached across tests (do not mutate)."""
    return _scene


@pytest.fixture
def register():
    """Register third-party plugin classes for one test (the built-ins are loaded first): ``register(cls)``
    for a solver, ``register(cls, kind="problem")`` for a problem; removed again after the test."""
    registry.solvers()
    registry.problems()
    added: list[tuple[dict, str]] = []

    def reg(cls, kind="solver"):
        table = registry._SOLVERS if kind == "solver" else registry._PROBLEMS
        (registry.register_solver if kind == "solver" else registry.register_problem)(cls)
        added.append((table, cls.name))
        return cls

    yield reg
    for table, name in added:
        table.pop(name, None)
