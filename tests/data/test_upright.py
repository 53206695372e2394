"""The up check: photos held upright agree on up in any frame; a photo turned half a turn about its viewing
direction is found, and only it; bad poses are named."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.data.upright import UPSIDE_DOWN_DEG, check_upright, upright_summary
from pytest_n2r.errors import InvalidArgument, InvalidType

from .synthetic import HALF_TURN, in_a_random_frame, look_at, ring_poses, rolled


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 60), lowest=st.floats(0.0, 75.0), seed=st.integers(0, 2**31))
def test_photos_held_upright_agree_however_steeply_they_look_down(n, lowest, seed):
    # each ring within 10°: past 55° down its up axes' principal axis lies on the horizon, which a consensus taken
    # as that axis would follow (the first version of the check did)
    rng = np.random.default_rng(seed)
    poses = in_a_random_frame(ring_poses(n, rng, (lowest, lowest + 10.0)), rng)
    check = check_upright([f"p{k:02d}" for k in range(n)], poses)
    assert check.upside_down == () and not check.doubtful, (check.angles_deg.round(1), lowest)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 60), steepest=st.floats(0.0, 20.0), turned_share=st.floats(0.0, 0.45),
       seed=st.integers(0, 2**31))
def test_the_half_turned_photos_and_only_they_are_found(n, steepest, turned_share, seed):
    # a turned photo's up lies 180° - (its elevation + roll) from the world's up: past 120° while that and the
    # consensus's own offset (within the others' elevation + roll) stay under 60° together
    rng = np.random.default_rng(seed)
    poses = ring_poses(n, rng, (0.0, steepest))
    turned = set(rng.choice(n, size=int(turned_share * n), replace=False).tolist())
    poses = in_a_random_frame([p @ HALF_TURN if k in turned else p for k, p in enumerate(poses)], rng)
    names = [f"p{k:02d}" for k in range(n)]
    check = check_upright(names, poses)
    assert set(check.upside_down) == {names[k] for k in turned}, (check.angles_deg.round(1), sorted(turned))
    assert check.doubtful == (len(turned) > 0.25 * n)


@pytest.mark.parametrize(("rings", "photos"), [([(60.0, 60.0)], 12), ([(60.0, 60.0)], 36), ([(75.0, 75.0)], 36),
                                               ([(45.0, 45.0), (75.0, 75.0)], 24)])
def test_a_capture_looking_steeply_down_keeps_its_consensus_on_the_vertical(rings, photos):
    rng = np.random.default_rng(1)
    poses = [p for ring in rings for p in ring_poses(photos, rng, ring)]
    check = check_upright([f"p{k:02d}" for k in range(len(poses))], poses)
    assert np.degrees(np.arccos(check.up[2])) < 3.0, f"consensus {check.up.round(3)} is not the world's up"
    assert check.upside_down == () and not check.doubtful


def test_photos_looking_straight_down_split_as_a_walk_to_and_fro_does():
    """A floor photographed in rows, the photographer turning round at each row's end: the photos' up axes point
    along the walk, one way then the other. Right poses, which the check cannot tell from a half-turn error:
    doubtful (``upright=False`` keeps them)."""
    check = check_upright([f"p{k:02d}" for k in range(24)], _floor_walk((False, True, False, True)))
    assert len(check.upside_down) == 12 and check.doubtful


def _floor_walk(rows: tuple[bool, ...], steps: int = 6) -> list[np.ndarray]:
    """Photos looking straight down at a floor in rows, the phone's up along the walk: ``True`` rows walked back."""
    poses = []
    for row, back in enumerate(rows):
        for step in range(steps):
            pose = look_at(np.array([float(step), float(row), 3.0]), np.array([float(step), float(row), 0.0]),
                           up=np.array([1.0, 0.0, 0.0]))
            poses.append(pose @ HALF_TURN if back else pose)
    return poses


def test_few_photos_looking_steeply_down_are_not_judged():
    """Three photos looking down 70-80°, 120° apart: their up axes fan out so widely that a consensus can fall
    between two and put the third 140° off (Hypothesis found it); the check judges none."""
    rng = np.random.default_rng(0)
    check = check_upright(["p0", "p1", "p2"], in_a_random_frame(ring_poses(3, rng, (70.0, 80.0)), rng))
    assert max(check.angles_deg) >= UPSIDE_DOWN_DEG, f"the draw no longer makes the case: {check.angles_deg}"
    assert not check.judged and check.upside_down == () and not check.doubtful
    assert check.summary() == ("3 photos' up axes fan out too widely to tell a photo turned half a turn from one "
                               "looking steeply down: none judged")


def test_a_floor_walked_mostly_one_way_loses_its_return_photos():
    """The documented limit: a return a quarter of the photos or less is skipped though its poses are right."""
    check = check_upright([f"p{k:02d}" for k in range(24)], _floor_walk((False, False, False, True)))
    assert check.upside_down == tuple(f"p{k}" for k in range(18, 24)) and not check.doubtful


@pytest.mark.parametrize("turned", [0, 20])
def test_more_photos_than_starts(turned):
    """150 photos: the consensus starts from 64 of them (and the mean), not from every one."""
    rng = np.random.default_rng(3)
    poses = ring_poses(150, rng, (0.0, 20.0))
    picked = set(rng.choice(150, size=turned, replace=False).tolist())
    check = check_upright([f"p{k:03d}" for k in range(150)],
                          in_a_random_frame([p @ HALF_TURN if k in picked else p for k, p in enumerate(poses)], rng))
    assert set(check.upside_down) == {f"p{k:03d}" for k in picked} and not check.doubtful
    split = check_upright([f"p{k:03d}" for k in range(150)], _floor_walk((False, True) * 15, steps=5))
    assert len(split.upside_down) == 75 and split.doubtful


def test_a_photo_looking_straight_down_among_upright_ones_is_not_upside_down():
    rng = np.random.default_rng(0)
    poses = ring_poses(12, rng, (0.0, 20.0))
    down = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3), up=np.array([0.0, 1.0, 0.0]))
    for roll in (0.0, 90.0, 180.0, 270.0):  # a phone held flat guesses its turn
        check = check_upright([f"p{k}" for k in range(13)], [*poses, rolled(down, roll)])
        # on the horizon of the consensus, which lies within the others' tilt and roll of the world's up
        assert check.upside_down == () and abs(check.angles_deg[-1] - 90.0) < 28.0, (roll, check.angles_deg[-1])


@pytest.mark.parametrize(("photos", "turned", "doubtful"), [(4, 1, False), (3, 1, True), (8, 2, False), (8, 3, True)])
def test_more_than_a_quarter_upside_down_is_doubtful(photos, turned, doubtful):
    check = check_upright([f"p{k}" for k in range(photos)], [np.eye(4)] * (photos - turned) + [HALF_TURN] * turned)
    assert len(check.upside_down) == turned and check.doubtful == doubtful


def test_the_record_and_its_summary():
    poses = [np.eye(4), np.eye(4), np.eye(4), HALF_TURN]
    record = check_upright(["a", "b", "c", "d"], poses).as_report()
    assert record == {"photos": 4, "threshold_deg": UPSIDE_DOWN_DEG, "judged": True, "largest_upright_deg": 0.0,
                      "upside_down": {"d": 180.0}, "doubtful": False}
    assert upright_summary(record) == "1 of 4 photos upside down against the others (d 180°; the others within 0°)"
    assert check_upright(["a", "b", "c"], poses[:3]).summary() == "3 photos agree on up (all within 0° of it)"
    many = check_upright([f"p{k}" for k in range(14)], [np.eye(4)] * 7 + [HALF_TURN] * 7).summary()
    assert many.startswith("7 of 14 photos upside down") and "and 2 more" in many, many
    assert many.endswith(": too many for a few wrong poses"), many
    assert upright_summary({**record, "dropped": True}).endswith(": skipped (--any-roll keeps them)")
    assert upright_summary({**record, "dropped": False}).endswith(": kept, as --any-roll asks")


@pytest.mark.parametrize(("names", "poses", "error", "match"), [
    (["a", "b"], [np.eye(4)] * 3, InvalidArgument, "2 names for 3 poses"),
    (["a", "b"], [np.eye(4)] * 2, InvalidArgument, "2 photos; at least 3"),
    (["a", "b", "a"], [np.eye(4)] * 3, InvalidArgument, r"names \['a'\] given more than once"),
    (["a", "b", "c"], [np.eye(3)] * 3, InvalidType, r"c2w must have shape \(N 4 4\), got \(3, 3, 3\)"),
    (["a", "b", "c"], [np.eye(4), np.eye(3), np.eye(4)], InvalidType, "c2w must be an array of shape"),
    (["a", "b", "c"], [np.eye(4), np.full((4, 4), np.nan), np.eye(4)], InvalidArgument, "c2w contains 16 non-finite"),
])
def test_bad_poses_are_named(names, poses, error, match):
    with pytest.raises(error, match=match):
        check_upright(names, poses)
