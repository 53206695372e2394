"""Interpolating between two camera poses: slerp for the rotation, a straight line for the centre.

Convention
----------
- Rotations are 3x3 float64 matrices; poses are camera-to-world (``world_from_camera``) 4x4 float64
  matrices with OpenCV camera axes (x right, y down, z forward).
- ``t`` is the fraction of the way from the *start* to the *end*, in [0, 1]: ``t = 0`` returns the
  start exactly, ``t = 1`` the end (to round-off).
- The rotation turns at constant angular speed about the one axis of ``R_start^T @ R_end`` (the relative
  rotation, in the start camera's frame): ``R(t) = R_start @ exp(t * log(R_start^T @ R_end))``, the
  shorter way round. The camera centre moves along the straight line between the two centres.

Warning
-------
Near a half turn the axis of ``R_start^T @ R_end`` is ill-conditioned (OpenCV's Rodrigues logarithm):
measured against ``R_end`` at ``t = 1``, the error is below 1e-12 up to 179.999° and 3.5e-6 at 179.9999°.
Below about 6e-4° (a sine under 1e-5) OpenCV's logarithm returns no rotation at all; there the skew part of
``R_start^T @ R_end`` gives the axis and angle instead (a Hypothesis example at 1e-5° found the end off by
1.7e-7 before).
"""

from __future__ import annotations

import numpy as np

from .._validation import check_array, check_range

__all__ = ["slerp_rotation", "interpolate_c2w"]


def slerp_rotation(R_start: np.ndarray, R_end: np.ndarray, t: float) -> np.ndarray:
    """The rotation a fraction ``t`` in [0, 1] of the way from ``R_start`` to ``R_end`` (spherical linear
    interpolation: constant angular speed about one axis, the shorter way round).

    >>> from pytest_n2r.geometry import rotation_from_euler
    >>> R = slerp_rotation(np.eye(3), rotation_from_euler(0, 0, 40), 0.25)
    >>> np.allclose(R, rotation_from_euler(0, 0, 10))
    True
    """
    import cv2

    R_start = check_array("R_start", R_start, "3 3", dtype=np.float64)
    R_end = check_array("R_end", R_end, "3 3", dtype=np.float64)
    t = check_range("t", t, 0.0, 1.0)
    relative = R_start.T @ R_end
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(relative))  # the relative rotation, axis * angle
    if not rvec.any():
        # OpenCV reads a rotation whose sine is below 1e-5 as none at all; there sin(angle) * axis, the
        # skew part of the matrix, is the angle * axis to a relative error of angle² / 6 < 2e-11.
        rvec = 0.5 * np.array([[relative[2, 1] - relative[1, 2]], [relative[0, 2] - relative[2, 0]],
                               [relative[1, 0] - relative[0, 1]]])
    step, _ = cv2.Rodrigues(rvec * t)
    return R_start @ step


def interpolate_c2w(c2w_start: np.ndarray, c2w_end: np.ndarray, t: float) -> np.ndarray:
    """The camera-to-world pose a fraction ``t`` in [0, 1] of the way from ``c2w_start`` to ``c2w_end``:
    rotation by :func:`slerp_rotation`, camera centre on the straight line between the two centres.

    >>> from pytest_n2r.geometry import rotation_from_euler
    >>> end = np.eye(4)
    >>> end[:3, :3], end[:3, 3] = rotation_from_euler(0, 0, 40), [2.0, 0.0, 4.0]
    >>> middle = interpolate_c2w(np.eye(4), end, 0.5)
    >>> middle[:3, 3]
    array([1., 0., 2.])
    >>> np.allclose(middle[:3, :3], rotation_from_euler(0, 0, 20))
    True
    """
    c2w_start = check_array("c2w_start", c2w_start, "4 4", dtype=np.float64)
    c2w_end = check_array("c2w_end", c2w_end, "4 4", dtype=np.float64)
    c2w = np.eye(4)
    c2w[:3, :3] = slerp_rotation(c2w_start[:3, :3], c2w_end[:3, :3], t)
    t = float(t)
    c2w[:3, 3] = (1.0 - t) * c2w_start[:3, 3] + t * c2w_end[:3, 3]
    return c2w
