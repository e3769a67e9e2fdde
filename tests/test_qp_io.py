"""QP export/import (.npz, .mat) and validation."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.qp import QP


@pytest.mark.parametrize("ext", [".npz", ".mat"])
def test_round_trip(scene, tmp_path, ext):
    _, qp = scene("f2", 8, 1e-5)
    path = qp.save(tmp_path / f"qp{ext}")
    back = QP.load(path)
    assert abs(back.K - qp.K).max() == 0 and abs(back.B - qp.B).max() == 0
    assert np.array_equal(back.F, qp.F) and np.array_equal(back.weights, qp.weights)
    assert np.array_equal(back.geometry.node_dofs, qp.geometry.node_dofs)
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


def test_validation_messages():
    K = sp.eye(3)
    with pytest.raises(InputError, match="F must have length 3"):
        QP(K=K, F=np.zeros(2), B=sp.csr_matrix((1, 3)))
    with pytest.raises(InputError, match="B must have 3 columns"):
        QP(K=K, F=np.zeros(3), B=sp.csr_matrix((1, 2)))
    with pytest.raises(InputError, match="NaN"):
        QP(K=K, F=np.array([0, np.nan, 0]), B=sp.csr_matrix((1, 3)))
    with pytest.raises(InputError, match="symmetric"):
        QP(K=sp.csr_matrix(np.array([[2.0, 1, 0], [0, 2, 0], [0, 0, 2]])), F=np.zeros(3),
           B=sp.csr_matrix((1, 3))).check()
    with pytest.raises(InputError, match="\\.npz or \\.mat"):
        QP(K=K, F=np.zeros(3), B=sp.csr_matrix((1, 3))).save("qp.txt")


def test_atomic_write_gives_usual_permissions(tmp_path):
    import os
    import stat

    from dualfem.core.io import atomic_write_text

    umask = os.umask(0o022)
    try:
        p = atomic_write_text(tmp_path / "r.md", "x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o644


def test_benchmark_outputs_are_not_replaced_without_force(tmp_path):
    """A benchmark script refuses, before any work, to replace results already there (exit 2, one
    line naming the file and --force); with --force it may."""
    import subprocess
    import sys

    from dualfem.core.io import refuse_overwrite

    (tmp_path / "delta_sweep.json").write_text("{}")
    with pytest.raises(InputError, match="delta_sweep.json.*--force"):
        refuse_overwrite([tmp_path / "delta_sweep.md", tmp_path / "delta_sweep.json"], force=False)
    refuse_overwrite([tmp_path / "delta_sweep.json"], force=True)
    refuse_overwrite([tmp_path / "absent.json"], force=False)
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "delta_sweep.py"
    r = subprocess.run([sys.executable, str(script), "--N", "8", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "delta_sweep.json" in r.stderr and "--force" in r.stderr
    assert (tmp_path / "delta_sweep.json").read_text() == "{}"
