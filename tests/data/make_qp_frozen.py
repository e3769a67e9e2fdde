"""Write ``tests/data/qp_frozen.npz``: the thin-defect QPs of the structured mesh, frozen.

Run once from the repository root (``PYTHONPATH=. python tests/data/make_qp_frozen.py``) with the
code whose QPs are the reference; ``tests/test_qp_frozen.py`` then asserts that the current code
builds the same QPs (same DOF numbering) to 1e-14 relative. The cases: N = 16 and 32, each load
f1, f2, f3, both planes, delta = 1e-5 (the default), plus two non-horizontal defects (diagonal
and vertical) at N = 16. Arrays shared by several cases (K, K_fixed depend on N and the plane,
F on N and the load, B and the maps on N and the defect) are stored once; the writer checks that
they really are equal across the cases that share them.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from dualfem.core.scene import load_scene

OUT = Path(__file__).with_name("qp_frozen.npz")
DEFECTS = {"h": None, "d": [[0.25, 0.25], [0.75, 0.75]], "v": [[0.5, 0.25], [0.5, 0.75]]}


def cases() -> list[tuple[str, int, str, str]]:
    """(defect tag, N, load, plane) of every frozen QP."""
    out = [("h", N, load, plane) for N in (16, 32) for load in ("f1", "f2", "f3") for plane in ("strain", "stress")]
    out += [("d", 16, "f2", "strain"), ("v", 16, "f1", "stress")]
    return out


def build(tag: str, N: int, load: str, plane: str):
    over = {"N": N, "plane": plane}
    if DEFECTS[tag] is not None:
        over["defect"] = DEFECTS[tag]
    return load_scene(load, over).build()


def _csr(name: str, A) -> dict[str, np.ndarray]:
    A = sp.csr_matrix(A)
    A.sum_duplicates()
    A.sort_indices()
    return {f"{name}__data": A.data, f"{name}__indices": A.indices.astype(np.int32),
            f"{name}__indptr": A.indptr.astype(np.int32), f"{name}__shape": np.array(A.shape)}


def _put(store: dict, key: str, arrays: dict[str, np.ndarray]) -> None:
    for k, v in arrays.items():
        if k in store:
            if store[k].shape != v.shape or not np.array_equal(store[k], v):
                sys.exit(f"{k}: differs between cases that should share it")
        else:
            store[k] = v


def main() -> None:
    store: dict[str, np.ndarray] = {}
    for tag, N, load, plane in cases():
        qp = build(tag, N, load, plane)
        _put(store, f"K_{tag}{N}_{plane}", _csr(f"K_{tag}{N}_{plane}", qp.K))
        _put(store, f"Kf_{tag}{N}_{plane}", _csr(f"Kf_{tag}{N}_{plane}", qp.K_fixed))
        _put(store, f"F_{tag}{N}_{load}", {f"F_{tag}{N}_{load}": qp.F})
        geo = {**_csr(f"B_{tag}{N}", qp.B), f"weights_{tag}{N}": qp.weights, f"local_{tag}{N}": qp.local_dofs}
        geo.update({f"map_{tag}{N}_{k}": np.asarray(v) for k, v in qp.maps.items()})
        _put(store, f"geo_{tag}{N}", geo)
    np.savez_compressed(OUT, **store)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.2f} MB, {len(store)} arrays)")


if __name__ == "__main__":
    main()
