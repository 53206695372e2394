"""Image classifiers under τ1–τ6 on the object scene (UAV vehicle inspection): the top-1 class should not
change, and the probability vectors should stay similar (cosine similarity, ideal 1)."""

from __future__ import annotations

import pytest
from pytest_n2r import metamorphic
from pytest_n2r.metrics import class_invariance, cosine_similarity

from .conftest import load_classifier, skip_without_object

CLASSIFIERS = ("mobilenet_v2", "efficientnet_lite0")

pytestmark = pytest.mark.classifiers


@pytest.fixture(params=CLASSIFIERS, scope="module")
def net(request):
    return load_classifier(request.param)


@metamorphic(class_invariance(), eps=0.0, transform="tau1")
def test_class_invariance_tau1(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(class_invariance(), eps=0.0, transform="tau2")
def test_class_invariance_tau2(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.25, transform="tau1")
def test_cosine_similarity_tau1(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.25, transform="tau2")
def test_cosine_similarity_tau2(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.5, transform="tau3")
def test_cosine_similarity_tau3(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.5, transform="tau4")
def test_cosine_similarity_tau4(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.35, transform="tau5")
def test_cosine_similarity_tau5(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net


@metamorphic(cosine_similarity(), eps=0.35, transform="tau6")
def test_cosine_similarity_tau6(n2r_scene, net):
    skip_without_object(n2r_scene)
    return net
