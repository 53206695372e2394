"""A capture's training rays: one origin per photo (the same rays as one per pixel), priced before they are built,
a capture too large for the memory free refused with how much smaller to fit it, and a view whose photo is not its
camera's image, or whose pose is not rigid, refused naming it before the fit spends any time."""

from __future__ import annotations

import dataclasses
import re
import tracemalloc

import numpy as np
import pytest
import torch

from pytest_n2r.errors import FitError, InvalidArgument
from pytest_n2r.fit import fit
from pytest_n2r.fit.field_fit import fit_space
from pytest_n2r.fit.memory import HEADROOM
from pytest_n2r.fit.rays import RAY_BYTES, TrainingRays, ray_bytes
from pytest_n2r.geometry import camera_rays

from .conftest import SHORT_CONFIG

CPU = torch.device("cpu")


def test_each_photos_origin_stored_once_gives_every_pixels_ray(capture48):
    views = capture48.train_views
    space = fit_space(capture48, SHORT_CONFIG)
    rays = TrainingRays(views, space, CPU)
    per_pixel = [space.normalize_rays(*camera_rays(v.camera, v.c2w)) for v in views]
    o = np.concatenate([o.reshape(-1, 3) for o, _ in per_pixel])
    d = np.concatenate([d.reshape(-1, 3) for _, d in per_pixel])
    assert rays.origins.shape == (len(views), 3), "the origins are stored per pixel again"
    assert rays.n == sum(v.camera.width * v.camera.height for v in views) == len(o)
    assert torch.equal(rays.o(torch.arange(rays.n)), torch.from_numpy(o)), "an origin differs from its pixel's own"
    assert torch.equal(rays.d, torch.from_numpy(d)) and rays.rgb.dtype == torch.uint8


def test_building_the_rays_takes_no_more_memory_than_they_are_priced_at(capture48):
    views, space = capture48.train_views, fit_space(capture48, SHORT_CONFIG)
    held, building = ray_bytes(views)
    tracemalloc.start()
    try:
        rays = TrainingRays(views, space, CPU)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    kept = sum(t.numel() * t.element_size() for t in (rays.view, rays.d, rays.rgb))
    assert kept <= held, f"the rays hold {kept} bytes, priced at {held}"
    assert 0.7 * building <= peak <= building, f"building took {peak} bytes at the peak, priced at {building}"


def test_a_view_without_its_photo_is_refused_naming_it(capture48):
    views = [*capture48.train_views[:1], dataclasses.replace(capture48.train_views[1], image=None)]
    with pytest.raises(InvalidArgument, match=rf"view {re.escape(repr(views[1].name))} has no photo"):
        TrainingRays(views, fit_space(capture48, SHORT_CONFIG), CPU)


def _refusal(capture48, monkeypatch, free: dict[str, int | None], device: torch.device = CPU) -> str:
    monkeypatch.setattr("pytest_n2r.fit.rays.free_bytes", lambda dev: free[dev.type])
    with pytest.raises(FitError) as info:
        TrainingRays(capture48.train_views, fit_space(capture48, SHORT_CONFIG), device)
    return str(info.value)


def test_a_capture_too_large_for_the_memory_free_is_refused_with_how_much_smaller_to_fit_it(capture48, monkeypatch):
    views = capture48.train_views
    held, building = ray_bytes(views)
    message = _refusal(capture48, monkeypatch, {"cpu": held})  # room to hold the rays, not to build them
    pixels = held // RAY_BYTES
    assert f"the {len(views)} training photos hold {pixels:,} pixels: as training rays they need 2.5 MiB, 1.2 " \
           "MiB free (at most 80% of it is taken); fit them at least" in message, message
    factor = float(message.split("at least ")[1].split("×")[0])
    assert f"(with n2r fit, --downscale {factor:g} times the one given)" in message
    assert 1 < factor and building / factor ** 2 <= HEADROOM * held, f"{factor}× smaller would still not fit"
    assert "and no memory is free" in _refusal(capture48, monkeypatch, {"cpu": 0})


def test_rays_for_a_gpu_are_priced_against_its_memory_and_built_on_the_host(capture48, monkeypatch):
    held, building = ray_bytes(capture48.train_views)
    message = _refusal(capture48, monkeypatch, {"cpu": 10 * building, "cuda": held // 2}, torch.device("cuda"))
    assert "as training rays they need 1.2 MiB on cuda, 611.3 KiB free" in message, message
    assert "as training rays they need 2.5 MiB, " in _refusal(capture48, monkeypatch, {"cpu": 1000, "cuda": 10**12},
                                                                torch.device("cuda"))


def test_a_fit_on_too_little_memory_stops_before_any_step(capture48, monkeypatch):
    monkeypatch.setattr("pytest_n2r.fit.rays.free_bytes", lambda device: 1000)
    with pytest.raises(FitError, match=r"as training rays they need 2\.5 MiB, 1000 bytes free"):
        fit(capture48, SHORT_CONFIG, max_steps=10, device="cpu")


def _padded(image: np.ndarray) -> np.ndarray:
    return np.pad(image, ((0, 4), (0, 4), (0, 0)))


def _rgba(image: np.ndarray) -> np.ndarray:
    return np.concatenate([image, np.full(image.shape[:2] + (1,), 255, np.uint8)], -1)


#: A photo that is not its camera's image, and what the refusal says it is (the camera is 48×27).
BAD_IMAGES = {
    "larger": (_padded, "uint8 of shape (31, 52, 3)"),
    "smaller": (lambda im: np.ascontiguousarray(im[::2, ::2]), "uint8 of shape (14, 24, 3)"),
    "rgba": (_rgba, "uint8 of shape (27, 48, 4)"),
    "float": (lambda im: im.astype(np.float32) / 255, "float32 of shape (27, 48, 3)"),
    "transposed": (lambda im: np.ascontiguousarray(im.transpose(1, 0, 2)), "uint8 of shape (48, 27, 3)"),
    "grey": (lambda im: np.ascontiguousarray(im[..., 0]), "uint8 of shape (27, 48)"),
    "list": (lambda im: im.tolist(), "a list"),
}


def _with_view(capture48, index: int, **changes):
    """``capture48`` with its view ``index`` changed (a copy), and that view's name."""
    views = list(capture48.views)
    views[index] = dataclasses.replace(views[index], **changes)
    return dataclasses.replace(capture48, views=views), views[index].name


@pytest.mark.parametrize("kind", BAD_IMAGES)
def test_a_photo_that_is_not_its_cameras_image_is_refused_naming_the_view(capture48, kind):
    """One colour is taken for each ray of a view's camera, in order: a photo of another size, with an alpha
    channel, in float or transposed used to shift every later view's colours against their rays (or fail with a
    bare IndexError)."""
    change, found = BAD_IMAGES[kind]
    capture, name = _with_view(capture48, 1, image=change(capture48.views[1].image))
    with pytest.raises(InvalidArgument) as info:
        TrainingRays(capture.train_views, fit_space(capture48, SHORT_CONFIG), CPU)
    expected = (f"view {name!r}: image is {found}; expected uint8 RGB of shape (27, 48, 3), the size of its camera "
                "(48×27 pixels)")
    assert str(info.value) == expected, f"a {kind} photo: the refusal does not name the view and the image expected: " \
                                        f"{info.value}"


@pytest.mark.parametrize("split", ["train", "heldout"])
def test_a_fit_refuses_a_bad_view_before_it_measures_or_trains_on_any(capture48, monkeypatch, split):
    """A held-out photo is compared with the fitted field's render only at the end: refused before the fit too."""
    index = next(i for i, v in enumerate(capture48.views) if v.split == split)
    capture, name = _with_view(capture48, index, image=_rgba(capture48.views[index].image))

    def measured(*args, **kwargs):
        raise AssertionError(f"the fit measured the photos of a capture whose {split} view {name!r} is RGBA")

    monkeypatch.setattr("pytest_n2r.fit.field_fit.decide_appearance", measured)
    with pytest.raises(InvalidArgument, match=re.escape(f"view {name!r}: image is uint8 of shape (27, 48, 4)")):
        fit(capture, SHORT_CONFIG, max_steps=1, device="cpu", appearance="auto")


def test_a_distorted_camera_is_refused_naming_the_view(capture48):
    """A fit's rays are ideal pinhole rays: a distorted photo's pixels would be taken for rays they were not."""
    camera = dataclasses.replace(capture48.views[1].camera, distortion=(-0.2, 0.05, 0.0, 0.0))
    capture, name = _with_view(capture48, 1, camera=camera)
    with pytest.raises(InvalidArgument) as info:
        fit(capture, SHORT_CONFIG, max_steps=1, device="cpu")
    assert str(info.value).startswith(f"view {name!r}: its camera has lens distortion (-0.2, 0.05, 0.0, 0.0); a "
                                      "fit's rays are ideal pinhole rays"), \
        f"the refusal of a distorted camera does not name the view and the distortion: {info.value}"


@pytest.mark.parametrize("split", ["train", "heldout"])
@pytest.mark.parametrize("pose, found", [
    ("nan", "c2w contains 3 non-finite value(s) (NaN or Inf)"),
    ("scaled", "c2w rotation block is not a rotation"),
])
def test_a_view_without_a_rigid_pose_is_refused_naming_the_view(capture48, split, pose, found):
    """A NaN pose used to be named only as the fit space's ``center=(nan, nan, nan)``."""
    index = next(i for i, v in enumerate(capture48.views) if v.split == split)
    c2w = capture48.views[index].c2w.copy()
    if pose == "nan":
        c2w[:3, 3] = np.nan
    else:
        c2w[:3, :3] *= 2.0
    capture, name = _with_view(capture48, index, c2w=c2w)
    with pytest.raises(InvalidArgument) as info:
        fit(capture, SHORT_CONFIG, max_steps=1, device="cpu")
    assert str(info.value).startswith(f"view {name!r}: {found}"), \
        f"a {split} view with a {pose} pose: the refusal does not name the view and what is wrong: {info.value}"


def test_rays_needing_more_than_the_headroom_are_refused_with_the_least_factor_that_fits(capture48, monkeypatch):
    """Building the rays in 90 % of the free memory is more than HEADROOM (80 %) of it: refused, with the smallest
    tenth by which shrinking each side of the photos (their pixels by its square) fits them."""
    building = ray_bytes(capture48.train_views)[1]
    free = int(building / 0.9)
    message = _refusal(capture48, monkeypatch, {"cpu": free})
    factor = float(message.split("at least ")[1].split("×")[0])
    assert building / factor ** 2 <= HEADROOM * free < building / (factor - 0.1) ** 2, (
        f"{factor}× smaller along each side is not the least tenth that fits {building} bytes in {HEADROOM:.0%} of "
        f"{free}")
