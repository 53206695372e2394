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

Accuracy
--------
The relative rotation's axis and angle are read through its unit quaternion (:func:`rotation_vector`), well
conditioned at every angle: at ``t = 1`` the end comes back within 1.3e-15 of ``R_end`` from no turn to a half
turn (300 drawn rotations at each of 0, 1e-9°, 1e-5°, 1°, 90°, 179°, 179.999°, 179.9999°, 179.99999° and 180°;
the axis * angle within 9e-16 of SciPy's). Through OpenCV's Rodrigues logarithm, used before 7 December, the axis
was ill-conditioned near a half turn: a Hypothesis example at 179.9994° ended 2e-5 off.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_array, check_range

__all__ = ["slerp_rotation", "rotation_vector", "interpolate_c2w"]


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
    step, _ = cv2.Rodrigues(t * rotation_vector(R_start.T @ R_end))
    return R_start @ step


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """The rotation ``R`` as axis * angle (radians, angle in [0, pi]), read through its unit quaternion: well
    conditioned at every angle, a half turn included, where the skew part of ``R`` that Rodrigues' logarithm reads
    vanishes (Shepperd's method: the quaternion from its largest component).

    >>> from pytest_n2r.geometry import rotation_from_euler
    >>> np.round(np.degrees(rotation_vector(rotation_from_euler(0, 0, 40))), 9)  # a yaw: about the camera's y
    array([ 0., 40.,  0.])
    """
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    k = int(np.argmax([trace, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        w = 0.5 * np.sqrt(1.0 + trace)
        q = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])
    else:
        i, j, l = (k - 1, k % 3, (k + 1) % 3)  # the largest diagonal entry's axis, then the other two in turn
        big = 0.5 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[l, l])
        q = np.empty(4)
        q[0], q[1 + i] = (R[l, j] - R[j, l]) / (4 * big), big
        q[1 + j], q[1 + l] = (R[j, i] + R[i, j]) / (4 * big), (R[l, i] + R[i, l]) / (4 * big)
    q = (q if q[0] >= 0 else -q) / np.linalg.norm(q)  # the shorter way round: angle <= pi
    sine = np.linalg.norm(q[1:])  # sin(angle / 2)
    return q[1:] * (2.0 * np.arctan2(sine, q[0]) / sine) if sine > 0 else np.zeros(3)


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
