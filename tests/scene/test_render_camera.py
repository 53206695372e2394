"""Scene.render bounds the camera: a size, focal length or principal point no renderer can draw is refused by name
(before: a 10**10-pixel camera failed in numpy after seconds, fx <= 1e-38 or cx = 1e300 divided by zero inside a
compiled kernel of a fitted field). Scene.view, Scene.pair and Scene.length_scale name a view or units they cannot
use."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import Camera, Transform
from pytest_n2r.render.size import MAX_SIDE
from pytest_n2r.scene.base import MAX_FOCAL, MIN_FOCAL, PRINCIPAL_POINT_REACH
from tests.plugin.fakescene import PlaneScene


def _camera(**change) -> Camera:
    return Camera(**{"width": 32, "height": 24, "fx": 25.6, "fy": 25.6, "cx": 15.5, "cy": 11.5, **change})


@pytest.mark.parametrize(("camera", "expected"), [
    (_camera(width=MAX_SIDE + 1, cx=MAX_SIDE / 2), (f"camera width={MAX_SIDE + 1} pixels is too large; expected at "
                                                   f"most {MAX_SIDE} pixels")),
    (_camera(height=10**10), f"camera height=10000000000 pixels is too large; expected at most {MAX_SIDE} pixels"),
    (_camera(fx=1e-38), "camera fx=1e-38 pixels is out of bounds; expected a focal length in [1e-06, 1e+09] pixels"),
    (_camera(fy=1e-7), "camera fy=1e-07 pixels is out of bounds; expected a focal length in [1e-06, 1e+09] pixels"),
    (_camera(fx=1e300, fy=1e300), "camera fx=1e+300 pixels is out of bounds"),
    (_camera(cx=1e300), ("camera cx=1e+300 pixels is 1e+300 pixels from the image's centre; expected at most 1000 "
                        "image sizes (32000 pixels) from it")),
    (_camera(cy=-24012.0), ("camera cy=-24012.0 pixels is 2.402e+04 pixels from the image's centre; expected at most "
                           "1000 image sizes (24000 pixels) from it")),
])
def test_a_camera_no_renderer_can_draw_is_refused_naming_its_field(camera, expected):
    scene = PlaneScene()
    try:
        rendered = scene.render(scene.views[0].c2w, camera, ("rgb", "depth"))
    except InvalidArgument as exc:
        assert expected in str(exc), f"the refusal does not name the camera's field and its bound: {exc}"
    else:
        pytest.fail(f"{camera} was rendered ({rendered.rgb.shape}, depth finite: "
                    f"{bool(np.isfinite(rendered.depth).all())}) instead of refused")


@pytest.mark.parametrize("camera", [
    _camera(fx=MIN_FOCAL, fy=MAX_FOCAL),
    _camera(fx=0.5, fy=0.5),  # a 176-degree view
    _camera(width=16, height=16, cx=7.5 + PRINCIPAL_POINT_REACH * 16, cy=7.5 - PRINCIPAL_POINT_REACH * 16),
    _camera(width=MAX_SIDE, height=16, fx=8000.0, fy=8000.0, cx=MAX_SIDE / 2, cy=7.5),
])
def test_a_camera_within_the_bounds_renders(camera):
    scene = PlaneScene()
    rendered = scene.render(scene.views[0].c2w, camera, ("rgb",))
    assert rendered.rgb.shape == (camera.height, camera.width, 3), f"{camera} rendered {rendered.rgb.shape}"


def test_every_view_of_the_demo_scenes_is_within_the_bounds():
    from pytest_n2r.demo import load_demo
    from pytest_n2r.scene.base import check_render_camera

    for name in ("wall", "object"):
        for view in load_demo(name).views:
            assert check_render_camera(view.camera) is view.camera


@pytest.mark.parametrize("view", [None, [0], 1.7, True, np.float64(1.0), b"view1"], ids=repr)
def test_a_view_that_is_no_index_or_name_is_refused_naming_the_argument(view):
    """``Scene.view`` (and ``Scene.pair``) took ``int(view)``: None or a list ended in a bare TypeError from
    ``int``, and 1.7 or True picked view 1."""
    scene = PlaneScene()
    expected = (f"view={view!r} must be a view index (an int) or an image name (a str), not "
                f"{type(view).__name__}")
    for method, call in (("view", lambda: scene.view(view)), ("pair", lambda: scene.pair(view, Transform(yaw=1)))):
        with pytest.raises(InvalidType) as info:
            call()
        assert str(info.value) == expected, f"Scene.{method}({view!r}): the message does not say what a view is"


@pytest.mark.parametrize("view", [2, np.int64(2), np.uint8(2), "view2"], ids=repr)
def test_a_view_is_taken_by_int_numpy_integer_or_name(view):
    assert PlaneScene().view(view).index == 2, f"Scene.view({view!r}) picked another view"


@pytest.mark.parametrize("call", [
    lambda scene, units: scene.length_scale(units),
    lambda scene, units: scene.pair(0, Transform(yaw=1), units=units),
], ids=["length_scale", "pair"])
@pytest.mark.parametrize("units", ["meters", "METRES", 5])
def test_units_that_are_no_unit_are_refused_listing_the_units(call, units):
    """``units='meters'`` ended in a bare ``ValueError: 'meters' is not a valid Units``."""
    with pytest.raises(InvalidArgument) as info:
        call(PlaneScene(), units)
    assert str(info.value) == f"units={units!r} is not a unit; expected one of ['reference', 'scene', 'metres']", (
        f"the message does not list the units: {info.value}")


def test_pair_renders_both_views_at_the_camera_given():
    scene = PlaneScene()
    small = Camera(48, 36, 38.4, 38.4, 23.5, 17.5)
    source, follow = scene.pair(0, Transform(yaw=1), camera=small)
    for view in (source, follow):
        assert view.camera == small and view.rgb.shape[:2] == (36, 48)


def test_a_camera_with_lens_distortion_is_refused():
    scene = PlaneScene()
    camera = dataclasses.replace(scene.views[0].camera, distortion=(0.1, 0.0, 0.0, 0.0))
    with pytest.raises(InvalidArgument, match="camera has lens distortion"):
        scene.render(scene.views[0].c2w, camera)


def test_no_outputs_are_refused():
    scene = PlaneScene()
    with pytest.raises(InvalidArgument, match=r"outputs=\(\): expected one or more of"):
        scene.render(scene.views[0].c2w, scene.views[0].camera, ())


class _NaNDepth(PlaneScene):
    def _render(self, c2w, camera, outputs):
        out = super()._render(c2w, camera, outputs)
        out["depth"] = np.full((camera.height, camera.width), np.nan, np.float32)
        return out


def test_a_nan_depth_is_refused_naming_depth():
    scene = _NaNDepth()
    with pytest.raises(InvalidArgument, match=r"rendered \d+ NaN/Inf depth value"):
        scene.render(scene.views[0].c2w, scene.views[0].camera, ("depth",))


class _Changed(PlaneScene):
    """A plane whose ``_render`` changes one output as a Scene of one's own might get it wrong."""

    def __init__(self, output: str, change):
        super().__init__()
        self.output, self.change = output, change

    def _render(self, c2w, camera, outputs):
        out = super()._render(c2w, camera, outputs)
        out[self.output] = self.change(out[self.output])
        return out


@pytest.mark.parametrize(("output", "change", "got"), [
    ("depth", lambda d: None, "nothing"),
    ("rgb", lambda rgb: rgb.astype(np.float32) / 255, "a float32 array of shape (72, 96, 3)"),
    ("rgb", lambda rgb: rgb[..., ::-1].tolist(), "list"),
    ("rgb", lambda rgb: rgb[:, :, 0], "a uint8 array of shape (72, 96)"),
    ("depth", lambda d: d.T, "a float32 array of shape (96, 72)"),
    ("opacity", lambda a: a.astype(np.float64), "a float64 array of shape (72, 96)"),
])
def test_a_render_of_another_output_shape_or_type_is_refused_naming_it(output, change, got):
    """Before: a left-out output failed later inside the render cache or a metric (``'NoneType' object has no
    attribute 'nbytes'``), and a float RGB image in [0, 1] reached the SUT as a picture."""
    scene = _Changed(output, change)
    expected = {"rgb": "a uint8 array of shape (72, 96, 3)", "depth": "a float32 array of shape (72, 96)",
                "opacity": "a float32 array of shape (72, 96)"}[output]
    with pytest.raises(InvalidArgument) as caught:
        scene.render(scene.views[0].c2w, scene.views[0].camera, ("rgb", "depth", "opacity"))
    assert str(caught.value) == (f"scene 'plane' rendered {got} as {output!r}; its _render must return every output "
                                 f"it is asked for, {output!r} as {expected}"), f"unexpected message: {caught.value}"
