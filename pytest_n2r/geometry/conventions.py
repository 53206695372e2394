"""Conversions between our pose convention and those of other tools.

Convention
----------
Ours: camera-to-world 4x4 float64, OpenCV camera axes (x right, y down, z forward).

- nerfstudio / instant-ngp / NeRF ``transform_matrix``: camera-to-world, OpenGL camera axes
  (x right, y up, z backward). Converting flips the camera's y and z axes (right-multiplication by
  ``diag(1, -1, -1, 1)``), which is its own inverse.
- COLMAP: world-to-camera rotation as a unit quaternion ``qvec = (w, x, y, z)`` and translation
  ``tvec``, OpenCV axes. Converting inverts the rigid transform.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_array
from ..errors import InvalidArgument
from .pose import invert_pose, orthonormalize

__all__ = [
    "opengl_to_opencv",
    "opencv_to_opengl",
    "c2w_from_colmap",
    "colmap_from_c2w",
    "quaternion_to_rotation",
    "rotation_to_quaternion",
]

_FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_to_opencv(c2w_opengl: np.ndarray) -> np.ndarray:
    """Camera-to-world with OpenGL camera axes → camera-to-world with OpenCV camera axes.

    >>> opengl_to_opencv(np.eye(4))[:3, 2]       # OpenGL looks down -z, so our +z is world -z
    array([ 0.,  0., -1.])
    """
    M = check_array("transform_matrix", c2w_opengl, "4 4", dtype=np.float64)
    out = M @ _FLIP_YZ
    out[:3, :3] = orthonormalize(out[:3, :3])
    return out


def opencv_to_opengl(c2w: np.ndarray) -> np.ndarray:
    """Inverse of :func:`opengl_to_opencv` (for writing nerfstudio ``transforms.json``)."""
    return check_array("c2w", c2w, "4 4", dtype=np.float64) @ _FLIP_YZ


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` (Hamilton, COLMAP order) → 3x3 rotation; normalizes first."""
    q = check_array("qvec", q, "4", dtype=np.float64)
    n = float(np.linalg.norm(q))
    if n < 1e-12:
        raise InvalidArgument("qvec has zero length; expected a unit quaternion (w, x, y, z)")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """3x3 rotation → unit quaternion ``(w, x, y, z)`` with ``w >= 0`` (Shepperd's method, stable)."""
    R = check_array("R", R, "3 3", dtype=np.float64)
    tr = np.trace(R)
    i = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if i == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    elif i == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s])
    elif i == 2:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def c2w_from_colmap(qvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """COLMAP world-to-camera ``(qvec, tvec)`` → our camera-to-world 4x4."""
    w2c = np.eye(4)
    w2c[:3, :3] = quaternion_to_rotation(qvec)
    w2c[:3, 3] = check_array("tvec", tvec, "3", dtype=np.float64)
    return invert_pose(w2c)


def colmap_from_c2w(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Our camera-to-world 4x4 → COLMAP world-to-camera ``(qvec, tvec)``."""
    w2c = invert_pose(check_array("c2w", c2w, "4 4", dtype=np.float64))
    return rotation_to_quaternion(w2c[:3, :3]), w2c[:3, 3].copy()
