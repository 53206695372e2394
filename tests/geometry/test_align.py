"""Umeyama similarity alignment recovers a known similarity."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import apply_similarity_to_pose, rotation_angle_deg, rotation_from_euler, umeyama

from .strategies import poses, transforms


@settings(deadline=None)
@given(transforms(), st.floats(0.01, 100.0), st.integers(0, 2**32 - 1))
def test_umeyama_recovers_a_similarity(tau, scale, seed):
    src = np.random.default_rng(seed).normal(size=(12, 3))
    R, t = tau.rotation, tau.translation
    dst = scale * src @ R.T + t
    s, R2, t2 = umeyama(src, dst)
    assert s == pytest.approx(scale, rel=1e-9)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-8 * (1 + scale))


@settings(deadline=None)
@given(poses(), transforms(), st.floats(0.1, 10.0))
def test_aligned_pose_moves_with_the_world(c2w, tau, s):
    out = apply_similarity_to_pose(c2w, s, tau.rotation, tau.translation)
    np.testing.assert_allclose(out[:3, 3], s * tau.rotation @ c2w[:3, 3] + tau.translation, atol=1e-12)
    assert rotation_angle_deg(out[:3, :3], tau.rotation @ c2w[:3, :3]) < 1e-6


def test_rotation_angle_of_known_rotation():
    assert rotation_angle_deg(np.eye(3), rotation_from_euler(0, 0, 30)) == pytest.approx(30.0)
    assert rotation_angle_deg(np.eye(3), rotation_from_euler(0, 180, 0)) == pytest.approx(180.0)


def test_umeyama_rejects_degenerate_input():
    with pytest.raises(ValueError, match="at least 3"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="coincide"):
        umeyama(np.ones((4, 3)), np.zeros((4, 3)))
    line = np.outer(np.arange(5.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        umeyama(line, line)


@pytest.mark.parametrize(("R", "which"), [
    (np.diag([1.0, 1.0, -1.0]), "a reflection read as a 0° rotation"),
    (1.5 * rotation_from_euler(0, 0, 30), "a scaled rotation read as 25.8°"),
    (np.full((3, 3), np.nan), "NaN"),
])
def test_the_angle_between_rotations_refuses_matrices_that_are_not_rotations(R, which):
    with pytest.raises(InvalidArgument, match=r"R_b (is not a rotation|contains 9 non-finite)"):
        rotation_angle_deg(np.eye(3), R)
    with pytest.raises(InvalidArgument, match=r"R_a (is not a rotation|contains 9 non-finite)"):
        rotation_angle_deg(R, np.eye(3))


def test_a_pose_with_a_nan_gap_is_never_the_nearest():
    from pytest_n2r.geometry.view_gap import nearest_pose

    nan_pose = np.full((4, 4), np.nan)
    assert nearest_pose(np.eye(4), [nan_pose, np.eye(4)], 1.0) == (1, 0.0, 0.0), "min() kept the NaN first"
