"""A capture's training rays: one origin per photo (the same rays as one per pixel), and a capture too large for
the memory free refused with what to do, before its rays are built."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from pytest_n2r.errors import FitError
from pytest_n2r.fit import fit
from pytest_n2r.fit.field_fit import fit_space
from pytest_n2r.fit.memory import HEADROOM
from pytest_n2r.fit.rays import RAY_BYTES, TrainingRays
from pytest_n2r.geometry import camera_rays

from .conftest import SHORT_CONFIG


def test_each_photos_origin_stored_once_gives_every_pixels_ray(capture48):
    views = capture48.train_views
    space = fit_space(capture48, SHORT_CONFIG)
    rays = TrainingRays(views, space, torch.device("cpu"))
    per_pixel = [space.normalize_rays(*camera_rays(v.camera, v.c2w)) for v in views]
    o = np.concatenate([o.reshape(-1, 3) for o, _ in per_pixel])
    d = np.concatenate([d.reshape(-1, 3) for _, d in per_pixel])
    every = torch.arange(rays.n)
    assert rays.n == sum(v.camera.width * v.camera.height for v in views) == len(o)
    assert torch.equal(rays.o(every), torch.from_numpy(o)), "an origin differs from its pixel's own"
    assert torch.equal(rays.d, torch.from_numpy(d)) and rays.rgb.dtype == torch.uint8


def test_a_capture_too_large_for_the_memory_free_is_refused_with_how_much_smaller_to_fit_it(capture48):
    views = capture48.train_views
    space = fit_space(capture48, SHORT_CONFIG)
    pixels = sum(v.camera.width * v.camera.height for v in views)
    free = pixels * RAY_BYTES  # room for the rays, not for building them
    with pytest.raises(FitError) as info:
        TrainingRays(views, space, torch.device("cpu"), free)
    message = str(info.value)
    assert f"the {len(views)} training photos hold {pixels:,} pixels: as training rays they need" in message
    assert "MiB free (at most 80% of it is taken); fit them at least" in message and "(n2r fit --downscale)" in message
    factor = float(message.split("at least ")[1].split("×")[0])
    largest = max(v.camera.width * v.camera.height for v in views)
    shrunk = (2 * RAY_BYTES * pixels + 72 * largest) / factor ** 2  # 72: a photo's float64 and float32 conversion
    assert shrunk <= HEADROOM * free * 1.01, f"{factor}× smaller would still not fit"
    assert factor > 1 and math.isfinite(factor)


def test_a_fit_on_too_little_memory_stops_before_any_step(capture48, monkeypatch):
    monkeypatch.setattr("pytest_n2r.fit.rays.free_bytes", lambda device: 1000)
    with pytest.raises(FitError, match=r"as training rays they need 2\.\d MiB, 0\.0 MiB free"):
        fit(capture48, SHORT_CONFIG, max_steps=10, device="cpu")
