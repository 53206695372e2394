"""Fixtures of the perception suite. The scenes come from pytest-n2r (``n2r_scene``): the built-in demo
scenes by default (``n2r_scenes`` in pyproject.toml), or whatever ``--n2r-scene`` names."""

from __future__ import annotations

import pytest
from perception.classifiers import WeightsMissing, classifier
from perception.detectors import detector

#: The scene of the UAV mission; classifiers are only meaningful where there is an object to classify.
OBJECT_SCENES = ("object",)
#: The built-in demo scene without an object (the AUV wall) and its fitted twin.
WALL_SCENES = ("wall", "wall-field")


@pytest.fixture(scope="session")
def orb():
    """The ORB configuration under test: ``PERCEPTION_ORB`` (default ``orb``, the shipped one)."""
    return detector()


def load_classifier(name: str):
    """The classifier, or skip the test with the install command when its weights are not installed."""
    try:
        return classifier(name)
    except WeightsMissing as exc:
        pytest.skip(str(exc))


def skip_without_object(scene) -> None:
    """Classifier relations need an object in view: skip them on the AUV wall scene."""
    if scene.name in WALL_SCENES:
        pytest.skip(f"scene {scene.name!r} shows a wall, not an object to classify")
