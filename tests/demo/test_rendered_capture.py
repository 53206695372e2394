"""The size of a rendered demo capture (``capture_scene``, ``check_size``)."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.rendered_capture import check_size
from pytest_n2r.errors import InvalidArgument, InvalidType


@pytest.mark.parametrize("size, expected", [(96, (96, 54)), ((64, 36), (64, 36)), ((np.int64(32), 18), (32, 18))])
def test_a_size_is_the_longer_side_or_a_pair_of_ints(size, expected):
    camera = check_size(size, ground_truth("wall").views[0].camera)
    assert (camera.width, camera.height) == expected, (size, camera)


@pytest.mark.parametrize("size, error, message", [
    ((480.7, 270.2), InvalidType, r"size=\(480\.7, 270\.2\) must be an int .* or a \(width, height\) pair of ints"),
    ((True, 64), InvalidType, r"pair of ints"),
    ((64, 36, 3), InvalidType, r"pair of ints"),
    ("64x36", InvalidType, r"pair of ints"),
    ((4, 36), InvalidArgument, r"gives 4x36 pixels; expected at least 8x8"),
])
def test_a_size_that_is_no_pixel_count_is_refused_not_truncated(size, error, message):
    """``(480.7, 270.2)`` rendered at 480x270: the fractions were dropped without a word."""
    with pytest.raises(error, match=message):
        check_size(size, ground_truth("wall").views[0].camera)
