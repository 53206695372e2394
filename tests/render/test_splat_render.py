"""The compiled splat rasterizer against the independent float64 reference (every Gaussian at every pixel),
known answers, and bit-determinism whatever the tiles, runs and threads."""

from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.demo.scenes import look_at
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import Camera
from pytest_n2r.render.splat_render import SplatRenderer, SplatSettings
from pytest_n2r.splats import Gaussians, rgb_to_sh

from .splat_reference import render_reference

OUTPUTS = ("rgb", "depth", "opacity")
CAMERA = Camera(40, 30, 35.0, 37.0, 19.3, 14.8)


def random_scene(seed: int, n: int = 150, degree: int | None = None, spread: float = 0.5) -> Gaussians:
    rng = np.random.default_rng(seed)
    degree = seed % 4 if degree is None else degree
    return Gaussians(means=rng.normal(0, spread, (n, 3)), quats=rng.normal(size=(n, 4)),
                     log_scales=rng.uniform(-4, -1.5, (n, 3)), opacity_logits=rng.normal(1, 2, n),
                     sh=rng.normal(0, 0.5, (n, (degree + 1) ** 2, 3)))


def random_pose(rng: np.random.Generator, near: float = 1.5, far: float = 4.0) -> np.ndarray:
    d = rng.normal(size=3)
    return look_at(d / np.linalg.norm(d) * rng.uniform(near, far), rng.normal(0, 0.2, 3))


def assert_matches_reference(g: Gaussians, c2w: np.ndarray, camera: Camera, what: str, background=(0.2, 0.4, 0.6),
                             max_ambiguous: float = 0.01, **kwargs) -> dict:
    """Equal uint8 colour, and opacity and depth to float32 rounding, at every pixel the reference does not
    flag as decided by rounding (those must be rare)."""
    fast = SplatRenderer(g, SplatSettings(**kwargs), background).render(c2w, camera, OUTPUTS)
    ref = render_reference(g, c2w, camera, background, **kwargs)
    ok = ~ref["ambiguous"]
    assert ok.mean() >= 1 - max_ambiguous, f"{what}: {int((~ok).sum())} pixels are decided by rounding"
    diff = np.abs(fast["rgb"].astype(int) - ref["rgb"])[ok]
    assert diff.max(initial=0) == 0, \
        f"{what}: rgb differs from the reference by up to {diff.max()} at {int((diff > 0).sum())} values"
    np.testing.assert_allclose(fast["opacity"][ok], ref["opacity"][ok], atol=2e-7, err_msg=f"{what}: opacity")
    solid = ok & (ref["opacity"] > 1e-4)
    np.testing.assert_allclose(fast["depth"][solid], ref["depth"][solid], rtol=2e-6, err_msg=f"{what}: depth")
    assert (fast["depth"][ok & (ref["opacity"] == 0)] == 0).all(), f"{what}: depth is not 0 where nothing is drawn"
    return fast


@pytest.mark.parametrize("seed", range(8))
def test_random_scenes_match_the_reference(seed):
    rng = np.random.default_rng(100 + seed)
    g = random_scene(seed)
    fast = assert_matches_reference(g, random_pose(rng), CAMERA, f"seed {seed}, SH degree {g.sh_degree}")
    assert 0.05 < fast["opacity"].mean() < 0.99, "the random scene should cover part of the view"


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(1, 80), degree=st.integers(0, 3),
       w=st.integers(1, 48), h=st.integers(1, 48), fov=st.floats(5.0, 150.0), t_stop=st.sampled_from([1e-4, 0.05]),
       near=st.sampled_from([0.01, 1.0]))
def test_any_scene_camera_and_pose_matches_the_reference(seed, n, degree, w, h, fov, t_stop, near):
    rng = np.random.default_rng(seed)
    f = 0.5 * w / math.tan(math.radians(fov) / 2)
    camera = Camera(w, h, f, f * rng.uniform(0.8, 1.25), rng.uniform(-0.5, w - 0.5), rng.uniform(-0.5, h - 0.5))
    g = random_scene(seed, n, degree, spread=rng.uniform(0.1, 2.0))
    assert_matches_reference(g, random_pose(rng, 0.2, 6.0), camera, f"seed {seed}, {n} Gaussians, {camera}",
                             max_ambiguous=0.05, t_stop=t_stop, near=near)


def one_gaussian(sigma: float, depth: float, opacity: float, rgb=(0.8, 0.4, 0.2), scales=None) -> Gaussians:
    log = math.log(sigma) if scales is None else scales
    return Gaussians(means=[[0.0, 0.0, depth]], quats=[[0.3, -0.2, 0.9, 0.1]], log_scales=[[log] * 3 if scales is None
                     else scales], opacity_logits=[math.log(opacity / (1 - opacity))], sh=rgb_to_sh(np.array([[rgb]])))


@pytest.mark.parametrize("sigma, depth, opacity", [(0.05, 2.0, 0.9), (0.01, 1.0, 0.5), (0.2, 7.0, 0.99),
                                                    (1e-6, 3.0, 0.8)])
def test_one_isotropic_gaussian_is_a_disc_of_known_opacity(sigma, depth, opacity):
    """A Gaussian of standard deviation σ on the optical axis at z-depth z, seen with focal length f: its image
    has variance (fσ/z)² + 0.3 px² (the dilation), peak opacity ``opacity`` at the principal point, and
    reaches the pixels where ``opacity · exp(-d²/2s²) >= 1/255`` (a disc), with the Gaussian's depth there."""
    f = 60.0
    camera = Camera(41, 41, f, f, 20.0, 20.0)
    bg = np.array([0.1, 0.2, 0.3])
    out = SplatRenderer(one_gaussian(sigma, depth, opacity), background=tuple(bg)).render(np.eye(4), camera)
    s2 = (f * sigma / depth) ** 2 + 0.3
    yy, xx = np.mgrid[0:41, 0:41]
    d2 = (xx - 20.0) ** 2 + (yy - 20.0) ** 2
    alpha = np.minimum(0.99, opacity * np.exp(-d2 / (2 * s2)))
    alpha[alpha < 1 / 255] = 0.0
    radius = math.sqrt(2 * s2 * math.log(255 * opacity))
    assert (out["opacity"] > 0).sum() == (d2 <= radius ** 2).sum(), (
        f"{(out['opacity'] > 0).sum()} pixels drawn; "
        f"the disc of radius {radius:.3f} px holds {(d2 <= radius ** 2).sum()}")
    np.testing.assert_allclose(out["opacity"], alpha, atol=1e-6, err_msg="opacity is not the Gaussian's")
    assert out["opacity"][20, 20] == pytest.approx(opacity, abs=1e-6), "peak opacity at the principal point"
    np.testing.assert_allclose(out["depth"][alpha > 0], depth, rtol=1e-6, err_msg="depth inside the disc")
    assert (out["depth"][alpha == 0] == 0).all(), "depth outside the disc is 0"
    expected = np.rint((alpha[..., None] * np.array([0.8, 0.4, 0.2]) + (1 - alpha[..., None]) * bg) * 255)
    assert np.abs(out["rgb"].astype(int) - expected).max() <= 1, \
        "colour is not opacity·colour + (1 - opacity)·background"


def test_a_gaussian_behind_the_camera_or_at_the_near_plane_is_not_drawn():
    g = Gaussians(means=[[0, 0, -2.0], [0, 0, 0.005], [0, 0, 0.0]], quats=[[1, 0, 0, 0]] * 3,
                  log_scales=[[0.0] * 3] * 3, opacity_logits=[5.0] * 3, sh=np.zeros((3, 1, 3)))
    out = SplatRenderer(g).render(np.eye(4), CAMERA)
    assert out["opacity"].max() == 0.0, "a Gaussian behind the camera or nearer than `near` was drawn"


def test_nearer_gaussians_hide_farther_ones():
    """Two opaque discs, red in front of green: red wins wherever both reach."""
    g = Gaussians(means=[[0, 0, 3.0], [0, 0, 2.0]], quats=[[1, 0, 0, 0]] * 2, log_scales=[[-1.0] * 3] * 2,
                  opacity_logits=[8.0, 8.0], sh=rgb_to_sh(np.array([[[0, 1, 0]], [[1, 0, 0]]])))
    out = SplatRenderer(g).render(np.eye(4), CAMERA)
    centre = out["rgb"][15, 19]
    assert centre[0] > 240 and centre[1] < 10, f"the centre is {centre}; the red disc is in front"
    # the front disc is capped at opacity 0.99: the back one adds 0.99 × 0.01 of the weight at depth 3
    expected = (0.99 * 2.0 + 0.0099 * 3.0) / (0.99 + 0.0099)
    assert out["depth"][15, 19] == pytest.approx(expected, abs=1e-3), "depth is the weighted mean of the discs"


def _bit_scene():
    return random_scene(3, n=400), random_pose(np.random.default_rng(5)), Camera(70, 50, 60.0, 60.0, 34.5, 24.5)


def _digest(out: dict) -> str:
    import hashlib

    return hashlib.sha256(b"".join(out[name].tobytes() for name in OUTPUTS)).hexdigest()


def test_renders_are_bit_identical_whatever_the_tiles_and_runs():
    g, c2w, camera = _bit_scene()
    base = SplatRenderer(g).render(c2w, camera)
    variants = {"again": SplatSettings(), "tile 8": SplatSettings(tile=8), "tile 1": SplatSettings(tile=1),
                "tile 64": SplatSettings(tile=64), "runs of 7 pairs": SplatSettings(max_pairs=7),
                "runs of 1 pair": SplatSettings(max_pairs=1)}
    for what, s in variants.items():
        out = SplatRenderer(g, s).render(c2w, camera)
        for name in OUTPUTS:
            assert out[name].tobytes() == base[name].tobytes(), f"{name} differs with {what}"


def test_renders_are_bit_identical_on_one_thread():
    """In a fresh process with NUMBA_NUM_THREADS=1 (switching numba's thread count in this process would
    slow every later parallel region of the OpenMP layer)."""
    import os
    import subprocess
    import sys

    code = ("from tests.render.test_splat_render import _bit_scene, _digest; from pytest_n2r.render.splat_render "
            "import SplatRenderer; g, c2w, camera = _bit_scene(); print(_digest(SplatRenderer(g).render(c2w, camera)))")
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    single = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                            cwd=Path(__file__).resolve().parents[2]).stdout.strip()
    g, c2w, camera = _bit_scene()
    assert single == _digest(SplatRenderer(g).render(c2w, camera)), "the render on one thread differs"


@pytest.mark.parametrize("field, value, expected", [
    ("near", 0.0, "SplatSettings.near=0.0; expected a finite number > 0"),
    ("t_stop", 1.0, "SplatSettings.t_stop=1.0; expected a number in [0, 1)"),
    ("tile", 0, "SplatSettings.tile=0; expected an int in 1..256"),
    ("max_pairs", 2.5, "SplatSettings.max_pairs=2.5; expected an int >= 1"),
    ("background", (2, 0, 0), "SplatSettings.background=(2, 0, 0); expected None or three values in [0, 1]"),
    # a string or bytes was taken character by character ('101' as magenta), a bool as 0 or 1
    ("background", "101", "SplatSettings.background='101'; expected None or three values in [0, 1]"),
    ("background", b"\x01\x00\x01", "SplatSettings.background=b'\\x01\\x00\\x01'; expected None or three values"),
    ("background", (True, False, True), "SplatSettings.background=(True, False, True); expected None or three"),
    ("background", np.array([True, False, True]), "SplatSettings.background=array([ True, False,  True]); expected"),
    ("background", [1, [0, 0], 1], "SplatSettings.background=[1, [0, 0], 1]; expected None or three values"),
])
def test_bad_settings_are_named(field, value, expected):
    with pytest.raises(InvalidArgument) as info:
        SplatSettings(**{field: value})
    assert expected in str(info.value), str(info.value)


@pytest.mark.parametrize("background", ["101", b"\x01\x00\x01", (True, False, True), (1, 0, 0, True)], ids=repr)
def test_a_background_that_is_no_three_numbers_is_refused_by_the_renderer(background):
    """A string or bytes was taken character by character ('101' rendered over magenta), a bool as 0 or 1."""
    with pytest.raises(InvalidArgument) as info:
        SplatRenderer(random_scene(1), background=background)
    assert str(info.value) == f"background={background!r}; expected three values in [0, 1]", str(info.value)


def test_only_the_outputs_asked_for_are_returned():
    out = SplatRenderer(random_scene(1)).render(np.eye(4) @ random_pose(np.random.default_rng(1)), CAMERA, ("depth",))
    assert set(out) == {"depth"}, f"returned {sorted(out)}"


@pytest.mark.slow
def test_1080p_with_a_million_gaussians_fits_in_a_few_gigabytes():
    """Peak NumPy memory (tracemalloc) of a 1920×1080 render of 10⁶ Gaussians spread so that most are in view:
    measured 0.55 GB for one render's buffers (a record of 88 B, pixel and tile rectangles, key and tile count
    of 44 B per Gaussian, the depth-ordered records, rectangles, counts and sort keys of about 150 B per
    visible Gaussian, each tile's copy of its records and rectangles, 104 B per (tile, Gaussian) pair, 1.6
    million pairs here, 40 B of state per pixel); the bound is 2 GB. The scene's own arrays (float32 as read,
    and the renderer's float64 means, covariance factors, opacities and reach) add about 170 B per Gaussian
    at SH degree 0 (0.17 GB here)."""
    rng = np.random.default_rng(0)
    n = 1_000_000
    g = Gaussians(means=rng.uniform(-1, 1, (n, 3)), quats=rng.normal(size=(n, 4)),
                  log_scales=rng.uniform(-6, -4, (n, 3)), opacity_logits=rng.normal(0, 1, n), sh=np.zeros((n, 1, 3)))
    renderer = SplatRenderer(g)
    camera = Camera(1920, 1080, 1000.0, 1000.0, 959.5, 539.5)
    c2w = look_at(np.array([0.0, -3.0, 0.0]), np.zeros(3))
    tracemalloc.start()
    try:
        out = renderer.render(c2w, camera)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2e9, f"the 1080p render of 10⁶ Gaussians peaked at {peak / 1e9:.2f} GB"
    assert out["opacity"][440:640, 860:1060].min() > 0.9, "the middle of the view should be covered"


def test_no_gaussians_render_the_background():
    """An empty set (a converted field with nothing opaque enough, a filtered file) is a valid scene."""
    g = Gaussians(means=np.zeros((0, 3)), quats=np.zeros((0, 4)), log_scales=np.zeros((0, 3)),
                  opacity_logits=np.zeros(0), sh=np.zeros((0, 1, 3)))
    out = SplatRenderer(g, background=(0.2, 0.4, 0.6)).render(np.eye(4), CAMERA)
    assert (out["rgb"] == [51, 102, 153]).all() and out["opacity"].max() == 0 and out["depth"].max() == 0, (
        "an empty scene should render the background, opacity 0 and depth 0")
