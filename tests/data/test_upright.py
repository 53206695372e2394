"""The up check: photos held upright agree on up in any frame; a photo turned half a turn about its viewing
direction is found, and only it; bad poses are named."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.data.upright import UPSIDE_DOWN_DEG, check_upright, upright_summary
from pytest_n2r.errors import InvalidArgument

from .synthetic import HALF_TURN, look_at


def _orbit(n: int, tilt_deg: float, rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` cameras around the origin, looking at it from up to ``tilt_deg`` above the horizon, each rolled by
    a hand's few degrees; world up is +z."""
    poses = []
    for k in range(n):
        azimuth, elevation = 2 * np.pi * k / n, np.radians(rng.uniform(0.0, tilt_deg))
        eye = 4.0 * np.array([np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation),
                              np.sin(elevation)])
        roll = np.radians(rng.uniform(-8.0, 8.0))
        c, s = np.cos(roll), np.sin(roll)
        poses.append(look_at(eye, np.zeros(3), up=np.array([0.0, 0.0, 1.0])) @ np.array(
            [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    return poses


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q * np.linalg.det(q)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 40), tilt=st.floats(0.0, 60.0), turned_share=st.floats(0.0, 0.45), seed=st.integers(0, 2**31))
def test_the_half_turned_photos_and_only_they_are_found_in_any_world_frame(n, tilt, turned_share, seed):
    rng = np.random.default_rng(seed)
    world = np.eye(4)
    world[:3, :3] = _random_rotation(rng)  # structure from motion's frame is arbitrary
    world[:3, 3] = rng.normal(size=3) * 10
    poses = _orbit(n, tilt, rng)
    turned = set(rng.choice(n, size=int(turned_share * n), replace=False).tolist())
    poses = [world @ (p @ HALF_TURN if k in turned else p) for k, p in enumerate(poses)]
    names = [f"p{k:02d}" for k in range(n)]
    check = check_upright(names, poses)
    assert set(check.upside_down) == {names[k] for k in turned}, (check.angles_deg.round(1), sorted(turned))
    # each up lies within tilt + roll of the world's, and so does the consensus (the principal axis of vectors
    # within a cone lies within it)
    right = [a for k, a in enumerate(check.angles_deg) if k not in turned]
    assert max(right) < 2 * (tilt + 8.0) + 1e-6, f"an upright photo {max(right):.1f}° off, tilt {tilt:.0f}°"


def test_a_photo_looking_straight_down_is_upright_whichever_way_it_is_turned():
    rng = np.random.default_rng(0)
    poses = _orbit(12, 20.0, rng)
    for roll in (0.0, 90.0, 180.0, 270.0):  # a phone held flat guesses its turn
        down = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3), up=np.array([0.0, 1.0, 0.0]))
        c, s = np.cos(np.radians(roll)), np.sin(np.radians(roll))
        rolled = down @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        check = check_upright([f"p{k}" for k in range(13)], [*poses, rolled])
        # on the horizon of the consensus, which lies within the others' tilt and roll (28°) of the world's up
        assert check.upside_down == () and abs(check.angles_deg[-1] - 90.0) < 28.0, (roll, check.angles_deg[-1])
    assert UPSIDE_DOWN_DEG - 90.0 >= 30.0, "the threshold keeps its margin over a photo looking straight down"


def test_the_record_and_its_summary():
    poses = [np.eye(4), np.eye(4), np.eye(4), HALF_TURN]
    record = check_upright(["a", "b", "c", "d"], poses).as_report()
    assert record == {"photos": 4, "threshold_deg": UPSIDE_DOWN_DEG, "largest_upright_deg": 0.0,
                      "upside_down": {"d": 180.0}}
    assert upright_summary(record) == "1 of 4 photos upside down against the others (d 180°; the others within 0°)"
    assert check_upright(["a", "b", "c"], poses[:3]).summary() == "3 photos agree on up (all within 0° of it)"


@pytest.mark.parametrize(("names", "poses", "match"), [
    (["a", "b"], [np.eye(4)] * 3, "2 names for 3 poses"),
    (["a", "b"], [np.eye(4)] * 2, "2 photos; at least 3"),
    (["a", "b", "c"], [np.eye(3)] * 3, r"poses of shape \(3, 3\)"),
    (["a", "b", "c"], [np.eye(4), np.full((4, 4), np.nan), np.eye(4)], "finite"),
])
def test_bad_poses_are_named(names, poses, match):
    with pytest.raises(InvalidArgument, match=match):
        check_upright(names, poses)
