"""The end of a fit's report: how far each held-out view is from the fitted ones, and the training views scored
the same way as the held-out ones (pytest_n2r.fit.evaluate.final_scores)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pytest_n2r.data.capture import CapturedView, heldout_split
from pytest_n2r.fit import evaluate_views
from pytest_n2r.fit.evaluate import TRAIN_SCORED, mean_scores, nearest_fitted, spread_out
from pytest_n2r.geometry import Camera
from pytest_n2r.relation.floor.nearby import nearest_fitted_view

CAMERA = Camera(8, 6, fx=6.0, fy=6.0, cx=3.5, cy=2.5)


def _frame(name: str, x: float, yaw_deg: float = 0.0, split: str = "train") -> CapturedView:
    """A camera at ``(x, 0, 0)`` (scene units) turned ``yaw_deg`` about its y axis."""
    c2w = np.eye(4)
    a = np.radians(yaw_deg)
    c2w[:3, :3] = [[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]]
    c2w[0, 3] = x
    return CapturedView(name, CAMERA, c2w, split)


def test_the_report_says_how_far_each_heldout_view_is_from_its_nearest_fitted_view(short_fit, capture48):
    report = short_fit.report
    train = [v for v in capture48.train_views if v.image is not None]
    names = {v.name for v in train}
    rows = report["heldout"]
    assert [r["view"] for r in rows] == [v.name for v in capture48.heldout_views]
    for row, view in zip(rows, capture48.heldout_views):
        # the same convention, and the same code, as the field floor's nearby photo
        scene = SimpleNamespace(name="object", views=capture48.views, reference_length=capture48.reference_length)
        near, degrees, distance = nearest_fitted_view(scene, view.c2w)
        assert row["nearest"] in names and row["nearest"] == near.name, row
        assert row["nearest_degrees"] == pytest.approx(degrees, abs=1e-3)
        assert row["nearest_distance"] == pytest.approx(distance, abs=1e-4)
    summary = report["nearest_fitted"]
    for what in ("degrees", "distance"):
        values = [r[f"nearest_{what}"] for r in rows]
        assert summary[what]["median"] == pytest.approx(float(np.median(values)), abs=1e-3), summary
        assert summary[what]["min"] == min(values), summary
    assert summary["distance"]["min"] > 0, "a held-out view of the demo capture sits on a fitted one"


def test_the_report_scores_training_views_as_it_scores_the_heldout_ones(short_fit, capture48):
    report = short_fit.report
    train = [v for v in capture48.train_views if v.image is not None]
    scored = report["train_scored"]
    assert len(scored) == TRAIN_SCORED < len(train)
    assert scored[0]["view"] == train[0].name and scored[-1]["view"] == train[-1].name, "not spread along the capture"
    assert scored == evaluate_views(short_fit.field, spread_out(train)), "not the held-out views' scoring"
    means = mean_scores(scored)
    assert (report["train_psnr"], report["train_ssim"]) == (means["psnr"], means["ssim"])
    assert report["train_psnr"] > report["psnr"] - 3.0, "the fitted views score far below the held-out ones"


def test_video_frames_held_out_between_fitted_ones_are_near_them_photos_of_an_orbit_are_not():
    """The reviewer's portrait video: held-out frames lie 0.02-0.07 reference lengths and 1.4-4.6° from a fitted
    one; a capture walked around its subject, 0.13-0.15 and 6.8-8.9°. The report's gaps show the difference."""
    split = heldout_split(40)
    video = [_frame(f"f{i:03d}", 0.01 * i, 0.6 * i, s) for i, s in enumerate(split)]  # one frame a 1/100 s step
    orbit = [_frame(f"p{i:03d}", 0.15 * i, 8.0 * i, s) for i, s in enumerate(split)]
    for views, step, turn in ((video, 0.01, 0.6), (orbit, 0.15, 8.0)):
        held = [v for v in views if v.split == "heldout"]
        rows = nearest_fitted(held, [v for v in views if v.split == "train"], reference_length=1.0)
        for row, view in zip(rows, held):  # the frame before or after (as near: rounding picks one)
            i = int(view.name[1:])
            assert row["nearest"] in {views[j].name for j in (i - 1, i + 1) if 0 <= j < len(views)}, (view, row)
        assert all(r["nearest_distance"] == pytest.approx(step, abs=1e-4) for r in rows), rows
        assert all(r["nearest_degrees"] == pytest.approx(turn, abs=1e-3) for r in rows), rows


def test_spread_out_keeps_every_view_when_there_are_few():
    assert spread_out(list("abc"), 8) == list("abc")
    assert spread_out(list(range(43)), 8) == [0, 6, 12, 18, 24, 30, 36, 42]
