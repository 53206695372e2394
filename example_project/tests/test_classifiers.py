"""Image classifiers under the pose transforms on the object scene (UAV vehicle inspection): the
probability vectors should stay similar (cosine similarity, ideal 1).

``eps`` is the worst deviation of the two networks seen (demo ``object`` scene, 320×180) rounded up with a
margin of about 0.1. The first values came from 20 derandomized examples, and τ1/τ2/τ5 sat too close to
what other draws reach: the derandomized examples change when the suite's imports do (a cause not found
yet), and MobileNetV2 then failed τ2 at 0.474 and 0.488. They were measured again over those runs and a
60-example search of each relation: worst MobileNetV2 / EfficientNet-Lite0 deviations 0.53 / 0.29 (τ1),
0.49 / 0.41 (τ2), 0.54 / 0.35 (τ5), 0.29 / 0.25 (τ6). What the measurements ruled out:

- **class invariance under τ1/τ2** does not hold on the demo van for either network, not even as "the
  source's top-1 class stays in the follow-up's top 5": both networks are unsure what the van is (top-1
  probability about 0.17, among neighbouring ImageNet classes), and a motion of a few degrees reorders
  them. Different examples broke MobileNetV2 in one run and EfficientNet-Lite0 in another, so no
  relation (and no xfail) on it would be stable. The 2-D mutations keep top-5 invariance
  (test_deepxplore.py) under brightness in every run; under black patches MobileNetV2 loses it on 2-3 % of
  draws, an expected failure there;
- **τ3/τ4**: their large motions move the van out of the networks' 224×224 centre crop in many views,
  and the measured cosine deviations (up to 0.85) leave no eps that would both pass and mean anything.
"""

from __future__ import annotations

import pytest

from pytest_n2r import metamorphic
from pytest_n2r.metrics import cosine_similarity

from .conftest import load_classifier, skip_without_object

CLASSIFIERS = ("mobilenet_v2", "efficientnet_lite0")

pytestmark = pytest.mark.classifiers


@pytest.fixture(params=CLASSIFIERS, scope="module")
def net(request):
    return load_classifier(request.param)


@metamorphic(cosine_similarity(), eps=0.65, transform="tau1")
def test_cosine_similarity_tau1(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.6, transform="tau2")
def test_cosine_similarity_tau2(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.65, transform="tau5")
def test_cosine_similarity_tau5(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.55, transform="tau6")
def test_cosine_similarity_tau6(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net
