"""Adaptive pixel sampling: traced pixels are the full render's, smooth cells are interpolated, edges traced."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import Camera
from pytest_n2r.render.adaptive import grid_axis, sample_adaptively
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import named_pose, random_field

OUTPUTS = ("rgb", "depth", "opacity")


class ImageTracer:
    """Traces pixels of a known image ``(H, W, 5)`` (rgb, depth, opacity) and remembers which."""

    def __init__(self, image: np.ndarray):
        self.image = image.astype(np.float32)
        self.traced = np.zeros(image.shape[:2], dtype=bool)

    def __call__(self, want: np.ndarray, rgb: np.ndarray, depth: np.ndarray, opacity: np.ndarray) -> None:
        assert not self.traced.reshape(-1)[want].any(), "a pixel was traced twice"
        self.traced.reshape(-1)[want] = True
        flat = self.image.reshape(-1, 5)[want]
        rgb[want], depth[want], opacity[want] = flat[:, :3], flat[:, 3], flat[:, 4]

    def sample(self, stride: int, tolerance: float, depth_tolerance: float = 0.1) -> np.ndarray:
        h, w = self.image.shape[:2]
        rgb, depth, opacity, traced = sample_adaptively(self, h, w, stride, tolerance, depth_tolerance)
        assert traced == self.traced.sum(), f"sample_adaptively reports {traced} pixels traced, not {self.traced.sum()}"
        return np.concatenate([rgb, depth[:, None], opacity[:, None]], axis=1).reshape(h, w, 5)


def affine_image(h: int, w: int, seed: int) -> np.ndarray:
    """Every channel an affine function of the pixel position (depth positive)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    a = rng.uniform(-0.01, 0.01, (2, 5))
    image = 0.5 + a[0] * x[..., None] + a[1] * y[..., None]
    image[..., 3] += 2.0
    return image


@settings(max_examples=60, deadline=None)
@given(h=st.integers(1, 40), w=st.integers(1, 40), log_stride=st.integers(0, 4), seed=st.integers(0, 99))
def test_an_affine_image_is_reproduced_and_a_loose_tolerance_traces_only_the_coarse_grid(h, w, log_stride, seed):
    stride = 1 << log_stride
    tracer = ImageTracer(affine_image(h, w, seed))
    out = tracer.sample(stride, tolerance=1.0, depth_tolerance=1.0)
    np.testing.assert_allclose(out, tracer.image, atol=1e-5,
                               err_msg=f"{w}×{h}, stride {stride}: bilinear interpolation of an affine image is off")
    coarse = (h * w) if min(h, w) < 2 else grid_axis(h, stride).size * grid_axis(w, stride).size
    assert tracer.traced.sum() == coarse, (f"{w}×{h}, stride {stride}: traced {tracer.traced.sum()} pixels with "
                                           f"nothing to refine; the coarse grid has {coarse}")


@settings(max_examples=60, deadline=None)
@given(h=st.integers(2, 40), w=st.integers(2, 40), log_stride=st.integers(1, 4), edge=st.floats(0.0, 1.0),
       vertical=st.booleans())
def test_a_step_edge_is_traced_pixel_by_pixel_and_flat_colour_interpolated(h, w, log_stride, edge, vertical):
    """Cells the edge crosses have disagreeing corners, so they are split down to single pixels; the others
    are flat, so interpolation is exact: the whole image comes out exact."""
    image = np.full((h, w, 5), 0.2)
    image[..., 3] = 1.0
    if vertical:
        image[:, int(edge * w):, :3] = 0.9
    else:
        image[int(edge * h):, :, 3] = 5.0  # a depth edge only: colour and opacity agree across it
    tracer = ImageTracer(image)
    out = tracer.sample(1 << log_stride, tolerance=0.05)
    assert np.array_equal(out, tracer.image), (f"{w}×{h}, stride {1 << log_stride}, edge at {edge:.2f} "
                                               f"({'colour' if vertical else 'depth'}): "
                                               f"{int((out != tracer.image).any(-1).sum())} pixels are wrong")


@settings(max_examples=40, deadline=None)
@given(h=st.integers(2, 24), w=st.integers(2, 24))
def test_at_the_last_split_a_pixel_between_two_agreeing_traced_pixels_is_interpolated_and_the_rest_traced(h, w):
    """Colour quadratic in x, constant in y: every 2×2 cell splits; its edge pixels on a traced column are
    interpolated (their ends agree), those on a traced row traced (interpolation along x would be wrong), and
    then its centre is interpolated between the two traced pixels above and below it: every pixel of the rows
    between traced rows is interpolated, exactly, and every other pixel traced."""
    image = np.full((h, w, 5), 0.5)
    image[..., 0] = 0.05 * np.arange(w)[None, :] ** 2
    tracer = ImageTracer(image)
    out = tracer.sample(2, tolerance=0.05)
    assert np.array_equal(out, tracer.image), f"{w}×{h}: {int((out != tracer.image).any(-1).sum())} pixels are wrong"
    between = ~np.isin(np.arange(h), grid_axis(h, 2))[:, None] & np.ones(w, dtype=bool)
    assert np.array_equal(tracer.traced, ~between), (f"{w}×{h}: traced {tracer.traced.sum()} pixels; expected "
                                                     f"every one but the {between.sum()} on rows between traced rows")


def test_a_thin_line_between_coarse_pixels_can_be_missed_and_stride_1_traces_everything():
    """The documented limit: detail narrower than the coarsest grid that falls between its pixels."""
    image = np.full((9, 9, 5), 0.3)
    image[:, 5, :3] = 1.0  # column 5: between the traced columns 4 and 8 of stride 4
    tracer = ImageTracer(image)
    assert not np.array_equal(tracer.sample(4, 0.05), tracer.image), "the thin line was found at stride 4"
    tracer = ImageTracer(image)
    assert np.array_equal(tracer.sample(1, 0.05), tracer.image) and tracer.traced.all()


def test_stride_must_be_a_power_of_two():
    with pytest.raises(ValueError, match="stride=3: expected a power of two"):
        sample_adaptively(ImageTracer(np.ones((4, 4, 5))), 4, 4, 3, 0.1, 0.1)


CAMERA = Camera(64, 48, 60.0, 60.0, 31.5, 23.5)


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_adaptive_renders_keep_every_traced_pixel_of_the_full_render(backend):
    field = random_field(resolution=12, occupied=0.3, seed=2, density_scale=1.0)
    field.values[:, 1:] *= 0.2  # gentle colours: most cells are smooth enough to interpolate
    c2w = named_pose("inside")
    full = FieldRenderer(field, RenderSettings(backend=backend, adaptive=0.0)).render(c2w, CAMERA, OUTPUTS)
    renderer = FieldRenderer(field, RenderSettings(backend=backend, adaptive=0.04, adaptive_stride=4))
    out = renderer.render(c2w, CAMERA, OUTPUTS)
    if backend == "compiled":  # one thread per ray: a traced pixel is the full render's to the bit
        same = ((out["rgb"] == full["rgb"]).all(-1) & (out["depth"] == full["depth"])
                & (out["opacity"] == full["opacity"]))
    else:  # torch composites a batch with float32 sums whose rounding depends on the batch's rays
        same = ((np.abs(out["rgb"].astype(int) - full["rgb"]) <= 1).all(-1)
                & np.isclose(out["depth"], full["depth"], rtol=1e-5, atol=0)
                & np.isclose(out["opacity"], full["opacity"], rtol=1e-5, atol=1e-6))
    assert renderer.last_traced < CAMERA.width * CAMERA.height, "nothing was interpolated: the test tests nothing"
    assert same.sum() >= renderer.last_traced, (f"only {same.sum()} pixels equal the full render; "
                                                f"{renderer.last_traced} were traced")
    # Bounds measured on this field (seeds 2-5, strides 2 and 4): an interpolated pixel at most 12-16 levels from
    # the full render and the image 48.4-50.0 dB from it (seed 2: 12 levels, 50.0 dB), since the last split
    # interpolates a pixel between two agreeing traced pixels of its row or column (before: 2-13 levels, 56-71 dB);
    # the fox lost 0.02 dB to that against its photos (docs/performance-log.md, "Rendering"). A pixel off by more than
    # twice the tolerance, or an image below 46 dB, is a fault.
    error = out["rgb"].astype(float) - full["rgb"]
    diff, db = np.abs(error).max(), 10 * np.log10(255.0**2 / np.mean(error**2))
    assert diff <= 2 * 0.04 * 255 + 1, f"an interpolated pixel is {diff:.0f} levels from the full render"
    assert db >= 46.0, f"the adaptive render is {db:.1f} dB from the full render; expected >= 46 dB"
    rgb_only = renderer.render(c2w, CAMERA, ("rgb",))["rgb"]
    assert np.array_equal(rgb_only, out["rgb"]), "rgb alone differs from rgb rendered with depth and opacity"


def test_the_default_stride_follows_the_image_size_and_small_images_trace_every_pixel():
    renderer = FieldRenderer(random_field(resolution=8))
    strides = [renderer.stride(Camera(w, h, 100.0, 100.0, w / 2, h / 2))
               for w, h in ((320, 180), (480, 270), (960, 540), (1920, 1080), (270, 480))]
    assert strides == [1, 2, 4, 8, 2], f"default strides {strides}"
    assert FieldRenderer(random_field(resolution=8), RenderSettings(adaptive_stride=16)).stride(CAMERA) == 16


@pytest.mark.parametrize("value", [3, 0, 128])  # 2.0, not an int: tests/render/test_settings.py
def test_a_bad_stride_is_named(value):
    with pytest.raises(InvalidArgument, match=re.escape(f"RenderSettings.adaptive_stride={value!r}: expected None or "
                                                        "a power of two in 1..64")):
        RenderSettings(adaptive_stride=value)
