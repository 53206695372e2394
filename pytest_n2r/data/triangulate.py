"""Sparse surface points from images whose poses are known (for sources without SfM points).

Method
------
SIFT features (OpenCV) in every image; each image is matched with its ``neighbours`` nearest cameras
(by centre distance, among those whose optical axes differ by less than 60 degrees); matches pass
Lowe's ratio test (0.75); each match is triangulated linearly (``cv2.triangulatePoints``) with the
given poses and kept only when it lies in front of both cameras, reprojects within
``max_reprojection_px`` pixels in both images and is seen under at least ``min_angle_deg`` degrees of
parallax (:func:`matched_pairs` gives these matches pair by pair; :mod:`.exposure` reads the photos'
colours at them). A point seen in several pairs is counted once per pair, which does not bias the medians and
percentiles it feeds (:mod:`pytest_n2r.data.extent`).

Convention
----------
Images are ``H x W x 3`` uint8 RGB, ideal pinhole (undistorted) and of their camera's size; poses are
camera-to-world, OpenCV axes. Points are returned in world units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgument
from ..geometry import Camera, invert_pose

__all__ = ["neighbour_pairs", "PairMatches", "matched_pairs", "triangulate_views"]


def neighbour_pairs(
    c2ws: Sequence[np.ndarray], neighbours: int = 4, max_angle_deg: float = 60.0
) -> list[tuple[int, int]]:
    """Index pairs ``(i, j)``, ``i < j``: each camera with its ``neighbours`` nearest cameras (by centre)
    whose optical axis is within ``max_angle_deg`` degrees of its own."""
    centres = np.array([np.asarray(c)[:3, 3] for c in c2ws])
    axes = np.array([np.asarray(c)[:3, 2] for c in c2ws])
    cos_max = np.cos(np.radians(max_angle_deg))
    pairs: set[tuple[int, int]] = set()
    for i in range(len(c2ws)):
        dist = np.linalg.norm(centres - centres[i], axis=1)
        ok = (axes @ axes[i] > cos_max) & (np.arange(len(c2ws)) != i)
        for j in np.flatnonzero(ok)[np.argsort(dist[ok], kind="stable")][:neighbours]:
            pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)


@dataclass(frozen=True, eq=False)
class PairMatches:
    """The matches between views ``i`` and ``j`` (``i < j``) that triangulate consistently with their poses:
    ``ui`` and ``uj`` are ``(M, 2)`` pixel positions in each (x right, y down, pixel centres at integers),
    ``points`` the ``(M, 3)`` world points they meet at."""

    i: int
    j: int
    ui: np.ndarray
    uj: np.ndarray
    points: np.ndarray


def matched_pairs(
    images: Sequence[np.ndarray], cameras: Sequence[Camera], c2ws: Sequence[np.ndarray], *,
    neighbours: int = 4, max_reprojection_px: float = 2.0, min_angle_deg: float = 1.5, max_features: int = 2000,
) -> list[PairMatches]:
    """SIFT matches between neighbouring views with known poses, each kept only where it triangulates in front
    of both cameras, reprojects within ``max_reprojection_px`` in both and is seen under at least
    ``min_angle_deg`` of parallax (0: any parallax, however small; cameras at one spot still triangulate nothing).
    One entry per pair with at least 8 ratio-test matches before the checks; see the module docstring."""
    import cv2

    if not len(images) == len(cameras) == len(c2ws):
        raise InvalidArgument(
            f"images, cameras and c2ws must have one entry per view; got {len(images)}, {len(cameras)}, {len(c2ws)}"
        )
    for k, (img, cam) in enumerate(zip(images, cameras)):
        if cam.distortion:
            raise InvalidArgument(f"cameras[{k}] has lens distortion; undistort the images first")
        if img.shape[:2] != (cam.height, cam.width):
            raise InvalidArgument(
                f"images[{k}] has size {img.shape[1]}x{img.shape[0]}; its camera is {cam.width}x{cam.height}")

    sift = cv2.SIFT.create(nfeatures=max_features)
    features = []
    for img in images:
        kps, desc = sift.detectAndCompute(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), None)
        pts = np.array([kp.pt for kp in kps], dtype=np.float64).reshape(-1, 2)
        features.append((pts, desc))

    matcher = cv2.BFMatcher(cv2.NORM_L2)
    w2cs = [invert_pose(c) for c in c2ws]
    out = []
    for i, j in neighbour_pairs(c2ws, neighbours):
        (pi, di), (pj, dj) = features[i], features[j]
        if di is None or dj is None or len(di) < 2 or len(dj) < 2:
            continue
        knn = matcher.knnMatch(di, dj, k=2)
        good = [m[0] for m in knn if len(m) == 2 and m[0].distance < 0.75 * m[1].distance]
        if len(good) < 8:
            continue
        ui = pi[[m.queryIdx for m in good]]
        uj = pj[[m.trainIdx for m in good]]
        points, ok = _triangulate_pair(
            ui, uj, cameras[i], cameras[j], w2cs[i], w2cs[j], max_reprojection_px, min_angle_deg
        )
        out.append(PairMatches(i, j, ui[ok], uj[ok], points[ok]))
    return out


def triangulate_views(
    images: Sequence[np.ndarray], cameras: Sequence[Camera], c2ws: Sequence[np.ndarray], *,
    neighbours: int = 4, max_reprojection_px: float = 2.0, min_angle_deg: float = 1.5, max_features: int = 2000,
) -> np.ndarray:
    """Triangulate SIFT matches between neighbouring views with known poses → ``(N, 3)`` world points.

    See the module docstring for the method. Returns an empty ``(0, 3)`` array when nothing survives.
    """
    pairs = matched_pairs(images, cameras, c2ws, neighbours=neighbours, max_reprojection_px=max_reprojection_px,
                          min_angle_deg=min_angle_deg, max_features=max_features)
    return np.concatenate([p.points for p in pairs], axis=0) if pairs else np.zeros((0, 3))


def _triangulate_pair(
    ui: np.ndarray, uj: np.ndarray, cam_i: Camera, cam_j: Camera, w2c_i: np.ndarray, w2c_j: np.ndarray,
    max_err: float, min_angle_deg: float,
) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    P_i = cam_i.K @ w2c_i[:3]
    P_j = cam_j.K @ w2c_j[:3]
    X_h = cv2.triangulatePoints(P_i, P_j, ui.T, uj.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        X = (X_h[:3] / X_h[3]).T
    ok = np.all(np.isfinite(X), axis=1)
    for P, w2c, u in ((P_i, w2c_i, ui), (P_j, w2c_j, uj)):
        z = X @ w2c[2, :3] + w2c[2, 3]
        ok &= z > 0
        x = X @ P[:, :3].T + P[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.linalg.norm(x[:, :2] / x[:, 2:3] - u, axis=1)
        ok &= err < max_err
    c_i = -w2c_i[:3, :3].T @ w2c_i[:3, 3]
    c_j = -w2c_j[:3, :3].T @ w2c_j[:3, 3]
    ri, rj = X - c_i, X - c_j
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.sum(ri * rj, axis=1) / (np.linalg.norm(ri, axis=1) * np.linalg.norm(rj, axis=1))
    ok &= cos < np.cos(np.radians(min_angle_deg))
    return X, ok
