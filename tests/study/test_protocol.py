"""`n2r study` follows the paper's protocol: its detectors keep the N highest-response points (`--points`, the paper's
100), and RQ2 draws the same whether RQ1 runs or not."""

from __future__ import annotations

import csv
import random

import numpy as np
import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.demo import ground_truth
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.study import StudyConfig, resolve_sut, run_study, write_study


@pytest.fixture(scope="module")
def wall_image() -> np.ndarray:
    """demo:wall's first view at 320 pixels: hundreds of ORB and SIFT points, about 150 AKAZE ones."""
    scene = ground_truth("wall")
    view = scene.views[0]
    return scene.render(view.c2w, view.camera.fit_within(320), ("rgb",)).rgb


def _top(keypoints: list, n: int) -> np.ndarray:
    """The pixel coordinates of the ``n`` keypoints of largest response (ties by y, x, size, angle, octave)."""
    ranked = sorted(keypoints, key=lambda k: (-k.response, k.pt[1], k.pt[0], k.size, k.angle, k.octave))
    return np.array([k.pt for k in ranked[:n]], np.float32).reshape(-1, 2)


@pytest.mark.parametrize("name", ["sift", "akaze"])
def test_points_keeps_the_n_of_largest_response(name, wall_image):
    """The built-in detectors kept up to 1000 points (AKAZE all) where the paper kept the 100 most confident; with
    points=N, SIFT and AKAZE keep exactly the N of largest response of their uncapped detection."""
    import cv2

    uncapped = {"sift": lambda: cv2.SIFT_create(),
                "akaze": lambda: (getattr(cv2, "AKAZE_create", None) or cv2.xfeatures2d.AKAZE_create)()}[name]()
    every = uncapped.detect(cv2.cvtColor(wall_image, cv2.COLOR_RGB2GRAY), None)
    assert len(every) > 60, f"the image must have more points than kept: {len(every)}"
    sut = resolve_sut(name, None, points=50)
    assert sut.points == 50
    np.testing.assert_array_equal(sut.fn(wall_image), _top(every, 50))


def test_orb_is_configured_for_n_points(wall_image):
    """ORB keeps what ORB configured for N points (nfeatures=N) finds: at most N, as its pyramid levels share them
    (43 of 50 here: the coarse levels find fewer corners than their share)."""
    import cv2

    orb = cv2.ORB_create(nfeatures=50).detect(cv2.cvtColor(wall_image, cv2.COLOR_RGB2GRAY), None)
    out = resolve_sut("orb", None, points=50).fn(wall_image)
    assert 0 < len(out) <= 50
    np.testing.assert_array_equal(out, _top(orb, 50))


def test_without_points_the_detectors_are_as_before(wall_image):
    """points=None (the fidelity report and `n2r info --shift`) keeps OpenCV's caps: 1000 for ORB and SIFT."""
    import cv2

    gray = cv2.cvtColor(wall_image, cv2.COLOR_RGB2GRAY)
    for name, make in (("orb", lambda: cv2.ORB_create(nfeatures=1000)), ("sift", lambda: cv2.SIFT_create(1000))):
        sut = resolve_sut(name, None)
        assert sut.points is None
        want = np.array([k.pt for k in make().detect(gray, None)], np.float32).reshape(-1, 2)
        np.testing.assert_array_equal(sut.fn(wall_image), want)
        assert len(want) > 100


def test_ties_are_broken_by_position_not_by_listing_order():
    """Equal responses: the same points kept whatever order the detector lists them in."""
    import cv2

    from pytest_n2r.study.suts import _strongest

    keypoints = [cv2.KeyPoint(float(x), float(y), 3.0, -1, 1.0 if x < 4 else 0.5) for x in range(8) for y in range(3)]
    kept = [{k.pt for k in _strongest(random.Random(s).sample(keypoints, len(keypoints)), 5)} for s in range(5)]
    assert all(k == kept[0] for k in kept)
    assert kept[0] == {(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0), (0.0, 1.0)}


@pytest.mark.parametrize("points", [0, -3, 2.5, True, "100"])
def test_bad_points_are_refused(points):
    with pytest.raises(InvalidArgument, match="--points"):
        resolve_sut("orb", None, points=points)


def test_cli_refuses_bad_points_before_any_work(tmp_path, capsys):
    code = main(["study", "demo:wall", "--sut", "orb", "-o", str(tmp_path / "out"), "--points", "0"])
    assert code != 0
    assert "--points 0: expected a positive integer" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_the_outputs_say_how_many_points_were_kept(tmp_path):
    """study.md and the CSVs say what the detectors kept; the default is the paper's 100."""
    code = main(["study", "demo:wall", "--sut", "orb", "-o", str(tmp_path), "--examples", "1", "--views", "1",
                 "--size", "64", "--fps-size", "64x36", "--fps-frames", "1"])
    assert code == 0
    text = (tmp_path / "study.md").read_text()
    assert "detectors orb kept at most the 100 highest-response points of each image" in text
    for table in ("examples.csv", "domain_shift.csv"):
        with open(tmp_path / table) as fh:
            assert {row["points"] for row in csv.DictReader(fh)} == {"100"}, table


def test_rq2_draws_the_same_with_and_without_a_real_photo(monkeypatch, tmp_path):
    """RQ1 drew its mutations of the photo from RQ2's generator, so a scene with a photo got other RQ2 draws than the
    same scene without one."""
    import pytest_n2r.study.run as study_run

    config = StudyConfig(examples=2, max_views=2, size=48, fps_frames=1, fps_sizes=((48, 27),),
                         families=("tau1", "m1", "m2"))
    suts = [resolve_sut("orb", None, points=20)]
    with_photo = run_study([ground_truth("wall")], suts, config)
    assert with_photo.realness, "RQ1 ran"
    monkeypatch.setattr(study_run, "_reference_image", lambda *_a: None)
    without = run_study([ground_truth("wall")], suts, config)
    assert not without.realness, "RQ1 skipped"
    assert [r["drawn"] for r in with_photo.examples] == [r["drawn"] for r in without.examples]
    write_study(without, tmp_path)  # a study without RQ1 still writes
