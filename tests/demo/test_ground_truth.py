"""The exact demo scenes: geometry is exact, colours are view-independent, rendering is deterministic."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from pytest_n2r.demo import demo_scene_names, ground_truth
from pytest_n2r.demo.exact import GroundTruthScene
from pytest_n2r.demo.materials import Flat
from pytest_n2r.demo.primitives import Box, Cylinder, Disc, Group, ReliefWall
from pytest_n2r.demo.scenes import build_scene
from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import Transform, backproject, camera_rays, pixel_grid, project

from .strategies import moved_views

SMALL = (96, 54)


def surface_distance(prim, p: np.ndarray) -> np.ndarray:
    """Distance-like residual of points ``p`` to a primitive's analytic surface, independent of the renderer."""
    if isinstance(prim, Disc):
        return np.abs(p[:, 2] - prim.height)
    if isinstance(prim, ReliefWall):
        h = prim.depth * (0.5 + sum(a * np.sin(fx * p[:, 0] + px) * np.sin(fz * p[:, 2] + pz)
                                    for a, fx, px, fz, pz in prim.waves))
        return np.abs(p[:, 1] - (prim.y0 - h))
    if isinstance(prim, Box):
        lo, hi = np.asarray(prim.lo), np.asarray(prim.hi)
        inside = np.all((p >= lo - 1e-5) & (p <= hi + 1e-5), axis=1)
        face = np.minimum(np.abs(p - lo), np.abs(p - hi)).min(axis=1)
        return np.where(inside, face, np.inf)
    if isinstance(prim, Cylinder):
        k = "xyz".index(prim.axis)
        q = p - np.asarray(prim.centre)
        i, j = [m for m in range(3) if m != k]
        r = np.hypot(q[:, i], q[:, j])
        side = np.where(np.abs(q[:, k]) <= prim.half_length + 1e-5, np.abs(r - prim.radius), np.inf)
        cap = np.where(r <= prim.radius + 1e-5, np.abs(np.abs(q[:, k]) - prim.half_length), np.inf)
        return np.minimum(side, cap)
    raise AssertionError(f"no analytic residual for {type(prim).__name__}")


def small_camera(scene):
    return scene.views[0].camera.resized(*SMALL)


@pytest.mark.parametrize("name", demo_scene_names())
def test_depth_lies_on_the_analytic_surface(name):
    """Back-projecting the rendered z-depth lands on one of the scene's analytic surfaces (to 1e-5 units)."""
    scene = ground_truth(name)
    cam = small_camera(scene)
    for view in scene.views[::12]:
        out = scene.render(view.c2w, cam, ("depth", "opacity"))
        hit = out.opacity.ravel() == 1.0
        assert hit.mean() > 0.5, f"{name}/{view.name}: only {hit.mean():.0%} of pixels hit a surface"
        uv = pixel_grid(cam).reshape(-1, 2)[hit]
        p = backproject(uv, out.depth.ravel()[hit].astype(np.float64), cam, view.c2w)
        residual = np.min([surface_distance(prim, p) for prim in scene.primitives], axis=0)
        # float32 depth: relative precision 6e-8, i.e. ~4e-7 units at 7 units
        tol = 1e-5 * max(1.0, scene.reference_length)
        assert residual.max() < tol, (
            f"{name}/{view.name}: {np.sum(residual >= tol)} of {len(p)} back-projected pixels are off every "
            f"surface, worst by {residual.max():.3g} scene units"
        )
        # and project() maps them back onto their pixels with their z-depth
        uv2, z2 = project(p, cam, view.c2w)
        assert np.abs(uv2 - uv).max() < 1e-3
        np.testing.assert_allclose(z2, out.depth.ravel()[hit], rtol=1e-5)


@pytest.mark.parametrize("name", demo_scene_names())
def test_depth_equals_the_distance_to_the_first_hit(name):
    """A ray cast from another camera towards a rendered surface point never passes through a surface
    beyond it and, when the point is visible, hits exactly it (geometry is consistent across views)."""
    scene = ground_truth(name)
    cam = small_camera(scene)
    view = scene.views[9]
    other = Transform(yaw=4, x=0.08, pitch=-2).apply(view.c2w, scene.reference_length)
    out = scene.render(other, cam, ("depth", "opacity"))
    hit = out.opacity.ravel() == 1.0
    p = backproject(pixel_grid(cam).reshape(-1, 2)[hit], out.depth.ravel()[hit].astype(np.float64), cam, other)
    origin = view.c2w[:3, 3]
    d = p - origin
    t, _ = scene.cast(np.broadcast_to(origin, d.shape).copy(), d)  # the point is at t = 1
    assert np.all(t <= 1 + 1e-6), f"{name}: {np.sum(t > 1 + 1e-6)} rays passed through a surface point"
    visible = np.abs(t - 1) < 1e-6
    assert visible.mean() > 0.8, f"{name}: only {visible.mean():.0%} of points seen from the second view"


@pytest.mark.parametrize("name", demo_scene_names())
def test_a_surface_point_has_the_same_colour_in_two_views(name):
    """Lambertian shading under a fixed light: the colour of a point does not depend on the viewpoint."""
    scene = ground_truth(name)
    cam = scene.views[0].camera.resized(240, 135)
    view = scene.views[16]
    follow = Transform(yaw=3, x=0.05).apply(view.c2w, scene.reference_length)
    a = scene.render(view.c2w, cam, ("rgb", "depth", "opacity"))
    b = scene.render(follow, cam, ("rgb", "depth", "opacity"))
    hit = (a.opacity == 1).ravel()
    uv = pixel_grid(cam).reshape(-1, 2)[hit]
    p = backproject(uv, a.depth.ravel()[hit].astype(np.float64), cam, view.c2w)
    uv_b, z_b = project(p, cam, follow)
    ui, vi = np.rint(uv_b[:, 0]).astype(int), np.rint(uv_b[:, 1]).astype(int)
    inside = (ui >= 0) & (ui < cam.width) & (vi >= 0) & (vi < cam.height)
    ui, vi, z_b, src = ui[inside], vi[inside], z_b[inside], a.rgb.reshape(-1, 3)[hit][inside]
    visible = np.abs(b.depth[vi, ui] - z_b) < 1e-3 * z_b
    diff = np.abs(src[visible].astype(int) - b.rgb[vi[visible], ui[visible]].astype(int)).mean(axis=1)
    # nearest-pixel lookups of textured surfaces differ by up to half a pixel of texture; the median is small,
    # and a view-dependent or misregistered renderer would be far off (random pairs differ by ~40)
    assert np.median(diff) < 8, f"{name}: median colour difference {np.median(diff):.1f} of 255"
    shuffled = np.abs(src[visible].astype(int) - np.roll(src[visible], 997, axis=0).astype(int)).mean(axis=1)
    assert np.median(shuffled) > 2 * np.median(diff)


@pytest.mark.parametrize("name", demo_scene_names())
def test_rendering_is_deterministic(name):
    scene = ground_truth(name)
    cam = small_camera(scene)
    v = scene.views[3]
    a = scene.render(v.c2w, cam, ("rgb", "depth", "opacity"))
    fresh = build_scene(name)  # a separately built instance: same description, same pixels, same hash
    b = fresh.render(v.c2w, cam, ("rgb", "depth", "opacity"))
    assert fresh.content_hash == scene.content_hash
    for out in ("rgb", "depth", "opacity"):
        assert getattr(a, out).tobytes() == getattr(b, out).tobytes(), f"{name}: {out} differs between renders"


def test_a_scene_built_and_hashed_loads_no_ray_caster():
    """A run that takes every render from the cache only builds the scenes and hashes them: the ray caster (its
    kernels and numba's compiler, about 0.2 s of CPU) is imported by the first render, not before."""
    import subprocess
    import sys

    code = ("import sys, pytest_n2r.demo as d; [d.ground_truth(n).content_hash for n in d.demo_scene_names()]; "
            "print(sorted(m for m in sys.modules if m.endswith(('raycast', 'mask_kernel', 'albedo_kernel'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"building and hashing the demo scenes imported {out.strip()}"


def test_content_hash_changes_with_the_scene():
    wall, obj = ground_truth("wall"), ground_truth("object")
    assert wall.content_hash != obj.content_hash
    assert len(wall.content_hash) == 64 and int(wall.content_hash, 16) >= 0


@pytest.mark.parametrize("name", demo_scene_names())
def test_trajectory_and_reference_length(name):
    scene = ground_truth(name)
    assert 40 <= len(scene.views) <= 60
    splits = [v.split for v in scene.views]
    first = 4 if name == "wall" else 0  # the wall holds out no row's end (scenes.py)
    assert [i for i, s in enumerate(splits) if s == "heldout"] == list(range(first, len(splits), 8))
    # reference length is the median z-depth seen from the training views: check it against the depth maps
    cam = scene.views[0].camera.fit_within(64)
    depths = [scene.render(v.c2w, cam, ("depth", "opacity")) for v in scene.views if v.split == "train"]
    median = np.median(np.concatenate([d.depth[d.opacity == 1] for d in depths]))
    assert scene.reference_length == pytest.approx(median, rel=0.01)
    # the built-in scene gives its reference length (scenes.py) rather than casting rays at every load: it
    # must be the measured one, bit for bit (the pose transforms' translations, and so every render, use it)
    measured = scene.median_train_depth()
    assert scene.reference_length == measured, (
        f"{name}: scenes.py gives reference_length={scene.reference_length!r}, but the scene measures "
        f"{measured!r}: put the measured value in scenes.py")


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(moved=moved_views(shift=0.3))
def test_outputs_are_well_formed_at_any_pose(moved):
    """At any transformed pose: opacity in [0, 1], depth positive and finite, rgb uint8, depth consistent."""
    name, index, tau = moved
    scene = ground_truth(name)
    cam = scene.views[0].camera.resized(32, 18)
    c2w = tau.apply(scene.views[index].c2w, scene.reference_length)
    out = scene.render(c2w, cam, ("rgb", "depth", "opacity"))
    assert out.rgb.dtype == np.uint8 and out.rgb.shape == (18, 32, 3)
    assert out.depth.dtype == np.float32 and np.all(np.isfinite(out.depth)) and np.all(out.depth > 0)
    assert out.opacity.dtype == np.float32 and out.opacity.min() >= 0 and out.opacity.max() <= 1
    o, d = camera_rays(cam, c2w)
    t, _ = scene.cast(o.reshape(-1, 3), d.reshape(-1, 3))
    hit = np.isfinite(t)
    assert np.array_equal(hit.reshape(18, 32), out.depth < scene.far)


def test_unknown_scene_is_named_in_the_error():
    with pytest.raises(InvalidArgument, match=r"'nope'.*\('wall', 'object'\)"):
        ground_truth("nope")


def _grouped_crate(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> GroundTruthScene:
    """A scene of one unit crate, ``(0, 0, 0)`` to ``(1, 1, 1)``, in a group with the box ``lo, hi``."""
    crate = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), {"*": Flat((0.5, 0.5, 0.5))})
    return GroundTruthScene("crate", [Group(lo, hi, (crate,))], [], light=(0.0, 0.0, 1.0), ambient=0.5,
                            background=(0.0, 0.0, 0.0), far=10.0, reference_length=1.0)


def test_a_group_box_that_clips_its_children_is_refused():
    """The content hash covers a group's members, not its box: a box narrower than its children would change
    pixels under the same hash, so the scene refuses it (a box around them changes no pixel)."""
    _grouped_crate((-0.1, -0.1, -0.1), (1.1, 1.1, 1.1))  # holds the crate: accepted
    with pytest.raises(InvalidArgument, match=r"GroundTruthScene 'crate': primitives\[0\] is a Group whose box .*"
                                              r"does not hold its child 0 \(Box"):
        _grouped_crate((-0.1, -0.1, -0.1), (1.1, 1.1, 0.5))


@pytest.mark.parametrize(
    ("arguments", "error", "match"),
    [
        ({"light": (0, 0, 0)}, InvalidArgument, r"light=\(0\.0, 0\.0, 0\.0\) has length 0; expected a non-zero"),
        ({"light": (1e200, 0, 0)}, InvalidArgument, r"light=\(1e\+200, 0\.0, 0\.0\) has length 1e\+200"),
        ({"light": (0, float("nan"), 1)}, InvalidArgument, r"light contains 1 non-finite value"),
        ({"light": (0, 1)}, InvalidType, r"light must have shape \(3\), got \(2,\)"),
        ({"ambient": 7.0}, InvalidArgument, r"ambient=7\.0 is out of range; expected a value in \[0, 1\]"),
        ({"ambient": "0.5"}, InvalidType, r"ambient='0\.5' must be a real number"),
        ({"background": (2, 2)}, InvalidArgument, r"background=\(2, 2\); expected an RGB triple of three values in"),
        ({"background": (0.1, 1.5, 0.2)}, InvalidArgument, r"background=\(0\.1, 1\.5, 0\.2\); expected an RGB triple"),
        ({"supersample": 0}, InvalidArgument, r"supersample=0 is out of range; expected an int in \[1, 16\]"),
        ({"supersample": 2.0}, InvalidType, r"supersample=2\.0 must be an int"),
        ({"far": 0.0}, InvalidArgument, r"far=0\.0 must be > 0"),
        ({"reference_length": -1.0}, InvalidArgument, r"reference_length=-1\.0 must be > 0"),
        ({"metres_per_unit": float("inf")}, InvalidArgument, r"metres_per_unit=inf must be finite"),
    ],
)
def test_bad_scene_arguments_are_named(arguments, error, match):
    """A zero light normalized to NaN and rendered every surface black; supersample=0, ambient=7 and a two-value
    background were taken as given."""
    crate = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), {"*": Flat((0.5, 0.5, 0.5))})
    valid = {"light": (0.0, 0.0, 2.0), "ambient": 0.5, "background": (0.0, 0.5, 1.0), "far": 10.0,
             "reference_length": 1.0}
    scene = GroundTruthScene("crate", [crate], [], **valid)
    assert scene.light.tolist() == [0.0, 0.0, 1.0] and scene.background.dtype == np.float32
    with pytest.raises(error, match=match):
        GroundTruthScene("crate", [crate], [], **{**valid, **arguments})


@pytest.mark.parametrize("lo, hi", [((-0.1, -0.1, 0.5), (1.1, 1.1, 1.1)), ((0.2, -0.1, -0.1), (1.1, 1.1, 1.1))])
def test_a_group_box_that_clips_its_children_from_below_is_refused(lo, hi):
    """The box's lower corner is checked as its upper one is: a crate cut off at its bottom or side would change
    pixels under the same content hash."""
    with pytest.raises(InvalidArgument, match=r"primitives\[0\] is a Group whose box .* does not hold its child 0"):
        _grouped_crate(lo, hi)


@pytest.mark.parametrize("name", demo_scene_names())
def test_a_camera_with_non_square_pixels_renders_the_depth_of_its_definition(name):
    """The built-in cameras have square pixels, where fx and fy can be swapped unseen; a camera whose fy is 1.6 fx (and
    whose principal point is off centre) renders the z-depth the vectorized definition gives."""
    from pytest_n2r.geometry import Camera

    scene = ground_truth(name)
    view = scene.views[9]
    square = view.camera.resized(48, 27)
    camera = Camera(48, 27, square.fx, 1.6 * square.fy, square.cx + 3.0, square.cy - 2.0)
    depth = scene.render(view.c2w, camera, ("depth",)).depth
    want = scene.render_reference(view.c2w, camera, ("depth",))["depth"]
    off = np.abs(depth - want) > 1e-5 * want
    assert not off.any(), f"{name}: {off.sum()} of {off.size} depths differ from the definition's, e.g. " \
                          f"{depth[off][0]:.4f} where it gives {want[off][0]:.4f}"
