"""The pytest plugin runs relations on a .n2r scene file given with ``--n2r-scene`` (pytester)."""

from __future__ import annotations

import pytest

# pytester drops the modules an inner run imported first; importing them here keeps one copy of each (see
# tests/plugin/conftest.py).
import pytest_n2r.metrics
import pytest_n2r.plugin.marker
import pytest_n2r.strategies  # noqa: F401

INNER = """
import numpy as np
from pytest_n2r import FieldScene, Validity, l2_norm, metamorphic, transforms


def test_the_fixture_is_the_fitted_scene(n2r_scene):
    assert isinstance(n2r_scene, FieldScene), type(n2r_scene)
    assert n2r_scene.name == "object" and len(n2r_scene.views) == 48, n2r_scene
    assert n2r_scene.report["steps"] == {steps}


# A 30-step fit is a blur with unreliable depth: the coverage check would reject every view.
@metamorphic(l2_norm(inputs="raw"), eps=1.0, transform=transforms(yaw=2), examples=3, validity=Validity(min_coverage=0))
def test_mean_colour(n2r_scene):
    return lambda rgb: [float(rgb.mean()) / 255.0]
"""


def test_the_plugin_loads_a_scene_file(pytester: pytest.Pytester, tiny_scene_file, monkeypatch):
    from .conftest import TINY_STEPS

    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_inner=INNER.format(steps=TINY_STEPS))
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", str(tiny_scene_file), "--n2r-size", "48",
                                "--n2r-device", "cpu")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["*test_mean_colour[[]object[]]*3 examples*"])


def test_render_scale_makes_the_scene_render_smaller_and_upsample(pytester: pytest.Pytester, tiny_scene_file,
                                                                   monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_inner="""
from pytest_n2r import metamorphic, transforms, l2_norm, Validity


def test_the_scene_renders_at_half_size(n2r_scene):
    assert n2r_scene.settings.scale == 0.5, n2r_scene.settings


@metamorphic(l2_norm(inputs="raw"), eps=1.0, transform=transforms(yaw=2), examples=2, validity=Validity(min_coverage=0))
def test_full_size_images_reach_the_sut(n2r_scene):
    def sut(rgb):
        assert max(rgb.shape[:2]) == 48, rgb.shape  # --n2r-size 48, not the 24 pixels rendered
        return [float(rgb.mean()) / 255.0]
    return sut
""")
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", str(tiny_scene_file), "--n2r-size", "48",
                                "--n2r-device", "cpu", "--n2r-render-scale", "0.5")
    result.assert_outcomes(passed=2)
