"""Depth sampling: exact on planes (inverse depth is affine in pixels), never in between at depth edges; homographies
at any scale."""

from __future__ import annotations

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import example, given, settings

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import Camera, Transform, camera_rays, plane_homography
from pytest_n2r.metrics.correspondence import DepthMapping, HomographyMapping, sample_depth
from pytest_n2r.render.view import RenderedView

from .scenes import CAMERA, WALL, Plane, pair, render_planes


def plane_depth(camera: Camera, c2w: np.ndarray, uv: np.ndarray | None = None) -> np.ndarray:
    """Exact z-depth of the world plane z = 4 seen from ``c2w`` (at pixel centres or at ``uv``)."""
    origins, dirs = camera_rays(camera, c2w, uv)
    return (4.0 - origins[..., 2]) / dirs[..., 2]


@settings(max_examples=50, deadline=None)
@given(
    tau=st.builds(Transform, pitch=st.floats(-30, 30), yaw=st.floats(-30, 30), roll=st.floats(-90, 90),
                  x=st.floats(-1, 1), z=st.floats(-1, 1)),
    uv=st.lists(st.tuples(st.floats(-0.5, CAMERA.width - 0.5), st.floats(-0.5, CAMERA.height - 0.5)),
                min_size=1, max_size=20),
)
def test_sampled_depth_is_exact_on_a_plane_up_to_the_border(tau, uv):
    c2w = tau.apply(np.eye(4))
    uv = np.array(uv)
    depth = plane_depth(CAMERA, c2w)  # float64: the property is about interpolation, not storage
    exact = plane_depth(CAMERA, c2w, uv)
    np.testing.assert_allclose(sample_depth(depth, uv, rel_tolerance=1.0), exact, rtol=1e-9)


@settings(max_examples=50)
@given(u=st.floats(-0.5, 9.5), v=st.floats(-0.5, 5.5), near=st.floats(0.5, 2), far=st.floats(3, 100))
def test_at_a_depth_edge_the_sample_is_foreground_or_background_never_between(u, v, near, far):
    depth = np.full((6, 10), far)
    depth[:, :5] = near  # a vertical depth edge between columns 4 and 5
    d = sample_depth(depth, np.array([[u, v]]), rel_tolerance=0.05)[0]
    expected = near if u < 4.5 else far  # the nearest pixel's side (u = 4.5 rounds to column 5)
    assert d == pytest.approx(expected, rel=1e-12), d


def test_one_pixel_wide_images_and_bad_depths():
    depth = np.array([[2.0], [2.0], [np.inf]])
    out = sample_depth(depth, np.array([[0.0, 0.0], [0.2, 1.0], [0.0, 2.0]]))
    assert out[0] == 2.0 and out[1] == 2.0 and np.isnan(out[2])
    assert np.isnan(sample_depth(np.zeros((3, 3)), np.array([[1.0, 1.0]]))[0])


def test_a_float32_depth_map_samples_as_its_float64_widening():
    """Renders store depth as float32; the four depths are read and then widened, which must give what the whole
    map widened first gives (holes, edges and non-finite depths included)."""
    rng = np.random.default_rng(7)
    depth = rng.uniform(0.5, 6.0, (40, 60)).astype(np.float32)
    depth[rng.integers(0, 40, 80), rng.integers(0, 60, 80)] = np.inf
    depth[rng.integers(0, 40, 80), rng.integers(0, 60, 80)] = 0.0
    depth[10:20, 30:] *= np.float32(1.5)  # a depth edge
    uv = rng.uniform([-0.5, -0.5], [59.5, 39.5], (500, 2))
    got, widened = sample_depth(depth, uv), sample_depth(depth.astype(np.float64), uv)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, widened)


@settings(max_examples=50, deadline=None)
@given(tau=st.builds(Transform, pitch=st.floats(-20, 20), yaw=st.floats(-20, 20), roll=st.floats(-45, 45),
                     x=st.floats(-0.5, 0.5), z=st.floats(-0.5, 0.5)),
       exponent=st.integers(-15, 15))
def test_a_homography_maps_alike_at_any_scale_and_a_singular_one_is_rejected_at_any(tau, exponent):
    """H and s H are one homography: np.eye(3) * 1e-5 was called singular, as the determinant test took H's
    scale for its invertibility."""
    H = plane_homography(CAMERA, np.eye(4), CAMERA, tau.apply(np.eye(4)), np.array([0.0, 0.0, 1.0]), -4.0)
    uv = np.array([[3.0, 4.0], [80.0, 60.0], [150.0, 110.0]])
    reference = HomographyMapping(H, CAMERA, CAMERA).to_follow(uv)
    scaled = HomographyMapping(H * 10.0**exponent, CAMERA, CAMERA).to_follow(uv)
    np.testing.assert_array_equal(scaled.visible, reference.visible, err_msg=f"H * 1e{exponent} sees other points")
    np.testing.assert_allclose(scaled.uv, reference.uv, rtol=1e-9, atol=1e-9, err_msg=f"H * 1e{exponent} maps apart")
    singular = H.copy()
    singular[2] = singular[0] + singular[1]  # rank 2
    with pytest.raises(InvalidArgument, match=r"H is singular \(condition number .* > 1e12\)"):
        HomographyMapping(singular * 10.0**exponent, CAMERA, CAMERA)


@pytest.mark.parametrize("shift", [2e4, -5e4])
def test_a_large_pure_shift_is_a_homography_not_a_singular_matrix(shift):
    """``det(H / max|H|)`` of a shift by 20 000 pixels is 1.25e-13: it was refused as singular."""
    mapped = HomographyMapping(np.array([[1.0, 0.0, shift], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), CAMERA, CAMERA)
    product = mapped.H_inv @ mapped.H  # proportional to the identity
    np.testing.assert_allclose(product / product[2, 2], np.eye(3), atol=1e-9)


def test_small_and_zero_homographies():
    for scale in (1.0, 1e-3, 1e-5, 1e-300):
        mapped = HomographyMapping(np.eye(3) * scale, CAMERA, CAMERA).to_follow(np.array([[3.0, 4.0]]))
        assert mapped.uv.tolist() == [[3.0, 4.0]], f"np.eye(3) * {scale:g} is the identity, got {mapped.uv}"
    with pytest.raises(InvalidArgument, match="H is singular"):
        HomographyMapping(np.zeros((3, 3)), CAMERA, CAMERA)


def test_lift_and_land_name_a_view_rendered_without_depth_or_opacity():
    """The constructor checked its views, but lift and land took any view: one rendered without depth crashed with
    "'NoneType' object has no attribute 'shape'"."""
    source, follow = pair(Transform(x=0.1))
    mapping = DepthMapping(source, follow)
    rgb_only = RenderedView(source.camera, source.c2w, rgb=np.zeros((CAMERA.height, CAMERA.width, 3), np.uint8))
    uv = np.array([[80.0, 60.0]])
    expected = r"view was rendered without depth, opacity; expected a view rendered with outputs including"
    with pytest.raises(InvalidArgument, match=expected):
        mapping.lift(uv, rgb_only)
    lifted = mapping.lift(uv, source)
    with pytest.raises(InvalidArgument, match=expected):
        mapping.land(lifted, rgb_only)
    with pytest.raises(InvalidType, match="view must be the RenderedView the SUT saw"):
        mapping.lift(uv, None)
    with pytest.raises(InvalidType, match="lifted must be the LiftedPoints of DepthMapping.lift, got ndarray"):
        mapping.land(uv, follow)
    with pytest.raises(InvalidArgument, match="source was rendered without depth, opacity"):
        DepthMapping(rgb_only, follow)
    assert mapping.land(lifted, follow).visible.tolist() == [True]


def test_points_landing_on_empty_space_are_low_opacity_never_occluded():
    """A source point that lands where the follow-up render has nothing (opacity 0, sky) is rejected as
    ``low_opacity`` only: counting it as ``occluded`` too reported sky as occlusion (and counted it twice)."""
    patch = Plane((0.0, 0.0, 1.0), -4.0, centre=(0.0, 0.0, 4.0), half=0.4)  # the follow-up sees only this much
    source = render_planes(np.eye(4), [WALL])
    follow = render_planes(Transform(yaw=3).apply(np.eye(4)), [patch])
    u, v = np.meshgrid(np.arange(10.0, 150.0, 9.0), np.arange(10.0, 110.0, 9.0))
    p = np.column_stack([u.ravel(), v.ravel()]) + [0.3, 0.4]
    mapped = DepthMapping(source, follow).to_follow(p)
    assert 0 < mapped.visible.sum() < len(p) - 10, "the case must put some points on the patch and many on sky"
    assert mapped.rejected["occluded"] == 0, f"points on empty space counted as occluded: {mapped.rejected}"
    assert mapped.rejected["low_opacity"] + mapped.rejected["outside"] + mapped.visible.sum() == len(p), (
        f"every point should be visible or rejected once: {mapped.rejected}, {mapped.visible.sum()} visible")


def scaled_occluder_scene(scale: float) -> tuple[RenderedView, RenderedView]:
    """A wall at z = 4 and a square occluder in front of it at z = 2, seen from the origin and from x = 0.5, all
    lengths times ``scale`` (edges off pixel centres, so round-off cannot flip a pixel's hit)."""
    wall = Plane((0.0, 0.0, 1.0), -4.0 * scale)
    occluder = Plane((0.0, 0.0, 1.0), -2.0 * scale, centre=(0.337 * scale, 0.02 * scale, 2.0 * scale),
                     half=0.241 * scale)
    source = render_planes(np.eye(4), [wall, occluder])
    follow = render_planes(Transform(x=0.5 * scale).apply(np.eye(4)), [wall, occluder])
    return source, follow


@settings(max_examples=25, deadline=None)
@given(exponent=st.floats(-2, 2))
@example(exponent=-2.0)
@example(exponent=2.0)
def test_occlusion_does_not_depend_on_the_scene_scale(exponent):
    """The depth tolerance is relative (5 % of the rendered depth): the same scene in centimetres or kilometres
    sees the same points. An absolute tolerance of 0.05 scene units saw through the occluder of a scene 100 times
    smaller (wall at 0.04, occluder at 0.02)."""
    u, v = np.meshgrid(np.arange(1.0, 159.0, 3.0), np.arange(1.0, 119.0, 3.0))
    p = np.column_stack([u.ravel(), v.ravel()]) + [0.37, 0.21]
    reference = DepthMapping(*scaled_occluder_scene(1.0)).to_follow(p)
    assert reference.rejected["occluded"] > 20, "the scene must hide points behind the occluder"
    scaled = DepthMapping(*scaled_occluder_scene(10.0**exponent)).to_follow(p)
    np.testing.assert_array_equal(scaled.visible, reference.visible,
                                  err_msg=f"a scene scaled by 1e{exponent:.3g} sees other points")
    assert scaled.rejected == reference.rejected, (
        f"a scene scaled by 1e{exponent:.3g} rejects {scaled.rejected}, not {reference.rejected}")
