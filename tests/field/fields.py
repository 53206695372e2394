"""Random scene fields, cameras and poses for the engine tests.

Grids are small (16–24 vertices) and images tiny, so every test runs in milliseconds once numba has loaded
its cached kernels. Poses are given in *normalized* coordinates of the field's space (the unit cube is the
captured region) and turned into scene units here, so one pose means the same thing at every scale.
"""

from __future__ import annotations

import numpy as np
import torch

from pytest_n2r.demo.scenes import look_at
from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.geometry import Camera

#: The default space: off-centre and not of unit size, so normalization is exercised.
SPACE = SceneSpace(center=(0.1, -0.2, 0.3), radius=2.0, shell=0.25)
#: A 32×24 pinhole camera with a ~56° horizontal field of view.
CAMERA = Camera(32, 24, 30.0, 30.0, 15.5, 11.5)
#: The same image through a telephoto lens (~0.15°), so the cube fills it from a thousand radii away.
TELEPHOTO = Camera(32, 24, 12000.0, 12000.0, 15.5, 11.5)

#: Named poses ``(eye, target)`` in normalized coordinates: inside the cube, outside it looking at it,
#: outside looking away, in the contracted shell, and a thousand radii away.
POSES = {
    "inside": ((0.3, -0.2, 0.1), (-0.5, 0.4, 0.2)),
    "outside": ((2.5, 1.5, -2.0), (0.0, 0.0, 0.0)),
    "looking_away": ((1.6, 0.4, -1.2), (3.2, 0.9, -2.5)),
    "in_shell": ((1.1, -0.3, 0.2), (0.0, 0.1, 0.0)),
    "far_away": ((700.0, -300.0, 600.0), (0.0, 0.0, 0.0)),
}


def random_field(resolution: int = 16, sh_degree: int = 1, occupied: float = 0.5, seed: int = 0,
                 space: SceneSpace = SPACE, density_scale: float = 3.0) -> SceneField:
    """A field with normal random raw densities (times ``density_scale``) and colours, and a random
    occupancy keeping about ``occupied`` of the cells."""
    generator = torch.Generator().manual_seed(seed)
    field = SceneField.empty(space, resolution, sh_degree=sh_degree, alpha=0.05, step_ratio=0.5)
    field.values.copy_(torch.randn(field.values.shape, generator=generator))
    field.values[:, 0] *= density_scale
    field.occupancy &= torch.rand(field.occupancy.shape, generator=generator) < occupied
    return field


def pose(eye: tuple[float, float, float], target: tuple[float, float, float], space: SceneSpace = SPACE) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes, scene units) at normalized ``eye`` looking at normalized ``target``."""
    center = np.asarray(space.center)
    eye_w = center + space.radius * np.asarray(eye, dtype=np.float64)
    target_w = center + space.radius * np.asarray(target, dtype=np.float64)
    forward = (target_w - eye_w) / np.linalg.norm(target_w - eye_w)
    up = np.array([0.0, 0.0, 1.0]) if abs(forward[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    return look_at(eye_w, target_w, up)


def named_pose(name: str, space: SceneSpace = SPACE) -> np.ndarray:
    """One of :data:`POSES` in scene units of ``space``."""
    eye, target = POSES[name]
    return pose(eye, target, space)


def camera_for(name: str) -> Camera:
    """The camera that sees the cube from pose ``name``: :data:`TELEPHOTO` from far away, else :data:`CAMERA`."""
    return TELEPHOTO if name == "far_away" else CAMERA
