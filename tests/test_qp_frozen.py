"""The structured-mesh QPs are frozen: the current code builds the same K, K_fixed, F, B,
weights, local_dofs and maps (same DOF numbering) as the reference file written by
``tests/data/make_qp_frozen.py`` with the original scikit-fem assembly, to 1e-14 relative."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

DATA = Path(__file__).with_name("data")
_spec = importlib.util.spec_from_file_location("make_qp_frozen", DATA / "make_qp_frozen.py")
frozen = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(frozen)
REF = dict(np.load(DATA / "qp_frozen.npz"))
RTOL = 1e-14


def _csr(name: str) -> sp.csr_matrix:
    return sp.csr_matrix((REF[f"{name}__data"], REF[f"{name}__indices"], REF[f"{name}__indptr"]),
                         shape=tuple(REF[f"{name}__shape"]))


def _close(got, ref, what: str) -> None:
    if sp.issparse(ref):
        assert got.shape == ref.shape, what
        err = abs(sp.csr_matrix(got) - ref).max() if ref.nnz else abs(got).max()
        scale = abs(ref).max()
    else:
        got, ref = np.asarray(got), np.asarray(ref)
        assert got.shape == ref.shape, f"{what}: shape {got.shape} != {ref.shape}"
        if ref.dtype.kind in "iu":
            assert np.array_equal(got, ref), what
            return
        err = np.abs(got - ref).max(initial=0.0)
        scale = np.abs(ref).max(initial=0.0)
    assert err <= RTOL * max(scale, 1e-300), f"{what}: max error {err:.3e} vs scale {scale:.3e}"


@pytest.mark.parametrize("tag, N, load, plane", frozen.cases())
def test_qp_unchanged(tag, N, load, plane):
    qp = frozen.build(tag, N, load, plane)
    g = f"{tag}{N}"
    _close(qp.K, _csr(f"K_{g}_{plane}"), "K")
    _close(qp.K_fixed, _csr(f"Kf_{g}_{plane}"), "K_fixed")
    # the 1/delta interface part on its own (it dominates K at delta = 1e-5)
    _close(qp.K - qp.K_fixed, _csr(f"K_{g}_{plane}") - _csr(f"Kf_{g}_{plane}"), "K - K_fixed")
    _close(qp.F, REF[f"F_{g}_{load}"], "F")
    _close(qp.B, _csr(f"B_{g}"), "B")
    _close(qp.weights, REF[f"weights_{g}"], "weights")
    _close(qp.local_dofs, REF[f"local_{g}"], "local_dofs")
    keys = [k[len(f"map_{g}_"):] for k in REF if k.startswith(f"map_{g}_")]
    assert keys
    exported = qp.to_dict()          # the typed parts (geometry) are exported as the same map_ arrays
    for k in keys:
        assert f"map_{k}" in exported, f"maps[{k!r}] missing"
        _close(exported[f"map_{k}"], REF[f"map_{g}_{k}"], f"maps[{k!r}]")
