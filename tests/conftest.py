"""Shared fixtures: small scenes built once per session."""
from __future__ import annotations

import functools

import pytest

from dualfem.core.scene import load_scene


@functools.cache
def _scene(name: str, N: int, delta: float, plane: str = "strain"):
    problem = load_scene(name, {"N": N, "delta": delta, "plane": plane})
    return problem, problem.build()


@pytest.fixture
def scene():
    """``scene(name, N, delta) -> (problem, qp)``, cached across tests (do not mutate)."""
    return _scene
