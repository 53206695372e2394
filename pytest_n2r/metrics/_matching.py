"""Matching two 2-D point sets within a distance: the pairs within it, mutual nearest neighbours and the
largest one-to-one matching (k-d tree, or binned numpy). "Within ``radius``" is inclusive, plus
:data:`~pytest_n2r.metrics.coverage.DISC_SLACK` for round-off in mapped points."""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numpy as np

from .coverage import DISC_SLACK

__all__ = ["maximum_matching", "mutual_nearest", "pairs_within"]


@functools.cache
def _kd_tree() -> Any:
    """SciPy's ``cKDTree``, imported on the first match (0.2-0.3 s: a warm main job that takes every keypoint
    metric's result from the render cache needs none), or ``None`` without SciPy."""
    try:  # scipy comes with scikit-image; the numpy path keeps the metrics working without it
        from scipy.spatial import cKDTree
    except ImportError:  # pragma: no cover - exercised through use_scipy=False in the tests
        return None
    return cKDTree


def _firsts(key: np.ndarray, d2: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Indices of the pairs that are nearest for their ``key`` point, ties going to the lowest ``other`` index
    (the pairs sorted by ``(key, d2, other)``, the first of each key)."""
    order = np.lexsort((other, d2, key))
    return order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(order) else order


def _close_pairs(a: np.ndarray, b: np.ndarray, radius: float,
                 use_scipy: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(i, j, d2)``: every pair of ``a[i]`` and ``b[j]`` at most ``radius`` apart (inclusive, plus
    :data:`~pytest_n2r.metrics.coverage.DISC_SLACK`, so that round-off in mapped points cannot drop a pair
    exactly ``radius`` apart) and its squared distance, in no particular order. The k-d tree (``use_scipy`` and
    SciPy present) and the binned numpy search only propose candidates; the squared distances and the test
    against the radius are the same numpy arithmetic on both paths, so both give the same pairs to the bit."""
    empty = np.zeros(0, dtype=np.intp)
    if len(a) == 0 or len(b) == 0:
        return empty, empty, np.zeros(0)
    reach = radius + DISC_SLACK
    tree = _kd_tree() if use_scipy else None
    if tree is not None:  # candidates a little past reach; the test below decides
        found = tree(a).sparse_distance_matrix(tree(b), np.nextafter(reach, np.inf), output_type="ndarray")
        i, j = found["i"].astype(np.intp), found["j"].astype(np.intp)
        d2 = ((a[i] - b[j]) ** 2).sum(axis=1)
    else:
        cells = list(_cell_pairs(a, b, reach))
        i, j, d2 = (np.concatenate([c[k] for c in cells]) for k in range(3)) if cells else (empty, empty, np.zeros(0))
    near = d2 <= reach * reach
    return i[near], j[near], d2[near]


def _cell_pairs(queries: np.ndarray, points: np.ndarray,
                radius: float) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``(query index, point index, squared distance)`` arrays of every pair whose point lies in one of the 3x3
    square cells of side ``radius`` around the query's cell, one cell offset at a time: a superset of the pairs
    within ``radius`` whose size grows with the number of close pairs, not ``N x M``."""
    origin = np.minimum(queries.min(axis=0), points.min(axis=0))
    cell = max(float(radius), 1e-12)
    pc = np.floor((points - origin) / cell).astype(np.int64)
    qc = np.floor((queries - origin) / cell).astype(np.int64)
    width = int(max(pc[:, 0].max(), qc[:, 0].max())) + 3  # keys of neighbouring cells never collide
    keys = (pc[:, 1] + 1) * width + (pc[:, 0] + 1)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            k = (qc[:, 1] + 1 + dv) * width + (qc[:, 0] + 1 + du)
            start, stop = np.searchsorted(sorted_keys, k, "left"), np.searchsorted(sorted_keys, k, "right")
            counts = stop - start
            if not counts.any():
                continue
            qi = np.repeat(np.arange(len(queries)), counts)
            pi = order[np.repeat(start - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())]
            yield qi, pi, ((queries[qi] - points[pi]) ** 2).sum(axis=1)


def pairs_within(a: np.ndarray, b: np.ndarray, radius: float, *,
                 use_scipy: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair ``(i, j)`` with ``a[i]`` and ``b[j]`` at most ``radius`` apart (Euclidean, inclusive, plus the
    slack), as the index arrays ``i``, ``j`` and the distances, nearest first (ties by ``i``, then ``j``)."""
    i, j, d2 = _close_pairs(a, b, radius, use_scipy)
    d = np.sqrt(d2)
    order = np.lexsort((j, i, d))
    return i[order], j[order], d[order]


def maximum_matching(a: np.ndarray, b: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """``(M, 2)`` index pairs ``(i, j)``, ``a[i]`` and ``b[j]`` at most ``radius`` apart, each point in at most
    one pair, with as many pairs as that allows (a maximum bipartite matching).

    The nearest pairs are taken first (every pair of mutual nearest neighbours among them); then each point of
    ``a`` left over gets a partner where an augmenting path reassigns others within ``radius``: a point whose
    neighbour took its counterpart pairs with the neighbour's instead, where mutual nearest neighbours would
    leave both unmatched.

    >>> a = np.array([[0.0, 0.0], [1.0, 0.0]])
    >>> maximum_matching(a, a + [1.2, 0.0], 2.0).tolist()   # both moved 1.2 px: both found again
    [[0, 0], [1, 1]]
    >>> mutual_nearest(a, a + [1.2, 0.0], 2.0).tolist()     # a[1]'s counterpart is nearer a[0]'s
    [[1, 0]]
    """
    i, j, _ = pairs_within(a, b, radius, use_scipy=use_scipy)
    mate_a, mate_b = [-1] * len(a), [-1] * len(b)
    for u, v in zip(i.tolist(), j.tolist(), strict=True):  # nearest first
        if mate_a[u] < 0 and mate_b[v] < 0:
            mate_a[u], mate_b[v] = v, u
    by_a = np.argsort(i, kind="stable")  # each point's candidates, still nearest first
    starts = np.searchsorted(i[by_a], np.arange(len(a) + 1))
    neighbours = j[by_a].tolist()
    adjacency = [neighbours[s:e] for s, e in zip(starts[:-1].tolist(), starts[1:].tolist(), strict=True)]
    free = [u for u in range(len(a)) if mate_a[u] < 0 and adjacency[u]]
    while free:  # Kuhn's augmenting paths, one visited set a pass, until a pass finds none
        seen = [False] * len(b)
        left = [u for u in free if not _augment(u, adjacency, mate_a, mate_b, seen)]
        if len(left) == len(free):
            break
        free = left
    pairs = [(u, v) for u, v in enumerate(mate_a) if v >= 0]
    return np.array(pairs, dtype=np.intp).reshape(-1, 2)


def _augment(root: int, adjacency: list[list[int]], mate_a: list[int], mate_b: list[int], seen: list[bool]) -> bool:
    """Whether an alternating path from the free point ``root`` of ``a`` reaches a free point of ``b`` through
    points not yet ``seen``; if so, the matching along it is flipped (one pair more). Iterative depth-first."""
    stack = [(root, 0)]  # (point of a, index of the next candidate to try)
    via: list[int] = []  # the point of b each stacked point of a (but the root) was reached through
    while stack:
        u, k = stack[-1]
        if k == len(adjacency[u]):
            stack.pop()
            if via:
                via.pop()
            continue
        stack[-1] = (u, k + 1)
        v = adjacency[u][k]
        if seen[v]:
            continue
        seen[v] = True
        if mate_b[v] < 0:  # a free point of b: flip the path
            for (w, _), x in zip(stack, [*via, v], strict=True):
                mate_a[w], mate_b[x] = x, w
            return True
        via.append(v)
        stack.append((mate_b[v], 0))
    return False


def mutual_nearest(a: np.ndarray, b: np.ndarray, radius: float, *, use_scipy: bool = True) -> np.ndarray:
    """``(M, 2)`` index pairs ``(i, j)`` such that ``b[j]`` is ``a[i]``'s nearest neighbour, ``a[i]`` is
    ``b[j]``'s, and they are at most ``radius`` apart. Each point is in at most one pair, sorted by ``i``. Of
    points equally near, the lowest index is the nearest, with SciPy or without, so points added far away (more
    than ``radius`` from every point) change no pair."""
    i, j, d2 = _close_pairs(a, b, radius, use_scipy)
    nearest_of_a = np.zeros(len(i), dtype=bool)
    nearest_of_a[_firsts(i, d2, j)] = True
    nearest_of_b = np.zeros(len(i), dtype=bool)
    nearest_of_b[_firsts(j, d2, i)] = True
    mutual = np.flatnonzero(nearest_of_a & nearest_of_b)
    mutual = mutual[np.argsort(i[mutual], kind="stable")]
    return np.stack([i[mutual], j[mutual]], axis=1)
