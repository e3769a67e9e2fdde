"""The versions recorded with every result (dualfem.experiments.machine): every solver backend, cheaply."""
from __future__ import annotations

import importlib.metadata as md
import importlib.util
import json
import subprocess
import sys
import textwrap

import pytest

from dualfem.experiments import machine


def test_versions_are_the_installed_metadata():
    v = machine.versions()
    for pkg in ("numpy", "scipy", "scikit-fem", "osqp", "clarabel", "cvxpy"):
        assert v[pkg] == md.version(pkg)
    for pkg in ("pypardiso", "mkl", "gmsh", "pyamg", "qpsolvers", "scikit-sparse", "mkl-service"):
        try:
            want = md.version(pkg)
        except md.PackageNotFoundError:
            assert pkg not in v                      # recorded when present, never invented
        else:
            assert v[pkg] == want
    assert json.loads(machine.machine_info()["versions"]) == v


def test_backend_modules_found_without_importing(tmp_path):
    """A backend counts when every library its module imports is installed; stdlib, numpy, scipy and
    relative imports are not libraries; its distributions' versions are recorded."""
    d = tmp_path / "solvers"
    d.mkdir()
    (d / "good_.py").write_text("import time\nimport numpy as np\nimport scipy.sparse as spa\n"
                                "from threadpoolctl import threadpool_limits\nfrom ..problem import Problem\n")
    (d / "gone_.py").write_text("import json\nimport threadpoolctl\nimport surely_not_installed_xyz\n")
    (d / "nothing_.py").write_text("import os\n")
    (d / "__init__.py").write_text("import surely_not_installed_xyz\n")
    (d / "broken_.py").write_text("def (:\n")
    got = machine.qpsolvers_backends(d)
    assert got == {"good": {"threadpoolctl": md.version("threadpoolctl")}}


@pytest.mark.skipif(importlib.util.find_spec("qpsolvers") is None, reason="qpsolvers is not installed")
def test_every_available_qpsolvers_backend_is_recorded():
    import qpsolvers

    got = machine.qpsolvers_backends()
    assert set(qpsolvers.available_solvers) <= set(got), set(qpsolvers.available_solvers) - set(got)
    v = machine.versions()
    for b in qpsolvers.available_solvers:
        assert got[b], b                             # at least one distribution with its version
        for dist, ver in got[b].items():
            assert md.version(dist) == ver
        assert v[f"qpsolvers/{b}"] == ", ".join(f"{k} {x}" for k, x in got[b].items())


def test_recording_versions_imports_no_solver_library():
    code = textwrap.dedent("""
        import json, sys
        from dualfem.experiments.machine import machine_info
        machine_info()
        heavy = ("qpsolvers", "cvxpy", "clarabel", "osqp", "proxsuite", "pypardiso", "gmsh", "pyamg", "highspy")
        print(json.dumps(sorted(m for m in heavy if m in sys.modules)))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
