"""The sparsity pattern of a P1 assembly: distinct node pairs from their int64 keys (shared by 2D and 3D)."""
from __future__ import annotations

import numpy as np


def distinct_pairs(keys: np.ndarray, nn: int, stable: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, pos) of the node pairs encoded as ``keys = a * nn + b`` (int64, flat; consumed):
    the distinct pairs sorted in row-major order and, for each key, the index of its pair. One argsort
    (``stable``: a merge sort, fast on a few sorted runs such as a structured mesh's)."""
    order = np.argsort(keys, kind="stable" if stable else None)
    sk = keys[order]
    del keys
    new = np.empty(sk.size, dtype=bool)
    new[:1] = True
    np.not_equal(sk[1:], sk[:-1], out=new[1:])
    pos = np.empty(sk.size, dtype=np.intp)
    pos[order] = np.cumsum(new) - 1
    del order
    rows, cols = np.divmod(sk[new], nn)
    return rows, cols, pos
