"""Hand-built analytic scenes for metric tests: views of planes with exact z-depth, no fitted field."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pytest_n2r.geometry import Camera, Transform, camera_rays, project
from pytest_n2r.render.view import RenderedView

CAMERA = Camera(160, 120, 150.0, 150.0, 79.5, 59.5)


@dataclass(frozen=True)
class Plane:
    """The world plane ``normal·X + offset = 0``, optionally limited to ``|X - centre|_inf <= half`` (a
    square patch, e.g. an occluder)."""

    normal: tuple[float, float, float]
    offset: float
    centre: tuple[float, float, float] | None = None
    half: float = np.inf


def render_planes(c2w: np.ndarray, planes: list[Plane], camera: Camera = CAMERA) -> RenderedView:
    """Exact z-depth (nearest plane hit in front of the camera) and opacity (1 where a plane is hit)."""
    origins, dirs = camera_rays(camera, c2w)
    depth = np.full((camera.height, camera.width), np.inf)
    for pl in planes:
        n = np.asarray(pl.normal, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(origins @ n + pl.offset) / (dirs @ n)
        hit = np.isfinite(t) & (t > 0)
        if pl.centre is not None:
            X = origins + dirs * np.where(hit, t, 0.0)[..., None]
            hit &= np.all(np.abs(X - np.asarray(pl.centre)) <= pl.half, axis=-1)
        depth = np.where(hit & (t < depth), t, depth)
    opacity = np.isfinite(depth).astype(np.float32)
    depth = np.where(np.isfinite(depth), depth, 1e3).astype(np.float32)
    return RenderedView(camera=camera, c2w=np.asarray(c2w, dtype=np.float64), depth=depth, opacity=opacity)


#: The camera looks down world +z at the wall z = 4 (normal (0, 0, 1), offset -4).
WALL = Plane((0.0, 0.0, 1.0), -4.0)


def pair(tau: Transform, planes: list[Plane] = (WALL,), camera: Camera = CAMERA) -> tuple[RenderedView, RenderedView]:
    """Source at the world origin looking down +z, follow-up at ``c2w @ T(tau)`` (translation in scene units)."""
    src = np.eye(4)
    return render_planes(src, list(planes), camera), render_planes(tau.apply(src), list(planes), camera)


def world_points_on_wall(rng: np.random.Generator, n: int, z: float = 4.0, half: float = 1.2) -> np.ndarray:
    """``n`` random points on the wall (inside the source view's frustum for the default CAMERA)."""
    xy = rng.uniform(-half, half, size=(n, 2))
    return np.column_stack([xy, np.full(n, z)])


def pixels_of(points_world: np.ndarray, view: RenderedView) -> np.ndarray:
    """Pixels ``(N, 2)`` of world points in ``view`` (NaN behind the camera)."""
    return project(points_world, view.camera, view.c2w)[0]
