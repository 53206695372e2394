"""Projection, back-projection with z-depth, rays, and plane-induced homographies.

Convention
----------
- Poses are camera-to-world 4x4 (OpenCV camera axes); cameras follow :class:`~pytest_n2r.geometry.Camera`
  (pixel centres at integer coordinates).
- **Depth is z-depth**: the coordinate along the optical axis in the camera frame, in scene units, not
  the distance along the ray.
- Pixel coordinates are ``(u, v)`` = (column, row), float. Pixel centres are at integers, so pixel ``(i, j)``
  covers ``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)`` and a point is *inside* an image of ``W x H`` pixels when
  ``-0.5 <= u < W - 0.5`` and ``-0.5 <= v < H - 0.5`` (half-open: every inside point has exactly one pixel).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_array
from .camera import Camera
from .pose import invert_pose, relative_pose

__all__ = [
    "pixel_grid",
    "camera_rays",
    "project",
    "pixels_from_camera",
    "inside_image",
    "backproject",
    "plane_homography",
    "rotation_homography",
    "apply_homography",
]


def pixel_grid(camera: Camera) -> np.ndarray:
    """All pixel centres as an ``(H, W, 2)`` float64 array of ``(u, v)``."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    return np.stack([u, v], axis=-1)


def camera_rays(camera: Camera, c2w: np.ndarray, uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World-space rays through pixels: ``origins (..., 3)`` and ``directions (..., 3)``.

    Directions are **not** unit length: each has camera-frame z-component 1, so the ray parameter
    ``t`` of a point equals its z-depth. ``uv`` defaults to every pixel centre (``(H, W, 2)``).
    """
    uv = pixel_grid(camera) if uv is None else check_array("uv", uv, "* 2", dtype=np.float64)
    c2w = np.asarray(c2w, dtype=np.float64)
    d_cam = np.stack(
        [(uv[..., 0] - camera.cx) / camera.fx, (uv[..., 1] - camera.cy) / camera.fy, np.ones(uv.shape[:-1])],
        axis=-1,
    )
    directions = d_cam @ c2w[:3, :3].T
    origins = np.broadcast_to(c2w[:3, 3], directions.shape).copy()
    return origins, directions


def project(points_world: np.ndarray, camera: Camera, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(N, 3)`` → pixel coordinates ``(N, 2)`` and z-depths ``(N,)``.

    Points behind the camera (``z <= 0``) get ``uv = NaN``; their depth is returned as is, so callers
    can test ``z > 0``.

    >>> cam = Camera(640, 480, 500.0, 500.0, 319.5, 239.5)
    >>> uv, z = project(np.array([[0.0, 0.0, 2.0]]), cam, np.eye(4))
    >>> uv, z
    (array([[319.5, 239.5]]), array([2.]))
    """
    p = check_array("points_world", points_world, "N 3", dtype=np.float64)
    w2c = invert_pose(c2w)
    pc = p @ w2c[:3, :3].T + w2c[:3, 3]
    z = pc[:, 2]
    u, v = pixels_from_camera(pc[:, 0], pc[:, 1], z, camera.fx, camera.fy, camera.cx, camera.cy)
    return np.stack([u, v], -1), z


def pixels_from_camera(x: np.ndarray, y: np.ndarray, z: np.ndarray, fx: float | np.ndarray, fy: float | np.ndarray,
                       cx: float | np.ndarray, cy: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame coordinates → pixel coordinates ``(u, v)``, NaN where ``z <= 0`` (behind the camera).

    Every argument broadcasts (intrinsics in pixels), so one call projects into many cameras at once.

    >>> pixels_from_camera(np.array([1.0, 1.0]), np.array([0.0, 0.0]), np.array([2.0, -2.0]), 100, 100, 50, 40)
    (array([100.,  nan]), array([40., nan]))
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.where(z > 0, z, np.nan)
        return fx * x / safe + cx, fy * y / safe + cy


def inside_image(u: np.ndarray, v: np.ndarray, width: ArrayLike, height: ArrayLike) -> np.ndarray:
    """Whether pixel coordinates lie inside an image of ``width x height`` pixels (half-open, see the
    Convention; False for NaN). Broadcasts like :func:`pixels_from_camera`.

    >>> inside_image(np.array([-0.5, 9.49, 9.5, np.nan]), np.zeros(4), 10, 5)
    array([ True,  True, False, False])
    """
    with np.errstate(invalid="ignore"):
        return (u >= -0.5) & (u < np.subtract(width, 0.5)) & (v >= -0.5) & (v < np.subtract(height, 0.5))


def backproject(uv: np.ndarray, depth: np.ndarray, camera: Camera, c2w: np.ndarray) -> np.ndarray:
    """Pixels ``(N, 2)`` with z-depths ``(N,)`` → world points ``(N, 3)`` (inverse of :func:`project`)."""
    uv = check_array("uv", uv, "N 2", dtype=np.float64)
    depth = check_array("depth", depth, "N", dtype=np.float64)
    origins, directions = camera_rays(camera, c2w, uv)
    return origins + directions * depth[:, None]


def plane_homography(
    camera_a: Camera, c2w_a: np.ndarray, camera_b: Camera, c2w_b: np.ndarray,
    normal: np.ndarray, offset: float,
) -> np.ndarray:
    """3x3 homography mapping pixels of view a to view b for points on the world plane ``n·X + d = 0``.

    ``normal`` is ``n`` (any length), ``offset`` is ``d``, both in world coordinates and scene units.
    ``H = K_b (R - t n_a^T / d_a) K_a^{-1}`` with ``(R, t)`` taking camera-a coordinates to camera b and
    the plane expressed in camera a. Raises if the plane passes through camera a's centre.
    """
    n = check_array("normal", normal, "3", dtype=np.float64)
    c2w_a = np.asarray(c2w_a, dtype=np.float64)
    n_a = c2w_a[:3, :3].T @ n
    d_a = float(n @ c2w_a[:3, 3] + offset)
    if abs(d_a) < 1e-12 * max(1.0, float(np.linalg.norm(n))):
        from ..errors import InvalidArgument

        raise InvalidArgument("the plane passes through camera a's centre; its homography is undefined")
    b_from_a = relative_pose(c2w_a, c2w_b)
    R, t = b_from_a[:3, :3], b_from_a[:3, 3]
    H = camera_b.K @ (R - np.outer(t, n_a) / d_a) @ np.linalg.inv(camera_a.K)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


def rotation_homography(camera_a: Camera, c2w_a: np.ndarray, camera_b: Camera, c2w_b: np.ndarray) -> np.ndarray:
    """Homography between two views with the same centre (pure rotation; the plane at infinity)."""
    R = relative_pose(c2w_a, c2w_b)[:3, :3]
    return camera_b.K @ R @ np.linalg.inv(camera_a.K)


def apply_homography(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Map pixels ``(N, 2)`` through a 3x3 homography; points mapped to infinity become NaN."""
    uv = check_array("uv", uv, "N 2", dtype=np.float64)
    h = np.concatenate([uv, np.ones((len(uv), 1))], axis=1) @ np.asarray(H, dtype=np.float64).T
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(np.abs(h[:, 2]) > 1e-12, h[:, 2], np.nan)
        return h[:, :2] / w[:, None]
