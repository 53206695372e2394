"""A capture's training rays: one origin per photo (the same rays as one per pixel), priced before they are built,
and a capture too large for the memory free refused with how much smaller to fit it."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import torch

from pytest_n2r.errors import FitError
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
