"""Failure pictures: the SUT's output drawn on the render, PNGs that round-trip."""

from __future__ import annotations

import re

import cv2
import numpy as np

from pytest_n2r.relation.artifacts import artifact_dir, draw_output, save_png


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
