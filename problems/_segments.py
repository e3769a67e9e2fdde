"""Exact distances between planar segments, and the pairs of segments within a gap found on a grid.

Shared by the defect checks of :mod:`dualfem.problems.gmsh_mesh` (crossing or touching defects) and
the crack generator of :mod:`dualfem.problems.fractured` (``min_gap``): :func:`segment_distances`
(broadcast over any shapes, crossings detected), :func:`near_segment_pairs` (a uniform grid of the
midpoints: O(n) pairs instead of all of them) and :func:`closest` (the closest approach of two
polylines, in row blocks).
"""
from __future__ import annotations

import numpy as np

__all__ = ["closest", "near_segment_pairs", "segment_distances"]


def segment_distances(P0, P1, Q0, Q1) -> tuple[np.ndarray, np.ndarray]:
    """Exact distances between segments P0-P1 and Q0-Q1 (coordinate arrays (..., 2), broadcast), and a
    mask of the pairs that cross properly (each segment's ends strictly on both sides of the other);
    the distance of a crossing pair is 0."""
    P0, P1, Q0, Q1 = (np.asarray(a, dtype=float) for a in (P0, P1, Q0, Q1))

    def cross(o, p, q):
        return (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0])

    def point_seg(p, s0, s1):
        d = s1 - s0
        t = np.clip(((p - s0) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
        e = p - (s0 + t[..., None] * d)
        return np.hypot(e[..., 0], e[..., 1])

    proper = ((np.sign(cross(P0, P1, Q0)) * np.sign(cross(P0, P1, Q1)) < 0)
              & (np.sign(cross(Q0, Q1, P0)) * np.sign(cross(Q0, Q1, P1)) < 0))
    d = np.minimum(np.minimum(point_seg(P0, Q0, Q1), point_seg(P1, Q0, Q1)),
                   np.minimum(point_seg(Q0, P0, P1), point_seg(Q1, P0, P1)))
    return np.where(proper, 0.0, d), proper


def near_segment_pairs(A: np.ndarray, B: np.ndarray | None, gap: float,
                       chunk: int = 1 << 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index pairs (i, j) of segments A[i] and B[j] (arrays (n, 2, 2): first and last point) whose exact
    distance is <= ``gap``, with those distances; with B None the pairs i < j within A.

    A uniform grid (cells of side the longest segment + ``gap``) hashes the segments' midpoints, so
    only segments in neighbouring cells are compared (O(n) for segments of similar lengths, instead of
    all n m pairs; segments much longer than the median are hashed as pieces, :func:`_split`); exact
    distances (:func:`segment_distances`) in chunks of ``chunk`` pairs."""
    same = B is None
    B = A if B is None else B
    empty = np.zeros(0, dtype=np.int64)
    if len(A) == 0 or len(B) == 0:
        return empty, empty, np.zeros(0)
    target = _piece_length(A, B, gap)
    if target is not None:      # a few long segments among short ones: hashed as pieces (same distances)
        (PA, ia), (PB, ib) = _split(A, target), (_split(B, target) if not same else (None, None))
        i, j, d = near_segment_pairs(PA, PB, gap, chunk)
        i, j = ia[i], (ia if same else ib)[j]
        keep = i != j if same else np.ones(len(i), dtype=bool)
        i, j, d = i[keep], j[keep], d[keep]
        order = np.lexsort((d, j, i))
        i, j, d = i[order], j[order], d[order]
        first = np.ones(len(i), dtype=bool)
        first[1:] = (i[1:] != i[:-1]) | (j[1:] != j[:-1])
        return i[first], j[first], d[first]
    ma, mb = A.mean(axis=1), B.mean(axis=1)
    la, lb = (np.hypot(*(X[:, 1] - X[:, 0]).T) for X in (A, B))
    reach = 0.5 * (la.max() + lb.max()) + gap         # midpoints of two segments within gap are this close
    lo = np.minimum(ma.min(axis=0), mb.min(axis=0))
    extent = float(np.max(np.maximum(ma.max(axis=0), mb.max(axis=0)) - lo))
    cell = max(float(reach), extent / 2 ** 20, 1e-300)     # at most 2^20 cells a side: no key overflow
    ca = np.floor((ma - lo) / cell).astype(np.int64)
    cb = np.floor((mb - lo) / cell).astype(np.int64)
    ny = int(max(ca[:, 1].max(), cb[:, 1].max())) + 3
    key_b = (cb[:, 0] + 1) * ny + (cb[:, 1] + 1)
    order = np.argsort(key_b, kind="stable")
    sorted_keys = key_b[order]
    ii, jj = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            k = (ca[:, 0] + 1 + dx) * ny + (ca[:, 1] + 1 + dy)
            start = np.searchsorted(sorted_keys, k, side="left")
            cnt = np.searchsorted(sorted_keys, k, side="right") - start
            total = int(cnt.sum())
            if not total:
                continue
            i = np.repeat(np.arange(len(A)), cnt)
            j = order[np.repeat(start - np.cumsum(cnt) + cnt, cnt) + np.arange(total)]
            keep = (i < j) if same else np.ones(total, dtype=bool)
            dm = ma[i] - mb[j]
            keep &= np.hypot(dm[:, 0], dm[:, 1]) <= reach
            ii.append(i[keep])
            jj.append(j[keep])
    if not ii:
        return empty, empty, np.zeros(0)
    i, j = np.concatenate(ii), np.concatenate(jj)
    out_i, out_j, out_d = [empty], [empty], [np.zeros(0)]
    for c0 in range(0, len(i), chunk):
        ic, jc = i[c0:c0 + chunk], j[c0:c0 + chunk]
        d, _ = segment_distances(A[ic, 0], A[ic, 1], B[jc, 0], B[jc, 1])
        near = d <= gap
        out_i.append(ic[near])
        out_j.append(jc[near])
        out_d.append(d[near])
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_d)


def _piece_length(A: np.ndarray, B: np.ndarray, gap: float) -> float | None:
    """The length to split segments into before hashing, when the longest segment is more than 4 times
    the median (the grid's cells are as wide as the longest segment: a few long ones would put every
    segment in a handful of cells); None when no split is needed."""
    lengths = np.concatenate([np.hypot(*(X[:, 1] - X[:, 0]).T) for X in (A, B)])
    pts = np.concatenate([A.reshape(-1, 2), B.reshape(-1, 2)])
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    target = max(2.0 * float(np.median(lengths)), gap, extent / 1024)
    return target if lengths.max() > 2.0 * target else None


def _split(S: np.ndarray, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Segments (n, 2, 2) cut into equal pieces no longer than ``target``, and each piece's segment index."""
    k = np.maximum(1, np.ceil(np.hypot(*(S[:, 1] - S[:, 0]).T) / target)).astype(np.int64)
    owner = np.repeat(np.arange(len(S)), k)
    step = np.arange(owner.size) - np.repeat(np.cumsum(k) - k, k)
    t0, t1 = (step / k[owner])[:, None], ((step + 1) / k[owner])[:, None]
    a, d = S[owner, 0], S[owner, 1] - S[owner, 0]
    pieces = np.stack([a + t0 * d, a + t1 * d], axis=1)
    pieces[:, 1][step == k[owner] - 1] = S[owner[step == k[owner] - 1], 1]      # the end exactly
    return pieces, owner


def closest(A: np.ndarray, B: np.ndarray, mask=None) -> tuple[float, bool, np.ndarray]:
    """Smallest segment distance between polylines A and B (pairs allowed by ``mask``), whether
    that pair crosses properly, and a point near the closest approach."""
    best, crossing, where = np.inf, False, A[0]
    for r0 in range(0, len(A) - 1, 256):               # row blocks keep memory bounded
        Ar = A[r0:r0 + 257]
        d, proper = segment_distances(Ar[:-1, None, :], Ar[1:, None, :], B[None, :-1, :], B[None, 1:, :])
        if mask is not None:
            d = np.where(mask[r0:r0 + 256], d, np.inf)
        k = np.unravel_index(np.argmin(d), d.shape)
        if d[k] < best:
            best, crossing = float(d[k]), bool(proper[k])
            where = 0.25 * (Ar[k[0]] + Ar[k[0] + 1] + B[k[1]] + B[k[1] + 1])
    return best, crossing, where
