"""Failure pictures: the SUT's output drawn on the render, PNGs that round-trip."""

from __future__ import annotations

import cv2
import numpy as np

from pytest_n2r.relation.artifacts import draw_output, save_png


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
