"""The pytest plugin runs relations on a .n2r scene file given with ``--n2r-scene`` (pytester)."""

from __future__ import annotations

import pytest

# pytester drops the modules an inner run imported first; importing them here keeps one copy of each (see
# tests/plugin/conftest.py).
import pytest_n2r.metrics
import pytest_n2r.plugin.marker
import pytest_n2r.strategies  # noqa: F401

MEAN_COLOUR = """
from pytest_n2r import Validity, l2_norm, metamorphic, transforms


# A 30-step fit is a blur with unreliable depth: the coverage check would reject every view.
@metamorphic(l2_norm(inputs="raw"), eps=1.0, transform=transforms(yaw=2), examples=3, validity=Validity(min_coverage=0))
def test_mean_colour(n2r_scene):
    return lambda rgb: [float(rgb.mean()) / 255.0]
"""

INNER = MEAN_COLOUR + """
from pytest_n2r import FieldScene


def test_the_fixture_is_the_fitted_scene(n2r_scene):
    assert isinstance(n2r_scene, FieldScene), type(n2r_scene)
    assert n2r_scene.name == "object" and len(n2r_scene.views) == 48, n2r_scene
    assert n2r_scene.report["steps"] == {steps}
"""


def test_the_plugin_loads_a_scene_file(pytester: pytest.Pytester, tiny_scene_file, monkeypatch):
    from .conftest import TINY_STEPS

    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_inner=INNER.format(steps=TINY_STEPS))
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(tiny_scene_file), "--n2r-size", "48",
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
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(tiny_scene_file), "--n2r-size", "48",
                                "--n2r-device", "cpu", "--n2r-render-scale", "0.5")
    result.assert_outcomes(passed=2)


def test_a_checkpoint_scene_is_warned_of(pytester: pytest.Pytester, tiny_capture, tiny_fit, tmp_path, monkeypatch):
    """A scene file whose fit did not finish passed its tests with no word: n2r info called it a checkpoint,
    the test run said nothing."""
    from pytest_n2r.scene import save_scene

    from .conftest import TINY_STEPS

    checkpoint = save_scene(tmp_path / "object.n2r", tiny_fit.field, tiny_fit.config, tiny_capture,
                            {**tiny_fit.report, "complete": False}, metres_per_unit=1.0)
    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_inner=MEAN_COLOUR)
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(checkpoint), "--n2r-size", "48",
                                "--n2r-device", "cpu")
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines([(f"*UnfinishedScene: scene 'object' is a checkpoint: its fit did not finish "
                                 f"({TINY_STEPS} steps)*")])
