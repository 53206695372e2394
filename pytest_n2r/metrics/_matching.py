"""Mutual nearest neighbours between two 2-D point sets within a distance (k-d tree, or chunked numpy)."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

__all__ = ["mutual_nearest", "nearest_within"]


@functools.cache
def _kd_tree() -> Any:
    """SciPy's ``cKDTree``, imported on the first match (0.2-0.3 s: a warm main job that takes every keypoint
    metric's result from the render cache needs none), or ``None`` without SciPy."""
    try:  # scipy comes with scikit-image; the numpy path keeps the metrics working without it
        from scipy.spatial import cKDTree
    except ImportError:  # pragma: no cover - exercised through use_scipy=False in the tests
        return None
    return cKDTree


def nearest_within(queries: np.ndarray, points: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """Index into ``points`` of each query's nearest point, or ``-1`` when none lies within ``radius``
    (Euclidean distance, inclusive)."""
    if len(points) == 0 or len(queries) == 0:
        return np.full(len(queries), -1, dtype=np.intp)
    tree = _kd_tree() if use_scipy else None
    if tree is not None:
        # distance_upper_bound is exclusive; nudge it so a point exactly at `radius` still counts
        dist, idx = tree(points).query(queries, k=1, distance_upper_bound=np.nextafter(radius, np.inf))
        return np.where(np.isfinite(dist) & (dist <= radius), idx, -1).astype(np.intp)
    return _nearest_within_grid(queries, points, radius)


def _nearest_within_grid(queries: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Numpy-only :func:`nearest_within`: bin ``points`` into square cells of side ``radius`` and look at
    the 3x3 cells around each query, so the work grows with the number of close pairs, not ``N x M``."""
    origin = np.minimum(queries.min(axis=0), points.min(axis=0))
    cell = max(float(radius), 1e-12)
    pc = np.floor((points - origin) / cell).astype(np.int64)
    qc = np.floor((queries - origin) / cell).astype(np.int64)
    width = int(max(pc[:, 0].max(), qc[:, 0].max())) + 3  # keys of neighbouring cells never collide
    keys = (pc[:, 1] + 1) * width + (pc[:, 0] + 1)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    best = np.full(len(queries), -1, dtype=np.intp)
    best_d2 = np.full(len(queries), np.inf)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            k = (qc[:, 1] + 1 + dv) * width + (qc[:, 0] + 1 + du)
            start, stop = np.searchsorted(sorted_keys, k, "left"), np.searchsorted(sorted_keys, k, "right")
            counts = stop - start
            if not counts.any():
                continue
            qi = np.repeat(np.arange(len(queries)), counts)
            pi = order[np.repeat(start - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())]
            d2 = ((queries[qi] - points[pi]) ** 2).sum(axis=1)
            # the nearest candidate per query in this cell: sort by (query, distance, index), keep firsts
            o = np.lexsort((pi, d2, qi))
            first = o[np.r_[True, qi[o][1:] != qi[o][:-1]]]
            q_first, d_first, p_first = qi[first], d2[first], pi[first]
            better = (d_first < best_d2[q_first]) | ((d_first == best_d2[q_first]) & (p_first < best[q_first]))
            best[q_first[better]] = p_first[better]
            best_d2[q_first[better]] = d_first[better]
    return np.where(best_d2 <= radius * radius, best, -1)


def mutual_nearest(a: np.ndarray, b: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """``(M, 2)`` index pairs ``(i, j)`` such that ``b[j]`` is ``a[i]``'s nearest neighbour, ``a[i]`` is
    ``b[j]``'s, and they are at most ``radius`` apart. Each point is in at most one pair."""
    ab = nearest_within(a, b, radius, use_scipy=use_scipy)
    i = np.flatnonzero(ab >= 0)
    j = ab[i]
    hit = np.unique(j)  # only the points of b that some point of a chose need a reverse look-up
    ba = np.full(len(b), -1, dtype=np.intp)
    ba[hit] = nearest_within(b[hit], a, radius, use_scipy=use_scipy)
    mutual = ba[j] == i
    return np.stack([i[mutual], j[mutual]], axis=1)
