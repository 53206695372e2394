"""Comparing two pose sets image by image after a similarity alignment."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.cli.main import main
from pytest_n2r.data import PoseSet, compare_poses, read_transforms_json
from pytest_n2r.data.colmap import write_colmap_text
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import Transform, apply_similarity_to_pose, rotation_from_euler

from .synthetic import orbit_poses, write_transforms


def _set(names, c2ws, source="x") -> PoseSet:
    from pytest_n2r.data import SourceFrame
    from pytest_n2r.geometry import Camera

    cam = Camera(64, 48, 50.0, 50.0, 31.5, 23.5)
    return PoseSet([SourceFrame(n, None, cam, c) for n, c in zip(names, c2ws)], source=source)


@settings(deadline=None, max_examples=30)
@given(st.floats(-179, 179), st.floats(-89, 89), st.floats(-179, 179), st.floats(0.01, 100.0))
def test_a_similar_copy_has_zero_error(yaw, pitch, roll, scale):
    poses = orbit_poses(8)
    R = rotation_from_euler(roll, pitch, yaw)
    moved = [apply_similarity_to_pose(c, scale, R, np.array([1.0, -2.0, 3.0])) for c in poses]
    cmp = compare_poses(_set([f"images/{k}.jpg" for k in range(8)], poses), _set([f"{k}.jpg" for k in range(8)], moved))
    assert len(cmp.names) == 8 and cmp.names[0] == "0.jpg"
    assert cmp.rotation_deg.max() < 1e-5 and cmp.centre_error.max() < 1e-9
    assert cmp.scale == pytest.approx(scale, rel=1e-9)  # units of b per unit of a


def test_one_turned_camera_shows_its_error():
    poses = orbit_poses(8)
    turned = list(poses)
    turned[3] = Transform(yaw=2.0).apply(poses[3])
    names = [f"{k}.jpg" for k in range(8)]
    cmp = compare_poses(_set(names, turned), _set(names, poses))
    assert cmp.rotation_deg[3] == pytest.approx(2.0, abs=1e-9)
    assert np.delete(cmp.rotation_deg, 3).max() < 1e-9 and cmp.centre_error.max() < 1e-9
    assert "rotation error max 2.000 deg" in cmp.summary()


def test_images_only_in_one_set_are_listed():
    poses = orbit_poses(6)
    cmp = compare_poses(_set(["a", "b", "c", "d", "e"], poses[:5]), _set(["b", "c", "d", "e", "f"], poses[1:]))
    assert cmp.names == ["b", "c", "d", "e"] and cmp.only_a == ["a"] and cmp.only_b == ["f"]


def test_two_cameras_whose_file_names_repeat_are_matched_on_their_folders():
    """cam0/0000.jpg and cam1/0000.jpg were one key: identical pose sets of a two-camera rig compared as far apart."""
    poses = orbit_poses(8)
    names = [f"cam{k % 2}/{k // 2:04d}.jpg" for k in range(8)]
    same = compare_poses(_set(names, poses), _set(names, poses))
    assert sorted(same.names) == sorted(names), f"matched {same.names}"
    assert same.rotation_deg.max() < 1e-9 and same.centre_error.max() < 1e-9, \
        f"identical pose sets compare {same.rotation_deg.max():.1f} deg apart: images were paired wrongly"
    deeper = compare_poses(_set([f"images/{n}" for n in names], poses), _set(names, poses))
    assert deeper.rotation_deg.max() < 1e-9 and len(deeper.names) == 8, "images/cam0/0000.jpg is cam0/0000.jpg"


def test_file_names_several_images_share_without_telling_folders_are_an_error_naming_them():
    poses = orbit_poses(8)
    names = [f"cam{k % 2}/{k // 2:04d}.jpg" for k in range(8)]
    with pytest.raises(IngestError) as info:
        compare_poses(_set([n.split("/")[1] for n in names[::2]], poses[::2]), _set(names, poses))
    assert "cannot tell which image is which: 0000.jpg, 0001.jpg, 0002.jpg, 0003.jpg, cam0/0000.jpg, " \
           "cam0/0001.jpg and 6 more share file names" in str(info.value), \
        f"an ambiguous file name was not refused naming the images: {info.value}"


def test_too_few_common_images():
    poses = orbit_poses(4)
    with pytest.raises(IngestError, match="only 2 images are in both pose sets"):
        compare_poses(_set(["a", "b", "c"], poses[:3]), _set(["b", "c", "x"], poses[1:]))


def test_poses_compare_option(corner, tmp_path, capsys):
    json_path = write_transforms(corner)
    poses = read_transforms_json(json_path)
    poses.frames[2] = replace(poses.frames[2], c2w=Transform(pitch=1.5).apply(poses.frames[2].c2w))
    write_colmap_text(tmp_path / "model", poses)
    assert main(["poses", str(json_path), "--compare", str(tmp_path / "model")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("compare"))
    assert "(colmap): 6 common images: rotation error max 1.500 deg" in line, line
