"""Gaussian splats of the demo scenes (pytest_n2r/demo/splats.py): bad arguments are named before any work."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.splats import sample_splats, similarity_transformed
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.splats.gaussians import Gaussians


@pytest.mark.parametrize("changes, message", [
    ({"opacity": 1.0}, r"opacity=1\.0 is out of range; expected a peak opacity in \(0, 1\)"),
    ({"opacity": 1.5}, r"opacity=1\.5 is out of range; expected a peak opacity in \(0, 1\)"),
    ({"opacity": 0.0}, r"opacity=0\.0 is out of range; expected a peak opacity in \(0, 1\)"),
    ({"opacity": float("nan")}, r"opacity=nan must be finite"),
    ({"spread": -0.5}, r"spread=-0\.5 must be > 0"),
    ({"spread": 0.0}, r"spread=0\.0 must be > 0"),
    ({"sh_noise": -0.1}, r"sh_noise=-0\.1 is out of range"),
])
def test_bad_splat_settings_are_named(changes, message):
    with pytest.raises(InvalidArgument, match=message):
        sample_splats(ground_truth("wall"), 64, **changes)


def _two_gaussians() -> Gaussians:
    return Gaussians(means=np.zeros((2, 3)), quats=np.tile([1.0, 0.0, 0.0, 0.0], (2, 1)),
                     log_scales=np.full((2, 3), -2.0), opacity_logits=np.zeros(2), sh=np.zeros((2, 1, 3)))


@pytest.mark.parametrize("scale", [0.0, -2.0])
def test_a_similarity_with_a_scale_not_above_zero_is_refused(scale):
    with pytest.raises(InvalidArgument, match=rf"scale={scale!r} must be > 0"):
        similarity_transformed(_two_gaussians(), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), scale)


def test_a_similarity_scales_the_gaussians():
    moved = similarity_transformed(_two_gaussians(), np.array([1.0, 0.0, 0.0, 0.0]), np.array([1.0, 2.0, 3.0]), 2.0)
    assert np.allclose(moved.means, [[1.0, 2.0, 3.0]] * 2), moved.means
    assert np.allclose(moved.log_scales, -2.0 + np.log(2.0)), "a scale of 2 must add log 2 to every log-scale"
