"""Failure pictures: the SUT's output drawn on the render, PNGs that round-trip, removed once stale."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from pytest_n2r.relation import Relation, RelationFailure, RunSettings, check_relation
from pytest_n2r.relation.artifacts import PICTURE_NAMES, artifact_dir, draw_output, remove_pictures, save_pair, save_png
from pytest_n2r.strategies import transforms
from tests.plugin.fakemetrics import AbsDifference
from tests.plugin.fakescene import PlaneScene, decode_ramp_x


def test_draw_output_marks_keypoints_and_labels():
    rgb = np.zeros((60, 80, 3), np.uint8)
    circled = draw_output(rgb, np.array([[40.0, 30.0]]))
    assert circled[30, 40:48].any() and not circled[5:10, 60:70].any()
    labelled = draw_output(rgb, np.array([0.1, 0.7, 0.2]))
    assert labelled.any()
    assert not draw_output(rgb, {"odd": "output"}).any(), "unknown outputs are saved undecorated"
    assert not rgb.any(), "the input must not be drawn on"


def test_save_png_round_trips_rgb(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 255, (9, 11, 3), dtype=np.uint8)
    path = save_png(tmp_path / "a" / "x.png", rgb)
    np.testing.assert_array_equal(cv2.imread(str(path))[..., ::-1], rgb)


def test_each_test_id_has_its_own_readable_picture_folder(tmp_path):
    long = "test_a.py::test_b[" + "x" * 200
    ids = ["test_a.py::test_b[a-b]", "test_a.py::test_b[a_b]", "test_a.py::test_b[a b]", "test_a.py::test_b[a/b]",
           long + "1]", long + "2]", "", "::"]
    folders = [artifact_dir(tmp_path, i) for i in ids]
    assert len({f.name for f in folders}) == len(ids), (
        f"test ids that differ only in punctuation or after 150 characters share a folder: {folders}")
    assert all(len(f.name) <= 150 + 9 for f in folders), f"a folder name is too long: {max(folders, key=len)}"
    assert all(re.fullmatch(r"[A-Za-z0-9_.-]+", f.name) for f in folders), f"unsafe folder names: {folders}"
    folder = artifact_dir(tmp_path, "test_a.py::test_b[fox]")
    assert folder.parent == tmp_path and re.fullmatch(r"test_a\.py-test_b-fox-[0-9a-f]{8}", folder.name), (
        f"the folder should be the test id made filename-safe and a short hash: {folder.name}")
    assert artifact_dir(tmp_path, "test_a.py::test_b[fox]") == folder, "one test id must keep one folder"


def test_removing_pictures_removes_only_what_save_pair_wrote(tmp_path):
    rgb = np.zeros((6, 8, 3), np.uint8)
    kept, cleared = artifact_dir(tmp_path, "t.py::test_kept"), artifact_dir(tmp_path, "t.py::test_cleared")
    for folder in (kept, cleared):
        save_pair(folder, rgb, rgb, 1, 2)
    (kept / "notes.txt").write_text("the user's")
    other = tmp_path / "unrelated.png"
    other.write_bytes(b"not ours")
    assert {p.name for p in remove_pictures(tmp_path, "t.py::test_kept")} == set(PICTURE_NAMES.values())
    assert [p.name for p in kept.iterdir()] == ["notes.txt"], "a file pytest-n2r did not write must stay"
    assert remove_pictures(tmp_path, "t.py::test_cleared") and not cleared.exists(), "an emptied folder goes"
    assert other.is_file() and tmp_path.is_dir(), "nothing outside the test's folder is touched"
    assert remove_pictures(tmp_path, "t.py::test_cleared") == [] and remove_pictures(tmp_path / "none", "x") == []


def test_removing_pictures_does_not_follow_symbolic_links(tmp_path):
    outside = tmp_path / "outside"
    save_pair(outside, np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8, 3), np.uint8), 1, 2)
    root = tmp_path / "artifacts"
    root.mkdir()
    artifact_dir(root, "t.py::test_linked").symlink_to(outside, target_is_directory=True)
    folder = artifact_dir(root, "t.py::test_file_links")
    folder.mkdir()
    (folder / "source.png").symlink_to(outside / "source.png")
    assert remove_pictures(root, "t.py::test_linked") == [] and remove_pictures(root, "t.py::test_file_links") == []
    assert sorted(p.name for p in outside.iterdir()) == sorted(PICTURE_NAMES.values())
    assert (folder / "source.png").is_symlink()


def _run(tmp_path, eps, sut=lambda rgb: float(decode_ramp_x(rgb)[36, 48])):
    relation = Relation.build(AbsDifference(), eps, transforms(yaw=10), examples=20)
    return check_relation(PlaneScene(texture="ramp"), sut, relation, test_id="t.py::test[plane]",
                          settings=RunSettings(artifacts=tmp_path, database=None))


def test_a_run_without_failure_pictures_removes_those_of_an_earlier_failure(tmp_path):
    """A test that failed, then passes (its eps loosened): its old pictures would show a failure that is gone."""
    folder = artifact_dir(tmp_path, "t.py::test[plane]")
    with pytest.raises(RelationFailure):
        _run(tmp_path, 0.05)
    assert sorted(p.name for p in folder.iterdir()) == sorted(PICTURE_NAMES.values())
    (tmp_path / "other-test-1234abcd").mkdir()
    assert _run(tmp_path, 255).outcome == "passed"
    assert not folder.exists(), f"stale failure pictures left: {list(folder.iterdir())}"
    assert [p.name for p in tmp_path.iterdir()] == ["other-test-1234abcd"], "other tests' folders stay"
    with pytest.raises(RelationFailure):
        _run(tmp_path, 0.05)

    def broken(rgb):
        raise ValueError("the SUT broke")

    with pytest.raises(Exception, match="the SUT broke"):  # a run that ends in an error shows no pictures either
        _run(tmp_path, 0.05, broken)
    assert not folder.exists()
    with pytest.raises(RelationFailure):
        _run(tmp_path, 0.05)

    def interrupted(rgb):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _run(tmp_path, 0.05, interrupted)
    assert folder.is_dir(), "an interrupted run did not end: the pictures of the last one that did stay"


def test_each_picture_shows_its_own_render_and_output(tmp_path):
    """The follow-up's pictures are the follow-up render with the follow-up's output drawn, not the source's."""
    source = np.zeros((60, 80, 3), np.uint8)
    follow = np.full((60, 80, 3), 200, np.uint8)
    paths = save_pair(tmp_path, source, follow, np.array([[10.0, 10.0]]), np.array([[60.0, 45.0]]))
    read = {role: cv2.imread(path)[..., ::-1] for role, path in paths.items()}
    np.testing.assert_array_equal(read["source_raw"], source)
    np.testing.assert_array_equal(read["follow_raw"], follow)
    np.testing.assert_array_equal(read["follow"], draw_output(follow, np.array([[60.0, 45.0]]), (235, 50, 50)))
    np.testing.assert_array_equal(read["source"], draw_output(source, np.array([[10.0, 10.0]])))


def test_keypoints_with_nan_coordinates_are_drawn_without_them():
    """A detector may return NaN rows: the finite keypoints are circled and the picture is still saved (an error
    there turned a relation's failure into a crash)."""
    rgb = np.zeros((60, 80, 3), np.uint8)
    drawn = draw_output(rgb, np.array([[np.nan, 5.0], [40.0, 30.0], [np.inf, np.nan]]))
    assert drawn[30, 40:48].any() and not drawn[5:10, 60:70].any()
