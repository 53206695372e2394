"""Stress tests of the splat rasterizer (the counterpart of test_stress.py for fields): any pose, any camera,
degenerate Gaussians (zero and huge scales, behind or at the camera, opacities at both ends, thousands on one
spot) — finite outputs, opacity in [0, 1], a documented depth, the same bytes for the same input, and the
reference's answer wherever it is defined to the bit.

Rule checked for depth: the weighted mean of the drawn Gaussians' z-depths, so it lies between the nearest
and farthest Gaussian in front of the camera, and it is 0 exactly where opacity is 0 (nothing drawn).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera
from pytest_n2r.render.splat_render import SplatRenderer
from pytest_n2r.splats import Gaussians

from ..field.fields import pose
from .splat_reference import render_reference
from .strategies import cameras, poses

OUTPUTS = ("rgb", "depth", "opacity")


@st.composite
def gaussian_sets(draw) -> Gaussians:
    """Up to 40 Gaussians in the unit cube with log scales from -100 (zero) to 12 (huge), opacity logits from
    -50 to 50, any rotation, SH degree 0..3 with large coefficients; sometimes all on one spot."""
    n = draw(st.integers(1, 40))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    degree = draw(st.integers(0, 3))
    kind = draw(st.sampled_from(["mixed", "zero", "huge", "one_spot"]))
    means = rng.uniform(-1, 1, (n, 3)) if kind != "one_spot" else np.tile(rng.uniform(-1, 1, 3), (n, 1))
    log_scales = {"mixed": rng.uniform(-100, 12, (n, 3)), "zero": np.full((n, 3), -100.0),
                  "huge": rng.uniform(8, 12, (n, 3)), "one_spot": rng.uniform(-5, 0, (n, 3))}[kind]
    return Gaussians(means=means, quats=rng.normal(size=(n, 4)), log_scales=log_scales,
                     opacity_logits=rng.choice([-50.0, -5.0, 0.0, 5.0, 50.0], n),
                     sh=rng.normal(0, 3, (n, (degree + 1) ** 2, 3)))


def assert_valid_view(out: dict, g: Gaussians, c2w: np.ndarray, camera: Camera, what: str) -> None:
    h, w = camera.height, camera.width
    rgb, depth, opacity = out["rgb"], out["depth"], out["opacity"]
    assert rgb.dtype == np.uint8 and rgb.shape == (h, w, 3), f"{what}: rgb is {rgb.dtype} {rgb.shape}"
    for name, array in (("depth", depth), ("opacity", opacity)):
        assert array.dtype == np.float32 and array.shape == (h, w), f"{what}: {name} is {array.dtype} {array.shape}"
        assert np.isfinite(array).all(), f"{what}: {name} has NaN/Inf"
    assert opacity.min() >= 0.0 and opacity.max() <= 1.0, f"{what}: opacity spans [{opacity.min()}, {opacity.max()}]"
    assert ((depth == 0) == (opacity == 0)).all(), f"{what}: depth is 0 exactly where opacity is 0"
    z = (g.means.astype(np.float64) - c2w[:3, 3]) @ c2w[:3, 2]
    z = z[z > 0.01]
    drawn = depth[opacity > 0]
    if drawn.size:
        assert drawn.min() >= z.min() * (1 - 1e-5) and drawn.max() <= z.max() * (1 + 1e-5), (
            f"{what}: depth spans [{drawn.min()}, {drawn.max()}], the Gaussians in front [{z.min()}, {z.max()}]")


#: A needle (log-scales −85, 9.4, −56) seen from inside the unit cube: the renderer's 2-D covariance, formed
#: as ``a c − b²`` from a float64 3-D covariance, had its conic 0.2 % off and the opacity at one pixel
#: 0.08281 against the exact 0.08320 (found by a random search over this test's scenes; Hypothesis had
#: once found the like at log-scales −80..+11.7 on a 1×2 camera, opacity off by 8e-5).
NEEDLE = Gaussians(means=[[-0.26409784, 0.55678684, 0.93289065]],
                   quats=[[-0.13786921, 0.63018566, -0.10518179, 0.42767468]],
                   log_scales=[[-84.67895, 9.431456, -55.725414]], opacity_logits=[5.0],
                   sh=[[[-2.2006292, -0.86833143, -2.5601513]]])
NEEDLE_VIEW = ((0.008377225248208593, 0.005622204885391596, -0.0031620829653424033),
               (-0.7839539756237756, -0.5261348168496099, 0.2959127203201913))


@settings(max_examples=60, deadline=None)
@given(g=gaussian_sets(), eye_target=poses(max_distance=1e4), camera=cameras(max_side=12))
@example(g=NEEDLE, eye_target=NEEDLE_VIEW, camera=Camera(2, 2, 30.730488967229537, 30.052265105616577, 0.5, 0.5))
def test_any_scene_pose_and_camera_give_a_valid_deterministic_view(g, eye_target, camera):
    c2w = pose(*eye_target)
    what = f"{len(g)} Gaussians, eye {eye_target[0]} towards {eye_target[1]}, {camera}"
    renderer = SplatRenderer(g)
    out = renderer.render(c2w, camera, OUTPUTS)
    assert_valid_view(out, g, c2w, camera, what)
    again = renderer.render(c2w, camera, OUTPUTS)
    fresh = SplatRenderer(Gaussians(**g.tensors())).render(c2w, camera, OUTPUTS)
    for name in OUTPUTS:
        assert out[name].tobytes() == again[name].tobytes(), f"{what}: {name} differs when rendered twice"
        assert out[name].tobytes() == fresh[name].tobytes(), f"{what}: {name} differs in a fresh renderer"
    # the reference's conics are exact and the renderer's 2-D determinant is a sum of squares, so even needles
    # of e¹² next to the 0.3 px² dilation agree to float32 rounding: over 2000 examples of these strategies
    # (a one-off run of this body) opacity differed by at most 3.0e-8 and no colour by a level (before the
    # fix: a ≤ 1 level and 1e-5 tolerance, and a needle 3.9e-4 off, see NEEDLE)
    ref = render_reference(g, c2w, camera)
    ok = ~ref["ambiguous"]
    diff = np.abs(out["rgb"].astype(int) - ref["rgb"])[ok]
    assert diff.max(initial=0) == 0, f"{what}: rgb differs from the reference by up to {diff.max(initial=0)}"
    np.testing.assert_allclose(out["opacity"][ok], ref["opacity"][ok], atol=2e-7, err_msg=f"{what}: opacity")


@pytest.mark.parametrize("size", [(1, 1), (1, 2), (2, 1), (1, 300)])
def test_one_pixel_wide_images(size):
    w, h = size
    camera = Camera(w, h, 20.0, 20.0, (w - 1) / 2, (h - 1) / 2)
    g = Gaussians(means=[[0.0, 0.0, 3.0]], quats=[[1, 0, 0, 0]], log_scales=[[0.0] * 3], opacity_logits=[5.0],
                  sh=np.zeros((1, 1, 3)))
    out = SplatRenderer(g).render(np.eye(4), camera, OUTPUTS)
    assert_valid_view(out, g, np.eye(4), camera, f"{w}×{h} image")
    assert out["opacity"][h // 2, w // 2] > 0.9, f"the Gaussian in front of a {w}×{h} camera is not drawn"


def test_ten_thousand_gaussians_on_one_pixel_terminate_and_stay_finite():
    """Early termination: after the transmittance falls below 1e-4 nothing more is added, and opacity stays
    below 1 (each Gaussian's opacity is capped at 0.99)."""
    n = 10_000
    g = Gaussians(means=np.tile([0.0, 0.0, 2.0], (n, 1)) + np.arange(n)[:, None] * [0, 0, 1e-4],
                  quats=[[1, 0, 0, 0]] * n, log_scales=np.full((n, 3), -3.0), opacity_logits=np.full(n, 50.0),
                  sh=np.zeros((n, 1, 3)))
    out = SplatRenderer(g).render(np.eye(4), Camera(5, 5, 50.0, 50.0, 2.0, 2.0), OUTPUTS)
    centre = float(out["opacity"][2, 2])
    assert 1 - 1e-3 < centre < 1.0, f"opacity {centre} at the centre; expected just below 1 (99 % and 99 % of the rest)"
    assert out["depth"][2, 2] == pytest.approx(2.0, abs=2e-3), "depth is the first Gaussians'"
