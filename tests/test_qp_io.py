"""QP export/import (.npz, .mat) and validation."""
from __future__ import annotations

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
    assert np.array_equal(back.maps["node_dofs"], qp.maps["node_dofs"])
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
