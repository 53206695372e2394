"""Similarity alignment of point sets and pose sets (Umeyama), for comparing two reconstructions.

Convention
----------
A similarity ``(s, R, t)`` maps a point ``x`` of frame *a* to ``s * R @ x + t`` in frame *b*; a
camera-to-world pose maps to ``[[R @ R_c2w, s * R @ c + t], [0, 1]]`` (the camera's own axes keep their
directions relative to the scene; the scale applies to positions only).
"""

from __future__ import annotations

import math

import numpy as np

from .._validation import check_array
from ..errors import InvalidArgument
from .pose import check_rotation

__all__ = ["umeyama", "apply_similarity_to_pose", "rotation_angle_deg"]


def umeyama(src: np.ndarray, dst: np.ndarray, *, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``(s, R, t)`` with ``dst ≈ s * R @ src + t`` (Umeyama 1991).

    ``src`` and ``dst`` are ``(N, 3)`` corresponding points, N >= 3 and not all collinear.
    Reference: S. Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns", IEEE TPAMI 13(4), 1991, doi:10.1109/34.88573.

    >>> src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> s, R, t = umeyama(src, 2 * src + [1, 2, 3])
    >>> round(s, 12), np.round(t, 12) + 0.0
    (2.0, array([1., 2., 3.]))
    """
    a = check_array("src", src, "N 3", dtype=np.float64)
    b = check_array("dst", dst, "N 3", dtype=np.float64)
    if len(a) != len(b):
        raise InvalidArgument(f"src and dst must have the same number of points, got {len(a)} and {len(b)}")
    if len(a) < 3:
        raise InvalidArgument(f"src has {len(a)} points; a similarity needs at least 3")
    mu_a, mu_b = a.mean(0), b.mean(0)
    a0, b0 = a - mu_a, b - mu_b
    var_a = float(np.mean(np.sum(a0 * a0, axis=1)))
    if var_a <= 1e-24:
        raise InvalidArgument("src points all coincide; the similarity is undefined")
    cov = b0.T @ a0 / len(a)
    U, D, Vt = np.linalg.svd(cov)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    if np.sort(D)[1] <= 1e-12 * max(D[0], 1e-300):
        raise InvalidArgument("src points are collinear; the rotation about their line is undefined")
    R = U @ S @ Vt
    s = float(np.trace(np.diag(D) @ S) / var_a) if with_scale else 1.0
    t = mu_b - s * R @ mu_a
    return s, R, t


def apply_similarity_to_pose(c2w: np.ndarray, s: float, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The camera-to-world pose of the same camera after the world moved by ``x -> s R x + t``."""
    out = np.eye(4)
    out[:3, :3] = R @ np.asarray(c2w, dtype=np.float64)[:3, :3]
    out[:3, 3] = s * R @ np.asarray(c2w, dtype=np.float64)[:3, 3] + t
    return out


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """The angle in **degrees** of the rotation taking ``R_a`` to ``R_b`` (geodesic distance, [0, 180]); both must
    be rotations (a reflection or a scaled matrix has no such angle: :class:`InvalidArgument`).

    >>> from pytest_n2r.geometry import rotation_from_euler
    >>> round(rotation_angle_deg(np.eye(3), rotation_from_euler(0.0, 0.0, 30.0)), 9)
    30.0
    """
    M = check_rotation(R_a, "R_a").T @ check_rotation(R_b, "R_b")
    cos = (np.trace(M) - 1.0) / 2.0
    sin = np.linalg.norm([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]]) / 2.0
    return math.degrees(math.atan2(sin, cos))
