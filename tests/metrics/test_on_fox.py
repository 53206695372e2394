"""The metrics and mutations on a real photo (the shared fox scene; skipped when it is absent).

ORB on a photo against its mutated copy, same pose: repeatability through the identity homography.
"""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r import strategies as m
from pytest_n2r.geometry import Camera
from pytest_n2r.metrics import interest_point_spread, repeatability
from pytest_n2r.render.view import RenderedView

from ..conftest import shared_scene

cv2 = pytest.importorskip("cv2")
pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def fox_view() -> RenderedView:
    path = shared_scene("fox") / "images" / "0001.jpg"
    bgr = cv2.imread(str(path))
    if bgr is None:
        pytest.skip(f"cannot read {path}")
    rgb = cv2.cvtColor(cv2.resize(bgr, (270, 480), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB)
    return RenderedView(Camera(270, 480, 344.0, 344.0, 134.5, 239.5), np.eye(4), rgb=rgb)


def orb(rgb: np.ndarray) -> list:
    return cv2.ORB_create(300).detect(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))


def test_orb_under_baseline_mutations(fox_view):
    metric = repeatability(px=2, mapping="homography")  # same pose: the identity homography
    source_points = orb(fox_view.rgb)
    assert len(source_points) > 100, "ORB should find texture on the fox photo"

    def score(mutation: m.Mutation) -> float:
        follow = mutation.apply_to_view(fox_view)
        return metric(source_points, orb(follow.rgb), fox_view, follow).score

    assert score(m.Brightness(0)) == 1.0  # no change, the same keypoints
    mild, strong = score(m.Brightness(20)), score(m.NoisePatch(size=0.5, seed=1))
    assert mild > 0.9, f"ORB should shrug off +20 grey levels (repeatability {mild:.3f})"
    assert strong < 0.6, f"noise over a quarter of the image should destroy keypoints ({strong:.3f})"
    metric.assert_within(source_points, orb(m.Brightness(20).apply(fox_view.rgb)), fox_view, fox_view, eps=0.1)
    spread = interest_point_spread(mapping="homography")
    assert spread(source_points, source_points, fox_view, fox_view).score == 1.0
