"""RenderSettings and FieldRenderer arguments: bad values are refused naming the setting."""

from __future__ import annotations

import dataclasses
import re

import cv2
import numpy as np
import pytest

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import Camera, camera_rays
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import CAMERA, named_pose, random_field


@pytest.mark.parametrize("changes, name", [
    ({"step_ratio": 0.0}, "step_ratio"),
    ({"step_ratio": 9.0}, "step_ratio"),
    ({"far": float("inf")}, "far"),
    ({"far": 0.0}, "far"),
    ({"t_stop": 1.0}, "t_stop"),
    ({"min_alpha": -0.1}, "min_alpha"),
    ({"scale": 0.05}, "scale"),
    ({"scale": 1.5}, "scale"),
    ({"chunk_rays": 0}, "chunk_rays"),
    ({"chunk_rays": 1.5}, "chunk_rays"),
    ({"adaptive": -1.0}, "adaptive"),
    ({"adaptive_depth": float("nan")}, "adaptive_depth"),
    ({"tail": (0.1, 0.3)}, "tail"),
    ({"tail": (0.3, 1.0)}, "tail"),
    ({"tail": 0.3}, "tail"),
    ({"shell_samples": 0}, "shell_samples"),
    ({"background": (2.0, 0.0, 0.0)}, "background"),
    ({"background": (0.0, 0.0)}, "background"),
    ({"backend": "cuda"}, "backend"),
    ({"colour_direction": "camera"}, "colour_direction"),
    ({"min_weight": 1.0}, "min_weight"),
    ({"min_weight": float("nan")}, "min_weight"),
    ({"adaptive": 1.5}, "adaptive"),  # above 1: nearly every pixel interpolated, a blurred picture
    ({"min_alpha": 1.0}, "min_alpha"),  # every cell skipped: a blank picture
    ({"shell_samples": 5000}, "shell_samples"),
])
def test_bad_settings_are_named(changes, name):
    ((_, value),) = changes.items()
    with pytest.raises(InvalidArgument, match=re.escape(f"RenderSettings.{name}={value!r}")) as error:
        RenderSettings(**changes)
    assert "expected" in str(error.value), f"the message does not say what is accepted: {error.value}"


@pytest.mark.parametrize("changes, expected", [
    ({"far": None}, "a number (default: 100.0)"),
    ({"t_stop": None}, "a number (default: 0.04)"),
    ({"step_ratio": "0.5"}, "a number (default: 0.5)"),
    ({"step_ratio": True}, "a number (default: 0.5)"),
    ({"chunk_rays": True}, "an integer (default: 65536)"),
    ({"chunk_rays": 2.0}, "an integer (default: 65536)"),
    ({"shell_samples": "4"}, "an integer or None (default: None)"),
    ({"adaptive_stride": 2.0}, "an integer or None (default: None)"),
    ({"tail": (0.3, None)}, "a list of numbers (default: 0.3,0.1)"),
    ({"background": (1, True, 0)}, "three numbers or None (default: None)"),
    ({"background": np.array(0.5)}, "three numbers or None (default: None)"),  # was a bare TypeError (0-d array)
    ({"background": np.full((3, 1), 0.5)}, "three numbers or None (default: None)"),
    ({"background": "101"}, "three numbers or None (default: None)"),
    ({"backend": None}, "a string (default: auto)"),
])
def test_settings_of_the_wrong_type_are_named_with_the_type_expected(changes, expected):
    """A string, None or a bool where a number belongs used to end in a bare TypeError from a comparison, or (a
    bool) to be taken as 0 or 1."""
    ((name, value),) = changes.items()
    try:
        RenderSettings(**changes)
    except InvalidArgument as error:
        message = str(error)
    except TypeError as error:
        pytest.fail(f"RenderSettings({name}={value!r}) raised a bare {error!r}, not an error naming the setting")
    else:
        pytest.fail(f"RenderSettings({name}={value!r}) was accepted; expected {expected}")
    assert message == f"RenderSettings.{name}={value!r}: expected {expected}", (
        f"RenderSettings({name}={value!r}): the message does not name the setting and the type expected: {message}")


def test_auto_picks_the_compiled_backend_on_the_cpu_and_settings_round_trip():
    renderer = FieldRenderer(random_field(resolution=8), RenderSettings())
    assert renderer.backend == "compiled", f"backend='auto' on a CPU field chose {renderer.backend!r}"
    settings = RenderSettings(step_ratio=0.7, shell_samples=3, background=(1, 0.5, 0))
    assert RenderSettings(**settings.to_dict()) == settings
    assert settings.background == (1.0, 0.5, 0.0)


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize("bad", ["nan", "inf"])
def test_a_non_finite_pose_is_refused_before_it_reaches_a_kernel(backend, bad):
    """A NaN pose used to crash the process in the compiled kernel (segmentation fault) and give an
    unrelated torch error in the reference."""
    c2w = named_pose("inside")
    c2w[0, 3] = float(bad)
    renderer = FieldRenderer(random_field(resolution=8), RenderSettings(backend=backend))
    with pytest.raises(InvalidArgument, match=r"c2w contains 1 non-finite value\(s\) \(NaN or Inf\)"):
        renderer.render(c2w, CAMERA, ("rgb", "depth"))


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_leftover_transmittance_shows_the_fields_background_unless_settings_name_one(backend):
    """In a field with no occupied cell no sample is taken: every pixel is the background."""
    field = dataclasses.replace(random_field(resolution=8), background=(0.2, 0.4, 0.6))
    field.occupancy[:] = False
    c2w = named_pose("inside")
    own = FieldRenderer(field, RenderSettings(backend=backend)).render(c2w, CAMERA, ("rgb", "opacity"))
    assert own["opacity"].max() == 0.0, "an empty field rendered some opacity"
    assert (own["rgb"] == [51, 102, 153]).all(), f"expected the field's background, got {np.unique(own['rgb'])}"
    named = FieldRenderer(field, RenderSettings(backend=backend, background=(1, 0, 0))).render(c2w, CAMERA, ("rgb",))
    assert (named["rgb"] == [255, 0, 0]).all(), f"expected the settings' background, got {np.unique(named['rgb'])}"


def test_a_scaled_render_is_the_small_render_resized_and_depth_is_never_blended():
    field = random_field(resolution=12, occupied=0.4, seed=5)
    c2w = named_pose("inside")
    out = FieldRenderer(field, RenderSettings(scale=0.5)).render(c2w, CAMERA, ("rgb", "depth", "opacity"))
    small = FieldRenderer(field).render(c2w, CAMERA.resized(16, 12), ("rgb", "depth", "opacity"))
    for name, image in out.items():
        assert image.shape[:2] == (CAMERA.height, CAMERA.width), f"scaled {name} is {image.shape}, not the camera's"
        assert image.dtype == small[name].dtype, f"scaled {name} is {image.dtype}, not {small[name].dtype}"
    rendered = set(np.unique(small["depth"]).tolist())
    assert set(np.unique(out["depth"]).tolist()) <= rendered, "the upsampled depth holds depths no pixel rendered"
    assert np.array_equal(out["rgb"], cv2.resize(small["rgb"], (CAMERA.width, CAMERA.height))), \
        "scaled rgb is not the small render resized bilinearly"


def test_compiled_pixel_rays_are_the_geometry_rays_normalized():
    """The renderer's compiled rays are ``normalize_rays(*camera_rays(...))`` to float32 rounding, for every pixel
    of an off-centre camera at a turned pose (flat index ``y·width + x``)."""
    field = random_field(resolution=8, seed=1)
    camera = Camera(37, 23, 41.0, 29.0, 17.3, 12.9)
    c2w = named_pose("outside")
    index = np.arange(camera.width * camera.height)
    uv = np.stack([index % camera.width, index // camera.width], -1).astype(np.float64)
    want_o, want_d = field.space.normalize_rays(*camera_rays(camera, c2w, uv))
    got_o, got_d = FieldRenderer(field, RenderSettings(backend="compiled"))._pixel_rays(index, camera, c2w)
    np.testing.assert_array_equal(got_o, want_o, err_msg="compiled ray origins differ from the geometry's")
    np.testing.assert_allclose(got_d, want_d, rtol=2 ** -23, atol=0, err_msg="compiled ray directions differ")


def test_a_background_may_be_a_numpy_array_and_is_stored_as_plain_floats():
    """A colour computed with NumPy (float32 included) is a colour; it is stored as floats (the content hash dumps
    the settings as JSON)."""
    settings = RenderSettings(background=np.array([0.25, 0.5, 1.0], dtype=np.float32))
    assert settings.background == (0.25, 0.5, 1.0), settings.background
    assert all(type(c) is float for c in settings.background), [type(c) for c in settings.background]


def test_a_field_render_rounds_colours_to_the_nearest_level():
    """An empty field shows its background (0.5, 0.25, 1.0): 127.5 and 63.75 grey levels, rounded to 128 and 64."""
    import dataclasses

    import numpy as np

    from pytest_n2r.render.field_render import FieldRenderer
    from tests.field.fields import CAMERA, named_pose, random_field

    field = dataclasses.replace(random_field(resolution=8), background=(0.5, 0.25, 1.0))
    field.occupancy[:] = False
    rgb = FieldRenderer(field, RenderSettings()).render(named_pose("inside"), CAMERA, ("rgb",))["rgb"]
    assert (rgb == [128, 64, 255]).all(), np.unique(rgb.reshape(-1, 3), axis=0)
