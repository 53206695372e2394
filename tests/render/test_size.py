"""Render sizes: 'WxH', the longer side, or a pair."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import Camera
from pytest_n2r.render.size import MIN_SIDE, RenderSize
from tests.plugin.fakescene import PlaneScene


@pytest.mark.parametrize(("text", "size"), [("480x270", (360, 270)), ("96", (96, 72)), ((40, 30), (40, 30)),
                                           ("480x360", (480, 360)), ("100x300", (100, 75))])
def test_render_size(text, size):
    """The 4:3 plane at '480x270' was stretched to 480x270 (fx 5, fy 3.75 times the original): a picture no
    camera took. A box keeps the view's aspect."""
    camera = PlaneScene().views[0].camera
    resized = RenderSize.parse(text).apply(camera)
    assert (resized.width, resized.height) == size


@settings(max_examples=200)
@given(width=st.integers(8, 4000), height=st.integers(8, 4000), box_w=st.integers(1, 2000), box_h=st.integers(1, 2000))
def test_a_box_never_stretches_a_view_and_fits_it(width, height, box_w, box_h):
    camera = Camera(width, height, 1.2 * width, 1.2 * width, (width - 1) / 2, (height - 1) / 2)
    try:
        resized = RenderSize(box_w, box_h).apply(camera)
    except InvalidArgument:  # refused: its fit has a side below MIN_SIDE (tested below); the box is then too small
        fit = camera.scaled(min(box_w / width, box_h / height))
        assert min(fit.size) < MIN_SIDE + 1, f"{width}x{height} in {box_w}x{box_h} refused, yet fits as {fit.size}"
        return
    assert min(resized.size) >= MIN_SIDE, f"{width}x{height} in {box_w}x{box_h} became {resized.size}"
    assert resized.width <= box_w and resized.height <= box_h, f"{resized.size} outside the box {box_w}x{box_h}"
    scale = min(box_w / width, box_h / height)  # the largest scale that fits the view in the box
    # each side is the view's side at that scale, to the rounding of a pixel and the one-pixel tolerance of a box
    # of the view's own aspect: never stretched by more than that
    assert abs(resized.width - width * scale) <= 1.5 and abs(resized.height - height * scale) <= 1.5, (
        f"{width}x{height} in {box_w}x{box_h} became {resized.size}: stretched, or not the largest fit")


@pytest.mark.parametrize(("size", "larger"), [("16", "at least 207"), ("20", "at least 207"), ("206", "at least 207"),
                                              ("16x16", "e.g. 214x214"), ("160x16", "e.g. 214x22")])
def test_a_render_size_that_leaves_a_side_below_min_side_is_refused(size, larger):
    """A 4000x300 view at '16' rendered 16x1: ORB then failed inside OpenCV, reported as the SUT's error."""
    camera = Camera(4000, 300, 3000.0, 3000.0, 1999.5, 149.5)
    try:
        fitted = RenderSize.parse(size).apply(camera)
    except InvalidArgument as exc:
        message = str(exc)
    else:
        pytest.fail(f"the 4000x300 view at render size {size!r} became {fitted.size}: a side below {MIN_SIDE}")
    assert message.startswith(f"a 4000x300 view at render size {size} is ") and f"below {MIN_SIDE} pixels" in message \
        and f"expected a larger render size ({larger} for this view)" in message, f"the refusal misleads: {message}"
    suggested = RenderSize.parse(larger.split()[-1]).apply(camera)
    assert min(suggested.size) >= MIN_SIDE, f"the suggested size {larger} still renders {suggested.size}"


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        ((480,), {}, InvalidArgument, (r"RenderSize\(width=480, height=None, longer=None\) is not a render size; "
                                       r"expected a width and a height \(a box\), or only longer")),
        ((), {}, InvalidArgument, r"RenderSize\(width=None, height=None, longer=None\) is not a render size"),
        ((480, 270), {"longer": 480}, InvalidArgument, r"RenderSize\(width=480, height=270, longer=480\) is not a"),
        ((None, 270), {}, InvalidArgument, r"RenderSize\(width=None, height=270, longer=None\) is not a render size"),
        ((8, 270), {}, InvalidArgument, r"RenderSize width=8 is out of range; expected an int in \[16, 16384\]"),
        ((), {"longer": 20000}, InvalidArgument, r"RenderSize longer=20000 is out of range"),
        (("480", 270), {}, InvalidType, r"RenderSize width='480' must be an int, not str"),
    ],
)
def test_a_render_size_made_directly_is_checked(args, kwargs, error, match):
    """RenderSize(480) (a width alone, through Relation.build(size=...)) failed in apply with "unsupported operand
    type(s) for /: 'NoneType' and 'int'"; a longer side alone is RenderSize(longer=480)."""
    with pytest.raises(error, match=match):
        RenderSize(*args, **kwargs)
    camera = PlaneScene().views[0].camera
    assert RenderSize(longer=96).apply(camera).size == RenderSize.parse("96").apply(camera).size == (96, 72)


def test_a_box_three_pixels_off_the_views_aspect_is_not_filled_by_stretching():
    """A box within a pixel of the view's aspect is filled; 3 pixels off, the view is fitted in it, not stretched."""
    camera = Camera(1000, 1000, 1200.0, 1200.0, 499.5, 499.5)
    assert RenderSize(100, 103).apply(camera).size == (100, 100)


@pytest.mark.parametrize("value", [True, False])
def test_a_boolean_size_is_refused_by_type(value):
    """``size=True`` is no size (``True`` is the int 1 to Python): refused as a type, naming the argument."""
    with pytest.raises(InvalidType, match=rf"size={value!r} must be 'WxH', a pair \(W, H\) or an int"):
        RenderSize.parse(value)
