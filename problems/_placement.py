"""Random sequential placement of defects, shared by the 2D and 3D ``fractured`` generators: of a batch of
candidates already clear of the placed defects, accept each one in order unless it conflicts with a candidate
accepted before it."""
from __future__ import annotations

import numpy as np


def first_fit(i: np.ndarray, j: np.ndarray, count: int, need: int) -> np.ndarray:
    """Boolean mask of the accepted candidates among ``count``, in order, up to ``need`` of them: candidate k is
    accepted unless a conflicting pair ``(i, j)`` with ``i < j = k`` names an accepted earlier candidate ``i``."""
    order = np.argsort(j, kind="stable")
    i, j = i[order], j[order]
    starts = np.searchsorted(j, np.arange(count + 1))
    accepted = np.zeros(count, dtype=bool)
    for k in range(count):
        if need <= 0:
            break
        if not accepted[i[starts[k]:starts[k + 1]]].any():
            accepted[k] = True
            need -= 1
    return accepted
