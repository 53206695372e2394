"""Tiny scenes for the scene-file tests: a random field on a few views, and a 30-step fit of a 32×24 capture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pytest_n2r.data.capture import Capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit import FitResult
from pytest_n2r.geometry import Camera
from pytest_n2r.scene import SceneView

from ..data.synthetic import look_at

#: The config of the tiny fits: two small grids, small batches (a 30-step fit takes about two seconds).
TINY_CONFIG = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,), batch_rays=256, prune_every=10,
                          alpha_init=1e-2)  # the default 1e-4 shows nothing after 30 steps: a black field
TINY_STEPS = 30


def random_field(resolution: int = 12, seed: int = 0, sh_degree: int = 1) -> SceneField:
    """A field with random densities and colours whose occupancy leaves out about a third of the cells."""
    generator = torch.Generator().manual_seed(seed)
    space = SceneSpace(center=(0.1, -0.2, 0.3), radius=2.5, shell=0.25)
    field = SceneField.empty(space, resolution, sh_degree=sh_degree, alpha=0.05, step_ratio=0.5)
    field.values.copy_(torch.randn(field.values.shape, generator=generator))
    field.occupancy &= torch.rand(field.occupancy.shape, generator=generator) > 0.3
    return field


def looking_at_origin(distance: float, yaw_deg: float) -> np.ndarray:
    """A camera-to-world pose (OpenCV axes) on a circle of ``distance`` in the x-z plane, facing the origin,
    image-down along -y."""
    a = np.radians(yaw_deg)
    eye = np.array([distance * np.sin(a), 0.0, -distance * np.cos(a)])
    return look_at(eye, np.zeros(3), up=np.array([0.0, 1.0, 0.0]))


def tiny_views(n: int = 4, with_images: bool = True) -> list[SceneView]:
    """``n`` 20×16 views around the origin (every fourth held out), with smooth colour-ramp photos if asked
    (JPEG keeps smooth images within a few grey levels)."""
    camera = Camera(20, 16, 18.0, 18.0, 9.5, 7.5)
    y, x = np.mgrid[0:16, 0:20]
    return [SceneView(i, f"frame_{i:03d}.png", camera, looking_at_origin(3.0, 30.0 * i),
                      "heldout" if i % 4 == 0 else "train",
                      np.stack([x * 12, y * 15, np.full_like(x, 40 * i)], -1).astype(np.uint8) if with_images else None)
            for i in range(n)]


@pytest.fixture
def field() -> SceneField:
    return random_field()


@pytest.fixture
def views() -> list[SceneView]:
    return tiny_views()


@pytest.fixture(scope="session")
def tiny_capture() -> Capture:
    """The demo ``object`` scene captured at 32×24 (48 views, 6 held out)."""
    from pytest_n2r.demo.rendered_capture import capture_scene
    from pytest_n2r.demo.scenes import build_scene

    return capture_scene(build_scene("object"), size=(32, 24))


@pytest.fixture(scope="session")
def tiny_fit(tiny_capture: Capture) -> FitResult:
    from pytest_n2r.fit import fit

    return fit(tiny_capture, TINY_CONFIG, max_steps=TINY_STEPS, device="cpu")


@pytest.fixture(scope="session")
def tiny_scene_file(tiny_capture: Capture, tiny_fit: FitResult, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny fit saved as a scene file (with its photos)."""
    from pytest_n2r.scene import save_scene

    path = tmp_path_factory.mktemp("scene") / "object.n2r"
    return save_scene(path, tiny_fit.field, tiny_fit.config, tiny_capture, tiny_fit.report, metres_per_unit=1.0)
