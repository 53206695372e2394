"""Coverage of an image by discs around points (the keypoint metrics' chance-match rule and interest-point
spread): the exact mask of covered pixel centres, and a cheap upper bound of its share.

Convention
----------
- Points are ``(N, 2)`` ``(u, v)`` pixels of a camera's image (OpenCV pixel centres at integer coordinates);
  a pixel centre is covered when it lies within ``radius`` pixels of a point (inclusive, plus
  :data:`DISC_SLACK`); discs are clipped to the image.
- A radius beyond the image's diagonal acts as the diagonal (a disc of it around any point of the image covers
  the whole image), so the work stays bounded by the image's size: ``radius=1e300`` costs what the diagonal does.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_positive
from ..geometry import Camera

__all__ = ["DISC_SLACK", "capped_radius", "coverage_mask", "coverage_bound"]

#: Slack (pixels) added to a disc's radius, and to repeatability's matching distance, so that round-off in mapped
#: coordinates (~1e-13 px through a homography, typically 1e-7 px through float32 depth) cannot flip a pixel
#: centre lying exactly on the circle, or drop a pair exactly ``px`` apart.
DISC_SLACK = 1e-6
#: Side (pixels) of the cells :func:`coverage_bound` counts.
_CELL = 4


def capped_radius(radius: float, camera: Camera) -> float:
    """``radius`` (pixels, checked finite and > 0) capped at the diagonal of ``camera``'s image."""
    return min(check_positive("radius", radius), float(np.hypot(camera.width, camera.height)))


def coverage_mask(points: np.ndarray, camera: Camera, radius: float) -> np.ndarray:
    """``H x W`` bool mask of the pixel centres within ``radius`` pixels (inclusive) of any point.

    ``points`` is ``(N, 2)`` ``(u, v)`` in pixels of ``camera``'s image; discs are exact at sub-pixel
    positions and clipped to the image. Each disc is one horizontal run of pixels per row; the runs, as
    indices into the rows laid end to end (``W + 1`` apart, so runs of two rows never touch), are sorted
    and merged into disjoint intervals, whose two ends mark a one-byte difference array that one pass sums:
    ``N * (2 radius + 1)`` runs sorted, and no array of the image's size wider than a byte (a warm main job
    paints about 400 masks at 320x180, and freeing and faulting in 8-byte difference arrays cost more than
    the arithmetic: 0.66-0.68 -> 0.39-0.41 ms a mask, docs/performance-log.md).
    """
    radius = capped_radius(radius, camera) + DISC_SLACK
    h, w = camera.height, camera.width
    # discs that miss the image go before the integer casts below (a point at 1e19 px or inf would not fit)
    points = points[np.all((points + radius >= 0) & (points - radius <= [w - 1, h - 1]), axis=1)]
    if len(points) == 0:
        return np.zeros((h, w), dtype=bool)
    r = int(np.ceil(radius))
    rows = np.floor(points[:, 1] + 0.5).astype(np.intp)[:, None] + np.arange(-r, r + 1)[None, :]
    dy2 = (rows - points[:, 1, None]) ** 2
    ok = (dy2 <= radius * radius) & (rows >= 0) & (rows < h)
    half = np.sqrt(np.maximum(radius * radius - dy2, 0.0))
    u = np.broadcast_to(points[:, 0, None], rows.shape)
    first = np.clip(np.ceil(u - half), 0, w).astype(np.intp)
    last = np.clip(np.floor(u + half) + 1, 0, w).astype(np.intp)  # one past the run's last column
    ok &= first < last
    if not ok.any():  # no disc holds a pixel centre of the image (radius under √0.5 px)
        return np.zeros((h, w), dtype=bool)
    row_start = rows[ok] * (w + 1)
    order = np.argsort(row_start + first[ok])
    starts, stops = (row_start + first[ok])[order], (row_start + last[ok])[order]
    reach = np.maximum.accumulate(stops)  # one past the furthest pixel the runs so far cover
    opens = np.r_[True, starts[1:] > reach[:-1]]  # a run that starts past them all opens an interval
    closes = np.r_[opens[1:], True]  # ... and closes the one before it, at that one's reach
    diff = np.zeros(h * (w + 1), np.int8)
    diff[starts[opens]] = 1
    diff[reach[closes]] = -1
    return np.cumsum(diff, dtype=np.int8).reshape(h, w + 1)[:, :w] > 0


def coverage_bound(points: np.ndarray, camera: Camera, radius: float) -> float:
    """An upper bound of ``coverage_mask(points, camera, radius).mean()`` at a fraction of its cost: the share
    of the image's pixels in the cells of ``_CELL`` × ``_CELL`` pixels that the bounding box of some disc's
    pixel centres (clipped to the image) touches. On the 757 point sets whose discs a warm main job painted
    (320×180, radius 3 and 8 px): shares 0.12–0.35, bounds 0.17–0.46."""
    radius = capped_radius(radius, camera) + DISC_SLACK
    h, w = camera.height, camera.width
    lo, hi = np.ceil(points - radius), np.floor(points + radius)  # (N, 2): the box of each disc's pixel centres
    limit = np.array([w - 1, h - 1])
    inside = np.all((hi >= 0) & (lo <= limit), axis=1)
    lo = (np.clip(lo[inside], 0, limit) // _CELL).astype(np.intp)
    hi = (np.clip(hi[inside], 0, limit) // _CELL).astype(np.intp) + 1  # one past the box's last cell
    cols, rows = -(-w // _CELL), -(-h // _CELL)
    corners = np.zeros((rows + 1, cols + 1), np.int64)  # a 2-D difference array of the boxes' cells
    np.add.at(corners, (lo[:, 1], lo[:, 0]), 1)
    np.add.at(corners, (lo[:, 1], hi[:, 0]), -1)
    np.add.at(corners, (hi[:, 1], lo[:, 0]), -1)
    np.add.at(corners, (hi[:, 1], hi[:, 0]), 1)
    touched = (corners.cumsum(axis=0).cumsum(axis=1)[:rows, :cols] > 0).astype(np.int64)
    widths = np.minimum(_CELL, w - _CELL * np.arange(cols))
    heights = np.minimum(_CELL, h - _CELL * np.arange(rows))
    return float(heights @ touched @ widths) / (w * h)
