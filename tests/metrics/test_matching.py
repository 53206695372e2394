"""The largest one-to-one matching of two point sets within a distance, against SciPy's Hopcroft-Karp, mutual
nearest neighbours whose distance ties go to the lowest index with SciPy and without, and the distance test's
slack for round-off."""

from __future__ import annotations

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis.extra.numpy import arrays
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching

from pytest_n2r.metrics._matching import _kd_tree, maximum_matching, mutual_nearest, pairs_within
from pytest_n2r.metrics.coverage import DISC_SLACK


def crowded(seed: int, n: int, spread: float) -> np.ndarray:
    """``n`` points in a ``spread`` px square: at a radius of a few px, many have several candidates."""
    return np.random.default_rng(seed).uniform(0.0, spread, size=(n, 2))


def largest_matching_size(a: np.ndarray, b: np.ndarray, radius: float) -> int:
    """The size of a maximum bipartite matching of the pairs within ``radius``, by SciPy (Hopcroft-Karp)."""
    if len(a) == 0 or len(b) == 0:
        return 0
    d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    graph = csr_matrix((d <= radius + DISC_SLACK).astype(np.int8))
    return int((maximum_bipartite_matching(graph, perm_type="column") >= 0).sum())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**16), n_a=st.integers(0, 80), n_b=st.integers(0, 80), spread=st.floats(5, 40),
       radius=st.floats(0.5, 4))
def test_the_matching_is_one_to_one_within_the_radius_and_as_large_as_one_can_be(seed, n_a, n_b, spread, radius):
    a, b = crowded(seed, n_a, spread), crowded(seed + 1, n_b, spread)
    pairs = maximum_matching(a, b, radius)
    i, j = pairs.T
    assert len(set(i.tolist())) == len(i) and len(set(j.tolist())) == len(j), f"a point paired twice: {pairs}"
    distances = np.hypot(*(a[i] - b[j]).T)
    far = distances > radius + DISC_SLACK
    assert not far.any(), f"pairs farther than {radius} px: {distances[far]}"
    assert len(pairs) == largest_matching_size(a, b, radius), "not a maximum matching"
    assert len(pairs) >= len(mutual_nearest(a, b, radius)), "fewer pairs than mutual nearest neighbours"


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), n_a=st.integers(0, 200), n_b=st.integers(0, 200), radius=st.floats(0.5, 10))
def test_numpy_pairs_and_matching_equal_the_kdtree_ones(seed, n_a, n_b, radius):
    a, b = crowded(seed, n_a, 60.0), crowded(seed + 1, n_b, 60.0)
    for fast, slow in zip(pairs_within(a, b, radius), pairs_within(a, b, radius, use_scipy=False), strict=True):
        np.testing.assert_array_equal(fast, slow)
    np.testing.assert_array_equal(maximum_matching(a, b, radius), maximum_matching(a, b, radius, use_scipy=False))


def test_pairs_are_listed_nearest_first_and_a_pair_exactly_at_the_radius_counts():
    a = np.array([[0.0, 0.0], [10.0, 0.0]])
    b = np.array([[2.0, 0.0], [10.5, 0.0], [0.0, 1.0], [0.0, 2.5]])
    for use_scipy in (True, False):
        i, j, d = pairs_within(a, b, 2.0, use_scipy=use_scipy)
        assert (i.tolist(), j.tolist(), d.tolist()) == ([1, 0, 0], [1, 2, 0], [0.5, 1.0, 2.0]), use_scipy


@pytest.mark.parametrize("use_scipy", [True, False], ids=["cKDTree", "numpy"])
def test_a_pair_at_the_radius_plus_round_off_counts_and_one_past_the_slack_does_not(use_scipy):
    """Mapped points carry round-off (1e-14 px through a homography, ~1e-7 px through float32 depth): a pair
    exactly ``radius`` apart before mapping must still count, so the test has the coverage mask's slack
    (``DISC_SLACK``); without it, one 2 px shift mapped through a homography scored 0 at ``px=2``."""
    a = np.array([[10.3, 20.7], [40.0, 20.0], [70.0, 20.0], [100.0, 20.0], [130.0, 20.0]])
    b = a + np.array([[2.0, 0.0], [0.0, 2.0 + 1e-12], [2.0 + DISC_SLACK / 2, 0.0], [2.001, 0.0], [0.0, 1.999]])
    i, j, _ = pairs_within(a, b, 2.0, use_scipy=use_scipy)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 0), (1, 1), (2, 2), (4, 4)]
    assert maximum_matching(a, b, 2.0, use_scipy=use_scipy).tolist() == [[0, 0], [1, 1], [2, 2], [4, 4]]
    assert mutual_nearest(a, b, 2.0, use_scipy=use_scipy).tolist() == [[0, 0], [1, 1], [2, 2], [4, 4]]


def test_a_crowded_set_moved_rigidly_is_matched_whole():
    """Points 1 px apart, all moved 1.2 px: each one's own counterpart is within 2 px, but a neighbour's is
    nearer, so mutual nearest neighbours keep one pair in two; the largest matching keeps every point."""
    centres = np.array([[u, v] for u in np.arange(10.0, 60.0, 10.0) for v in (10.0, 20.0)])
    a = np.vstack([centres, centres + [1.0, 0.0]])
    b = a + [1.2, 0.0]
    assert len(maximum_matching(a, b, 2.0)) == len(a)
    assert len(mutual_nearest(a, b, 2.0)) == len(a) // 2
    np.testing.assert_array_equal(maximum_matching(a, b, 2.0), np.column_stack([np.arange(len(a))] * 2))


def test_nearest_pairs_are_kept_where_the_count_allows():
    """Far-apart points are paired with their nearest counterpart, not another within the radius."""
    a = np.array([[0.0, 0.0], [30.0, 0.0]])
    b = np.array([[1.5, 0.0], [0.5, 0.0], [30.0, 1.9], [31.0, 0.0]])
    assert maximum_matching(a, b, 2.0).tolist() == [[0, 1], [1, 3]]


grid_points = st.integers(0, 30).flatmap(
    lambda n: arrays(np.float64, (n, 2), elements=st.integers(0, 10).map(float)))  # many equidistant points


@settings(max_examples=200, deadline=None)
@given(a=grid_points, b=grid_points, radius=st.sampled_from([0.5, 1.0, 1.5, 2.0, 3.0]))
def test_scipy_and_numpy_paths_break_distance_ties_alike_by_the_lowest_index(a, b, radius):
    """On an integer grid many points are equally near. cKDTree broke such ties by its tree layout, the numpy
    path by the lowest index: the mutual pairs differed with and without SciPy (25 of 400 random cases)."""
    assert _kd_tree() is not None, "SciPy is needed to compare its path with the numpy one"
    reach = radius + DISC_SLACK
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)  # what the metric computes, to the bit
    d2 = np.where(d2 <= reach * reach, d2, np.inf)
    lowest = [(i, int(np.argmin(d2[i]))) for i in range(len(a)) if len(b) and np.isfinite(d2[i]).any()]
    lowest = [[i, j] for i, j in lowest if int(np.argmin(d2[:, j])) == i]  # argmin: the lowest index of ties
    for use_scipy in (True, False):
        pairs = mutual_nearest(a, b, radius, use_scipy=use_scipy).tolist()
        assert pairs == lowest, f"{'cKDTree' if use_scipy else 'numpy'}: {pairs} are not the lowest-index {lowest}"
    fast, slow = mutual_nearest(a, b, radius), mutual_nearest(a, b, radius, use_scipy=False)
    assert fast.tolist() == slow.tolist(), f"mutual pairs with SciPy {fast.tolist()} != without {slow.tolist()}"


@settings(max_examples=100, deadline=None)
@given(a=grid_points, b=grid_points, far_a=grid_points, far_b=grid_points)
def test_points_added_far_away_change_no_mutual_pair(a, b, far_a, far_b):
    """Points more than the radius from every other change nobody's nearest neighbour, so no mutual pair
    (before, they changed cKDTree's layout and with it which of two equally near points it returned)."""
    radius = 2.0
    pairs = mutual_nearest(a, b, radius).tolist()
    for use_scipy in (True, False):
        more = mutual_nearest(np.vstack([a, far_a + 100.0]), np.vstack([b, far_b - 100.0]), radius,
                              use_scipy=use_scipy).tolist()
        assert more == pairs, f"{len(far_a) + len(far_b)} far points changed the mutual pairs {pairs} to {more}"
