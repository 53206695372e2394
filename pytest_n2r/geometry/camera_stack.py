"""Many pinhole cameras stacked as arrays, so that points are projected into all of them in one operation.

Convention
----------
Poses and pixels as in :mod:`pytest_n2r.geometry.projection`: cameras are stored world-to-camera, points are
world coordinates, a point is *seen* by a camera when it is in front of it (z-depth > 0) and projects inside
its image (half-open pixel cells). Distortion is ignored (the undistorted pinhole model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._validation import check_array
from ..errors import InvalidArgument
from .camera import Camera
from .pose import invert_pose
from .projection import inside_image, pixels_from_camera

__all__ = ["CameraStack"]


@dataclass(frozen=True)
class CameraStack:
    """``w2c`` ``(K, 4, 4)`` world-to-camera poses, ``intrinsics`` ``(K, 4)`` (fx, fy, cx, cy in pixels) and
    ``size`` ``(K, 2)`` (width, height in pixels) of K cameras.

    >>> stack = CameraStack.of([Camera(64, 48, 50.0, 50.0, 31.5, 23.5)] * 2, [np.eye(4), np.diag([-1.0, 1, -1, 1])])
    >>> stack.sees(np.array([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0], [5.0, 0.0, 2.0]]))
    array([[ True, False, False],
           [False,  True, False]])
    """

    w2c: np.ndarray
    intrinsics: np.ndarray
    size: np.ndarray

    @classmethod
    def of(cls, cameras: Sequence[Camera], c2ws: Sequence[np.ndarray]) -> CameraStack:
        """Stack ``cameras`` with their camera-to-world poses ``c2ws`` (one each)."""
        if len(cameras) != len(c2ws):
            raise InvalidArgument(f"CameraStack.of: {len(cameras)} cameras but {len(c2ws)} poses; "
                                  "expected one pose per camera")
        w2c = np.stack([invert_pose(c2w) for c2w in c2ws]) if len(c2ws) else np.zeros((0, 4, 4))
        intrinsics = np.array([[c.fx, c.fy, c.cx, c.cy] for c in cameras], dtype=np.float64).reshape(-1, 4)
        size = np.array([[c.width, c.height] for c in cameras], dtype=np.float64).reshape(-1, 2)
        return cls(w2c, intrinsics, size)

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points ``(N, 3)`` → ``u``, ``v`` (pixels, NaN behind a camera) and z-depth, each ``(K, N)``."""
        p = check_array("points_world", points_world, "N 3", dtype=np.float64)
        k = len(self.w2c)
        # one matrix product for all cameras: (3K, 3) rotations times (3, N) points, as (K, 3, N)
        pc = (self.w2c[:, :3, :3].reshape(3 * k, 3) @ p.T).reshape(k, 3, len(p)) + self.w2c[:, :3, 3, None]
        fx, fy, cx, cy = (self.intrinsics[:, i, None] for i in range(4))
        u, v = pixels_from_camera(pc[:, 0], pc[:, 1], pc[:, 2], fx, fy, cx, cy)
        return u, v, pc[:, 2]

    def sees(self, points_world: np.ndarray) -> np.ndarray:
        """``(K, N)`` bool: camera k sees point n (in front of it, inside its image)."""
        u, v, z = self.project(points_world)
        return (z > 0) & inside_image(u, v, self.size[:, 0, None], self.size[:, 1, None])
