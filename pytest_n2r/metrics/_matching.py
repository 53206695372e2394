"""Mutual nearest neighbours between two 2-D point sets within a distance (k-d tree, or chunked numpy)."""

from __future__ import annotations

import numpy as np

__all__ = ["mutual_nearest", "nearest_within"]

try:  # scipy comes with scikit-image; the numpy path keeps the metrics working without it
    from scipy.spatial import cKDTree as _KDTree
except ImportError:  # pragma: no cover - exercised through use_scipy=False in the tests
    _KDTree = None

#: Rows of the distance matrix computed at once by the numpy path (bounds its memory to ~32 MB).
_CHUNK = 1024


def nearest_within(queries: np.ndarray, points: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """Index into ``points`` of each query's nearest point, or ``-1`` when none lies within ``radius``
    (Euclidean distance, inclusive)."""
    if len(points) == 0 or len(queries) == 0:
        return np.full(len(queries), -1, dtype=np.intp)
    if use_scipy and _KDTree is not None:
        # distance_upper_bound is exclusive; nudge it so a point exactly at `radius` still counts
        dist, idx = _KDTree(points).query(queries, k=1, distance_upper_bound=np.nextafter(radius, np.inf))
        return np.where(np.isfinite(dist) & (dist <= radius), idx, -1).astype(np.intp)
    out = np.empty(len(queries), dtype=np.intp)
    for start in range(0, len(queries), _CHUNK):
        q = queries[start:start + _CHUNK]
        d2 = ((q[:, None, :] - points[None, :, :]) ** 2).sum(axis=-1)
        j = np.argmin(d2, axis=1)
        ok = d2[np.arange(len(q)), j] <= radius * radius
        out[start:start + _CHUNK] = np.where(ok, j, -1)
    return out


def mutual_nearest(a: np.ndarray, b: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """``(M, 2)`` index pairs ``(i, j)`` such that ``b[j]`` is ``a[i]``'s nearest neighbour, ``a[i]`` is
    ``b[j]``'s, and they are at most ``radius`` apart. Each point is in at most one pair."""
    ab = nearest_within(a, b, radius, use_scipy=use_scipy)
    ba = nearest_within(b, a, radius, use_scipy=use_scipy)
    i = np.flatnonzero(ab >= 0)
    j = ab[i]
    mutual = ba[j] == i
    return np.stack([i[mutual], j[mutual]], axis=1)
